// Tests twin/clock: the realtime pacer sleeps to absolute deadlines (never returns early)
// and its statistics count lateness and overruns; the lockstep pacer never waits.
// Wall-clock figures are only bounded loosely from below (sleeping never ends early);
// nothing here asserts how fast this machine is.
#include "twin/clock.hpp"

#include <gtest/gtest.h>

#include <thread>

namespace omnitwin::twin {
namespace {

TEST(Clock, RealtimePacerNeverWakesBeforeItsDeadline) {
  RealtimePacer p(1'000'000, 64);
  p.start();
  const std::int64_t t0 = monotonic_ns();
  for (SimTime t = 1'000'000; t <= 20'000'000; t += 1'000'000) {
    p.wait_until(t);
    EXPECT_GE(monotonic_ns() - t0, t - 200'000);  // start() and t0 are a few µs apart
    p.tick(t);
  }
  const RealtimeStats s = p.stats();
  EXPECT_EQ(s.ticks, 20u);
  EXPECT_GE(s.jitter_max_us, s.jitter_p99_us);
  EXPECT_GE(s.jitter_p99_us, 0.0);
}

TEST(Clock, RealtimePacerCountsOverruns) {
  RealtimePacer p(1'000'000, 8);
  p.start();
  std::this_thread::sleep_for(std::chrono::milliseconds(5));
  p.wait_until(1'000'000);  // already 4 ms late: returns at once
  p.tick(1'000'000);
  EXPECT_EQ(p.stats().overruns, 1u);
  EXPECT_GT(p.stats().jitter_max_us, 3000.0);
}

TEST(Clock, LockstepNeverWaits) {
  LockstepPacer p;
  p.start();
  const std::int64_t t0 = monotonic_ns();
  p.wait_until(3'600 * kNsPerSecond);
  EXPECT_LT(monotonic_ns() - t0, 1'000'000'000);
}

}  // namespace
}  // namespace omnitwin::twin
