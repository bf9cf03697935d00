// libFuzzer target for controller/canopen/co_master: our CANopen master, the one CANopen
// program that reads frames from devices we did not write, while it resets, configures (SDO),
// starts and runs four emulated CiA 402 drives (bus_emulators/canopen/co_drive, built from the
// shipped EDS) on the simulated CAN wire (can_bus), as tests/controller/canopen's network does.
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

#include "bus_emulators/can/can_bus.hpp"
#include "bus_emulators/canopen/co_drive.hpp"
#include "bus_emulators/canopen/co_eds.hpp"
#include "controller/canopen/co_master.hpp"

namespace co = omnitwin::canopen;
namespace can = omnitwin::can;
using omnitwin::controller::canopen::CoMaster;
using omnitwin::controller::canopen::CoProgramConfig;
using omnitwin::controller::canopen::to_string;

namespace {

constexpr co::SimTime kMs = 1'000'000;

const co::EdsDevice& shipped_eds() {
  static const co::EdsDevice eds = co::load_eds(std::string(OMNITWIN_SOURCE_DIR) + "/models/canopen/omnitwin_drive.eds");
  return eds;
}

// A frame the master sends must be one a CAN controller could put on the wire.
bool valid(const can::Frame& f) { return f.valid() && !f.extended; }

// The master (bus node 0) and four drives (nodes 1..4) on one 1 Mbit/s wire.
struct Network {
  can::CanBus bus{can::BusConfig{.bit_rate_bps = 1'000'000, .queue_capacity = 64, .max_nodes = 5}};
  std::unique_ptr<CoMaster> master;
  std::vector<std::unique_ptr<co::DriveNode>> drives;
  bool powered[4] = {true, true, true, true};
  co::SimTime now = 0;

  Network() {
    for (int i = 0; i < 5; ++i) bus.attach();
    CoProgramConfig cfg;
    cfg.eds = shipped_eds().source;
    cfg.wheel_counts_per_rev = 10000;
    master = std::make_unique<CoMaster>(cfg, shipped_eds(), [this](const can::Frame& f, co::SimTime t) {
      if (!valid(f)) std::abort();
      return bus.submit(0, f, t) == can::SubmitStatus::queued;
    });
    for (int i = 0; i < 4; ++i) {
      omnitwin::drive::DriveConfig dc;
      dc.counts_per_rev = 10000;
      drives.push_back(std::make_unique<co::DriveNode>(shipped_eds(), static_cast<std::uint8_t>(i + 1), dc,
                                                       [this, i](const can::Frame& f, co::SimTime t) {
                                                         return bus.submit(i + 1, f, t) == can::SubmitStatus::queued;
                                                       }));
    }
    bus.on_deliver([this](can::BusNode r, const can::Frame& f, const can::FrameTiming& t) {
      if (r == 0) master->on_frame(f, t.end_ns);
      else drives[static_cast<std::size_t>(r - 1)]->on_frame(f, t.end_ns);
    });
    for (auto& d : drives) d->power_on(0);
  }
  // `ms` SYNC periods: the master's tick on each ms, the drives' steps half-way.
  void run(int ms) {
    for (int k = 0; k < ms; ++k) {
      bus.advance(now);
      master->on_tick(now);
      bus.advance(now + kMs / 2);
      for (std::size_t i = 0; i < 4; ++i)
        if (powered[i]) drives[i]->step(now + kMs / 2, omnitwin::drive::Feedback{});
      now += kMs;
    }
  }
  void power(int i, bool on) {
    if (powered[i] == on) return;
    powered[i] = on;
    if (on) {
      bus.reattach(i + 1, now);
      drives[static_cast<std::size_t>(i)]->power_on(now);
    } else {
      bus.detach(i + 1, now);
      drives[static_cast<std::size_t>(i)]->power_off();
    }
  }
};

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
  std::uint8_t r[12];
  for (std::size_t at = 0; at < size; at += sizeof r) {
    std::memset(r, 0, sizeof r);
    std::memcpy(r, data + at, std::min(sizeof r, size - at));
    net.run(r[0] % 32);
    const std::uint8_t op = r[1] % 16;
    if (op <= 4) net.master->on_frame(frame_of(r), net.now);
    else if (op == 5) net.power(r[5] % 4, false);
    else if (op == 6) net.power(r[5] % 4, true);
    else if (op == 7) net.master->finish(net.now);
    if (std::string(to_string(net.master->phase())) == "?") std::abort();
  }
  net.run(50);
  net.master->shutdown(net.now);
  net.run(5);
  return 0;
}
