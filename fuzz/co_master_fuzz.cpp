// libFuzzer target for controller/canopen/co_master: our CANopen master, the one CANopen
// program that reads frames from devices we did not write, while it resets, configures (SDO),
// starts and runs four emulated CiA 402 drives (bus_emulators/canopen/co_drive, built from the
// shipped EDS) on the simulated CAN wire (can_bus): the tests' network
// (tests/controller/canopen/co_network.hpp).
//
// The drives answer properly, so the master reaches every phase; the input adds what a faulty
// or hostile bus would: records of 12 bytes [ms][op][id lo][id hi][dlc][rtr|node][6 data]…
// (missing bytes 0). `ms` master ticks (1 ms SYNC periods, 0..31) run first, then `op`:
//   0..3  a frame straight to the master: identifier (11 bits) from id lo/hi, DLC 0..15
//         (values over 8 are what a broken controller could report), data from the record
//         padded with its own bytes, a remote frame when bit 0 of byte 5 is set;
//   4     the same frame, but to a drive's SDO server, heartbeat or PDO identifier: id hi
//         picks the function code (SDO response 0x580, TPDO1 0x180, TPDO2 0x280, EMCY 0x080,
//         heartbeat 0x700), byte 5 the node (1..4), so the master's matching is reached;
//   5     drive (byte 5 % 4) loses power; 6 it powers on again;
//   7     the master finishes its path; 8..15 nothing more (op is byte 1 % 16).
// Properties checked: nothing crashes or throws (ASan/UBSan); the phase always has a name; every
// frame the master sends is a valid classic frame (11-bit identifier, DLC ≤ 8). Abort on any
// violation.
//
//   build/fuzz/co_master_fuzz fuzz/corpus/co_master
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "tests/controller/canopen/co_network.hpp"

namespace co = omnitwin::canopen;
namespace can = omnitwin::can;
using omnitwin::controller::canopen::CoMaster;
using omnitwin::controller::canopen::to_string;

namespace {

using omnitwin::controller::canopen::testing::Network;

// A frame the master sends must be one a CAN controller could put on the wire; the tests'
// network hands the master's frames to the wire, so the check wraps its send callback.
bool valid(const can::Frame& f) { return f.valid() && !f.extended; }

// The frame a record describes (op 0..4).
can::Frame frame_of(const std::uint8_t* r) {
  static constexpr std::uint16_t kCodes[] = {0x580, 0x180, 0x280, 0x080, 0x700};
  can::Frame f;
  const int node = 1 + r[5] % 4;
  f.id = r[1] == 4 ? static_cast<std::uint32_t>(kCodes[r[3] % 5] + node)
                   : static_cast<std::uint32_t>(r[2] | (r[3] & 0x07) << 8);
  if (r[1] != 4 && (r[5] & 1) != 0) f.kind = can::FrameKind::remote;
  f.dlc = static_cast<std::uint8_t>(r[4] & 0x0F);
  for (std::size_t k = 0; k < 8; ++k) f.data[k] = k < 6 ? r[6 + k] : r[k];
  return f;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Network net;
  net.on_master_send = [](const can::Frame& f) {
    if (!valid(f)) std::abort();
  };
  std::uint8_t r[12];
  for (std::size_t at = 0; at < size; at += sizeof r) {
    std::memset(r, 0, sizeof r);
    std::memcpy(r, data + at, std::min(sizeof r, size - at));
    net.run(r[0] % 32);
    const std::uint8_t op = r[1] % 16;
    if (op <= 4) net.master->on_frame(frame_of(r), net.now);
    else if (op == 5 || op == 6) {
      const int i = r[5] % 4;
      if (net.powered[static_cast<std::size_t>(i)] != (op == 6)) net.power(i, op == 6);
    }
    else if (op == 7) net.master->finish(net.now);
    if (std::string(to_string(net.master->phase())) == "?") std::abort();
  }
  net.run(50);
  net.master->shutdown(net.now);
  net.run(5);
  return 0;
}
