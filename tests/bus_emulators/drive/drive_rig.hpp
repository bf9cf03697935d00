// tests/bus_emulators/drive — test rig: one Cia402Drive stepping an AxisModel at the drive
// period (drive reads the axis' feedback, the axis integrates the drive's command), plus the
// controlword sequences the tests share. Header-only, test code.
#pragma once

#include <cmath>
#include <cstdint>
#include <functional>

#include "bus_emulators/drive/axis_model.hpp"
#include "bus_emulators/drive/cia402_drive.hpp"

namespace omnitwin::drive::testing {

struct Rig {
  explicit Rig(const DriveConfig& c = {}, const AxisModelConfig& a = {}, double pos0_rad = 0)
      : drive(c), axis(a, pos0_rad) {}

  Objects& o() { return drive.objects(); }
  // One drive period.
  Command step() {
    t += period_ns;
    last = drive.step(t, axis.feedback());
    axis.step(last, static_cast<double>(period_ns) * 1e-9);
    return last;
  }
  void run(double seconds) {
    const int n = static_cast<int>(std::lround(seconds / (static_cast<double>(period_ns) * 1e-9)));
    for (int i = 0; i < n; ++i) step();
  }
  // Steps until pred() holds; false after max_s seconds.
  bool run_until(const std::function<bool()>& pred, double max_s) {
    const int n = static_cast<int>(std::lround(max_s / (static_cast<double>(period_ns) * 1e-9)));
    for (int i = 0; i < n; ++i) {
      step();
      if (pred()) return true;
    }
    return false;
  }
  // Shutdown, switch on, enable operation (one period each).
  void enable() {
    step();  // transitions 0, 1
    o().controlword = cw::kShutdown;
    step();
    o().controlword = cw::kSwitchOn;
    step();
    o().controlword = cw::kEnableOperation;
    step();
  }
  void set_mode(Mode m) {
    o().mode = static_cast<std::int8_t>(m);
    step();
  }
  // PP: a new set-point to `target` (bit 4 raised for one period, then cleared), then steps
  // until the drive reports target reached; false after max_s seconds.
  bool pp_move(std::int32_t target, double max_s = 2.0) {
    o().target_position = target;
    o().controlword = cw::kEnableOperation | cw::new_set_point;
    step();
    o().controlword = cw::kEnableOperation;
    return run_until([&] { return (sw() & sw::target_reached) != 0; }, max_s);
  }
  std::uint16_t sw() { return o().statusword; }
  double load_counts() const { return axis.position_rad() * drive.counts_per_load_rad(); }

  Cia402Drive drive;
  AxisModel axis;
  SimTime t = 0;
  SimTime period_ns = 1'000'000;
  Command last;
};

}  // namespace omnitwin::drive::testing
