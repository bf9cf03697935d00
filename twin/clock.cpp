// twin layer — clock modes; see clock.hpp.
#include "twin/clock.hpp"

#include <algorithm>
#include <cerrno>
#include <numeric>

namespace omnitwin::twin {

std::int64_t monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

RealtimePacer::RealtimePacer(SimTime tick_period, std::size_t expected_ticks)
    : tick_period_(tick_period) {
  lateness_us_.reserve(expected_ticks + 16);
}

void RealtimePacer::start() { wall_start_ = monotonic_ns(); }

void RealtimePacer::wait_until(SimTime t) {
  const std::int64_t deadline = wall_start_ + t;
  if (monotonic_ns() >= deadline) return;
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(deadline / kNsPerSecond);
  ts.tv_nsec = static_cast<long>(deadline % kNsPerSecond);
  // Absolute deadline: an interrupted sleep simply resumes towards the same instant.
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

void RealtimePacer::tick(SimTime t) {
  const std::int64_t late = monotonic_ns() - (wall_start_ + t);
  if (late > tick_period_) ++overruns_;
  lateness_us_.push_back(static_cast<double>(std::max<std::int64_t>(late, 0)) * 1e-3);
}

RealtimeStats RealtimePacer::stats() const {
  RealtimeStats s;
  s.ticks = lateness_us_.size();
  s.overruns = overruns_;
  if (lateness_us_.empty()) return s;
  std::vector<double> sorted = lateness_us_;
  std::sort(sorted.begin(), sorted.end());
  s.jitter_mean_us = std::accumulate(sorted.begin(), sorted.end(), 0.0) / sorted.size();
  s.jitter_p99_us = sorted[std::min(sorted.size() - 1, static_cast<std::size_t>(0.99 * sorted.size()))];
  s.jitter_max_us = sorted.back();
  return s;
}

}  // namespace omnitwin::twin
