// controller layer — the platform application a bus master program runs on top of its core
// (the CANopen and TML programs): the platform loop of seed 002 fig. 4-13 started when the
// core's drives are ready, stepped every control period from the wheels' position counts,
// turning its wheel speeds into counts per second, and finished after the path and settle.
// The master's report takes its reference, odometry and path origin from here.
// Construction allocates (the path); tick() does not.
#pragma once

#include <array>
#include <cstdint>
#include <optional>

#include "controller/master_config.hpp"
#include "controller/platform_loop.hpp"
#include "controller/sim_clock.hpp"

namespace omnitwin::controller {

class PlatformDriver {
 public:
  // `platform` absent: no loop (tick() never commands). tick_s: the program's tick [s];
  // counts_per_rev: the drives' position units per wheel revolution.
  PlatformDriver(const std::optional<MasterConfig>& platform, double tick_s, double counts_per_rev);

  struct Step {
    bool command = false;                  // set `wheel_counts_per_s` on the drives this tick
    std::array<double, 4> wheel_counts_per_s{};
    bool finished = false;                 // the path and settle ended this tick
    bool started = false;                  // the loop started this tick
  };
  // One program tick at t [ns] while the drives are ready (`ready`) with their counts.
  // Real-time safe.
  Step tick(std::int64_t t, bool ready, const WheelCounts& counts);
  // Reference, odometry and path origin into the master's report.
  void fill(simclock::MasterReport& r) const;
  bool started() const { return started_; }

 private:
  std::optional<MasterConfig> platform_;
  std::optional<PlatformLoop> loop_;
  PlatformLoopOutput out_;
  double counts_per_rev_;
  std::int64_t every_ = 1, n_ = 0, origin_ = -1;
  bool started_ = false, finished_ = false;
};

}  // namespace omnitwin::controller
