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
//   elsewhere it runs as it is and says so in its statistics. Lateness goes into histograms
//   (LatenessHistogram), never a list of samples, so a run of any length (an hour-long soak,
//   a twin that runs until stopped) holds constant memory and never allocates on its cyclic
//   path; optionally each window of sim time (1 s in a run) is handed to a sink as it closes.
// Both keep the wall time they took so the run can report its real-time factor.
#pragma once

#include <array>
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

// Tick lateness in constant memory: 1 µs bins below 2048 µs, then 64 bins per octave (1.6 %
// wide) up to about 50 days. Quantiles are a bin's upper edge (never below the true value, by
// at most a bin's width), capped at the exact maximum; the mean and the maximum are exact.
// Real-time safe: add() neither allocates nor throws.
class LatenessHistogram {
 public:
  // One tick that started late_ns after its deadline [ns]; an early start counts as 0.
  void add(std::int64_t late_ns) noexcept;
  void clear() noexcept;
  std::uint64_t count() const { return count_; }
  double mean_us() const;
  double max_us() const { return static_cast<double>(max_ns_) * 1e-3; }
  // The q-quantile [µs] (q in [0, 1]) by nearest rank: the ceil(q·n)-th smallest sample.
  double quantile_us(double q) const;

  static constexpr std::size_t kExactUs = 2048;  // 1 µs bins below this
  static constexpr std::size_t kSubBins = 64;    // bins per octave above it
  static constexpr std::size_t kOctaves = 32;
  static constexpr std::size_t kBins = kExactUs + kSubBins * kOctaves;
  // The bin holding `us` and the upper edge of bin i [µs] (exposed for tests).
  static std::size_t bin_of(std::uint64_t us) noexcept;
  static std::uint64_t upper_edge_us(std::size_t bin) noexcept;

 private:
  std::array<std::uint64_t, kBins> bins_{};
  std::uint64_t count_ = 0;
  std::int64_t sum_ns_ = 0;
  std::int64_t max_ns_ = 0;
};

// One window of ticks (a second of sim time in a run's realtime.csv).
struct LatenessWindow {
  SimTime start = 0;          // sim time the window began [ns]
  std::uint64_t ticks = 0;
  std::uint64_t overruns = 0;
  double mean_us = 0, p50_us = 0, p99_us = 0, max_us = 0;
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
  // tick_period: the period of the ticks whose lateness is measured [ns].
  explicit RealtimePacer(SimTime tick_period);
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
  // Hands each window of `length` sim time to `sink` once a tick falls beyond it (and the
  // last one on flush_window()). Set before start(); not real-time safe. The sink runs on
  // the cyclic path, once per window.
  void set_window(SimTime length, std::function<void(const LatenessWindow&)> sink);
  // Hands the window still open to the sink, if it holds a tick.
  void flush_window();
  // Records the lateness of the instant t (call right after wait_until(t)). Real-time safe.
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
  LatenessHistogram lateness_;
  SimTime window_length_ = 0, window_start_ = 0;
  std::uint64_t window_overruns_ = 0;
  LatenessHistogram window_;
  std::function<void(const LatenessWindow&)> window_sink_;
  std::string scheduling_ = "not started";
  bool restore_policy_ = false;
  int old_policy_ = 0;
  int old_priority_ = 0;
  bool unlock_memory_ = false;
};

}  // namespace omnitwin::twin
