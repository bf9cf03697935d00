// Tests twin/clock: the realtime pacer sleeps to absolute deadlines (never returns early)
// and its statistics count lateness and overruns (a tick half a period late or more, so one
// 9.4 ms late at 10 ms counts); a readable wake descriptor is answered while waiting and also
// when the pacer is already late; the lockstep pacer never waits.
// Wall-clock figures are only bounded loosely from below (sleeping never ends early);
// nothing here asserts how fast this machine is.
#include "twin/clock.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

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

// Frames that came while the twin was busy are handed over before a late event runs.
TEST(Clock, ALatePacerStillAnswersTheWakeDescriptorFirst) {
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  RealtimePacer p(1'000'000, 8);
  int woken = 0;
  SimTime at = -1;
  p.set_wake(fds[0], [&](SimTime t) {
    ++woken;
    at = t;
    char c;
    ASSERT_EQ(::read(fds[0], &c, 1), 1);
  });
  p.start();
  ASSERT_EQ(::write(fds[1], "x", 1), 1);
  std::this_thread::sleep_for(std::chrono::milliseconds(5));
  p.wait_until(1'000'000);  // 4 ms late
  EXPECT_EQ(woken, 1);
  EXPECT_GT(at, 4'000'000) << "the wall-clock instant it was handled";
  p.wait_until(1'500'000);  // late, nothing readable: returns at once
  EXPECT_EQ(woken, 1);
  ::close(fds[0]);
  ::close(fds[1]);
}

TEST(Clock, AnOverrunIsATickHalfAPeriodLateOrMore) {
  constexpr SimTime period = 10'000'000;  // 10 ms
  EXPECT_TRUE(tick_overran(9'400'000, period)) << "the reported case: 9.4 ms late at 10 ms";
  EXPECT_TRUE(tick_overran(5'000'000, period));
  EXPECT_TRUE(tick_overran(25'000'000, period));
  EXPECT_FALSE(tick_overran(4'999'999, period));
  EXPECT_FALSE(tick_overran(0, period));
  EXPECT_FALSE(tick_overran(-1'000, period));
}

// The reported case on the wall clock: a 10 ms tick that starts about 9.4 ms late.
TEST(Clock, RealtimePacerCountsATickNinePointFourMillisecondsLate) {
  RealtimePacer p(10'000'000, 8);
  p.start();
  std::this_thread::sleep_for(std::chrono::microseconds(9'400));
  p.wait_until(0);
  p.tick(0);
  EXPECT_EQ(p.stats().overruns, 1u);
  EXPECT_GE(p.stats().jitter_max_us, 9'400.0);
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
