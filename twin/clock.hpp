// twin layer — clock modes: how simulated time maps onto the wall clock.
//
// lockstep: simulated time runs as fast as the computation allows and never looks at the
//   wall clock, so a scenario gives byte-identical results every run.
// realtime: simulated time follows CLOCK_MONOTONIC. Before each new instant the pacer
//   sleeps to an absolute deadline (clock_nanosleep TIMER_ABSTIME, no drift from relative
//   sleeps) and records, for the ticks it is told about, how late it woke (jitter) and how
//   often it was half a tick period or more behind (overruns: such a tick's inputs and
//   outputs are then nearer the next tick's instant than its own, so the master effectively
//   missed a cycle; "more than a whole period" would hide a tick 9.4 ms late at 10 ms).
//   Where permitted (root or CAP_SYS_NICE) the realtime pacer runs the thread under
//   SCHED_FIFO and locks memory for the run, and puts both back when it is destroyed;
//   elsewhere it runs as it is and says so in its statistics.
// Both keep the wall time they took so the run can report its real-time factor.
#pragma once

#include <cstdint>
#include <functional>
#include <ctime>
#include <string>
#include <vector>

#include "twin/scheduler.hpp"

namespace omnitwin::twin {

// Reads CLOCK_MONOTONIC [ns]. Real-time safe.
std::int64_t monotonic_ns();

// Whether a tick that started late_ns after its deadline is an overrun: late by half the
// tick period or more. Real-time safe.
constexpr bool tick_overran(std::int64_t late_ns, SimTime tick_period_ns) {
  return late_ns > 0 && 2 * late_ns >= static_cast<std::int64_t>(tick_period_ns);
}

class LockstepPacer final : public Pacer {
 public:
  void start() override { wall_start_ = monotonic_ns(); }
  void wait_until(SimTime) override {}
  void tick(SimTime) override {}
  double wall_seconds() const { return (monotonic_ns() - wall_start_) * 1e-9; }

 private:
  std::int64_t wall_start_ = 0;
};

struct RealtimeStats {
  std::string scheduling;          // e.g. "SCHED_FIFO 40" or "SCHED_OTHER (…)"
  std::uint64_t ticks = 0;
  std::uint64_t overruns = 0;      // ticks that started half a tick period late or more
  double jitter_mean_us = 0;       // lateness of tick starts against their deadline [µs]
  double jitter_p99_us = 0;
  double jitter_max_us = 0;
};

class RealtimePacer final : public Pacer {
 public:
  // tick_period: the period of the ticks whose lateness is measured [ns];
  // expected_ticks: capacity reserved up front so the cyclic path does not allocate.
  RealtimePacer(SimTime tick_period, std::size_t expected_ticks);
  ~RealtimePacer() override;
  RealtimePacer(const RealtimePacer&) = delete;
  RealtimePacer& operator=(const RealtimePacer&) = delete;

  void start() override;
  // Sleeps until wall_start + t; with a wake descriptor set, calls its callback whenever the
  // descriptor becomes readable meanwhile. Real-time safe.
  void wait_until(SimTime t) override;
  // A descriptor to answer while sleeping (e.g. the bus transport's socket) and what to do
  // with it, given the sim time it became readable at. -1 stops it. Not real-time safe.
  void set_wake(int fd, std::function<void(SimTime)> on_readable);
  // Records the lateness of the instant t (call right after wait_until(t)). Real-time safe
  // while fewer than expected_ticks were recorded.
  void tick(SimTime t) override;

  double wall_seconds() const { return (monotonic_ns() - wall_start_) * 1e-9; }
  RealtimeStats stats() const;

 private:
  void wait_waking(std::int64_t deadline);

  SimTime tick_period_;
  int wake_fd_ = -1;
  std::function<void(SimTime)> on_wake_;
  std::int64_t wall_start_ = 0;
  std::uint64_t overruns_ = 0;
  std::vector<double> lateness_us_;
  std::string scheduling_ = "not started";
  bool restore_policy_ = false;
  int old_policy_ = 0;
  int old_priority_ = 0;
  bool unlock_memory_ = false;
};

}  // namespace omnitwin::twin
