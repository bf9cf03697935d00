// twin/dds — decimation of the control-rate state stream to the DDS publish rate, by
// simulated time (never wall time), so that lockstep and realtime runs publish the same
// samples. A grid of publish instants every 1/rate from the first sample: a sample is taken
// when it reaches the next instant (less a small slack for rounding), so an offer period that
// does not divide the publish period still averages the publish rate. Real-time safe.
#pragma once

#include <cmath>
#include <cstdint>

namespace omnitwin::twin {

class RateDecimator {
 public:
  // rate_hz > 0 [Hz]; a rate above the offer rate takes every sample.
  explicit RateDecimator(double rate_hz)
      : period_ns_(static_cast<std::int64_t>(std::llround(1e9 / rate_hz))),
        slack_ns_(period_ns_ / 100) {}

  // Whether the sample at simulated time t_ns [ns] is published. Time going backwards (a new
  // run) restarts the grid. O(1) except after a long gap, no allocation, no system call.
  bool take(std::int64_t t_ns) {
    if (!started_ || t_ns < last_ns_) {
      started_ = true;
      next_ns_ = t_ns;
    }
    last_ns_ = t_ns;
    if (t_ns < next_ns_ - slack_ns_) return false;
    if (t_ns - next_ns_ > period_ns_) next_ns_ = t_ns;   // a gap: restart the grid here
    next_ns_ += period_ns_;
    return true;
  }

  std::int64_t period_ns() const { return period_ns_; }

 private:
  std::int64_t period_ns_;
  std::int64_t slack_ns_;
  std::int64_t next_ns_ = 0;
  std::int64_t last_ns_ = 0;
  bool started_ = false;
};

}  // namespace omnitwin::twin
