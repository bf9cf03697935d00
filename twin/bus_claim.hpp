// twin layer — one twin per bus on this host. A twin claims the bus it serves (a CAN
// transport's multicast group and port or its SocketCAN interface, an Ethernet interface it
// was told to use) by listening on an abstract Unix socket named after it; the kernel drops the
// claim when the process ends, however it ends, so nothing is left behind.
//
// Why: two twins on one bus put two sets of slaves with the same node numbers on it, and each
// master hears the other's drives. Two realtime CAN runs started at once on the default group
// ran that way, counted 1,779 frames from the other run and 91.67 % dropouts, and said nothing
// else (found in review). A bus of its own (lockstep's port 0, a veth pair made for the run)
// needs no claim but takes one all the same: it cannot collide.
#pragma once

#include <sys/types.h>

#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace omnitwin::twin {

// The bus is held by another process. pid: the holder's (-1 when it could not be learnt).
struct BusInUse : std::runtime_error {
  BusInUse(const std::string& what, pid_t holder) : std::runtime_error(what), pid(holder) {}
  pid_t pid;
};

class BusClaim {
 public:
  // Claims `key` (a bus as a transport spec without options: "udp:239.74.163.2:43113",
  // "socketcan:vcan0", "raw:eth1"). Throws BusInUse when another process holds it, and
  // std::runtime_error when no socket can be made. Not real-time safe (set-up only).
  explicit BusClaim(const std::string& key);
  ~BusClaim();
  BusClaim(const BusClaim&) = delete;
  BusClaim& operator=(const BusClaim&) = delete;

  const std::string& key() const { return key_; }

 private:
  std::string key_;
  int fd_ = -1;
};

// The abstract socket name of a claim on `key` (at most 107 bytes; a long key is hashed).
std::string bus_claim_name(const std::string& key);

// Claims each `raw:IFACE` among `specs` (options after '?' dropped; others and repeats skipped)
// into `claims`. Throws as BusClaim does.
void claim_interfaces(std::vector<std::unique_ptr<BusClaim>>& claims, const std::vector<std::string>& specs);

}  // namespace omnitwin::twin
