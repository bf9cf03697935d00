// Test support for the CANopen master tests and its fuzz target (not a test file): our master
// (bus node 0) and four emulated CiA 402 drives (nodes 1..4, built from the shipped EDS) on the
// simulated CAN wire at 1 Mbit/s, in process. One run(ms) = per millisecond the master's SYNC
// tick, then the drives' steps half-way; power(i, on) takes a drive off the wire and back.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "bus_emulators/can/can_bus.hpp"
#include "bus_emulators/canopen/co_drive.hpp"
#include "bus_emulators/canopen/co_eds.hpp"
#include "tests/bus_emulators/canopen/co_drive_on_bus.hpp"
#include "controller/canopen/co_master.hpp"

namespace omnitwin::controller::canopen::testing {

namespace co = omnitwin::canopen;
inline constexpr SimTime kMs = 1'000'000;

using co::testing::shipped_eds;

// The master (bus node 0) and four drives (bus nodes 1..4, node IDs 1..4) on one wire.
struct Network {
  can::CanBus bus{can::BusConfig{.bit_rate_bps = 1'000'000, .queue_capacity = 64, .max_nodes = 5}};
  CoProgramConfig cfg;
  std::unique_ptr<CoMaster> master;
  std::vector<std::unique_ptr<co::DriveNode>> drives;
  std::vector<bool> powered = {true, true, true, true};
  std::vector<std::string> events;
  SimTime now = 0;
  std::function<void(const can::Frame&)> on_master_send;  // sees every frame the master sends

  // The master reads `master_eds` (the drives are always built from the shipped one);
  // `configure` may change its configuration before it is built.
  explicit Network(const co::EdsDevice& master_eds = shipped_eds(),
                   const std::function<void(CoProgramConfig&)>& configure = {}) {
    for (int i = 0; i < 5; ++i) bus.attach();
    cfg.eds = master_eds.source;
    cfg.wheel_counts_per_rev = 10000;
    if (configure) configure(cfg);
    master = std::make_unique<CoMaster>(cfg, master_eds, [this](const can::Frame& f, SimTime t) {
      if (on_master_send) on_master_send(f);
      return bus.submit(0, f, t) == can::SubmitStatus::queued;
    });
    master->set_event_callback([this](SimTime, const std::string& s, bool) { events.push_back(s); });
    for (int i = 0; i < 4; ++i) drives.push_back(co::testing::drive_on_bus(bus, i + 1));
    bus.on_deliver([this](can::BusNode r, const can::Frame& f, const can::FrameTiming& t) {
      if (r == 0) master->on_frame(f, t.end_ns);
      else drives[static_cast<std::size_t>(r - 1)]->on_frame(f, t.end_ns);
    });
    for (auto& d : drives) d->power_on(0);
  }
  // Runs for `ms` milliseconds: the master's tick on each ms, the drives' steps half-way.
  void run(int ms) {
    for (int k = 0; k < ms; ++k) {
      bus.advance(now);
      master->on_tick(now);
      bus.advance(now + kMs / 2);
      for (std::size_t i = 0; i < 4; ++i)
        if (powered[i]) drives[i]->step(now + kMs / 2, drive::Feedback{});
      now += kMs;
    }
  }
  void power(int i, bool on) {
    powered[static_cast<std::size_t>(i)] = on;
    if (on) {
      bus.reattach(i + 1, now);
      drives[static_cast<std::size_t>(i)]->power_on(now);
    } else {
      bus.detach(i + 1, now);
      drives[static_cast<std::size_t>(i)]->power_off();
    }
  }
};

}  // namespace omnitwin::controller::canopen::testing
