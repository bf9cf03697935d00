// Tests twin/clock: the realtime pacer sleeps to absolute deadlines (never returns early)
// and its statistics count lateness and overruns (a tick half a period late or more, so one
// 9.4 ms late at 10 ms counts); a readable wake descriptor is answered while waiting and also
// when the pacer is already late; the lockstep pacer never waits. The lateness histogram gives
// quantiles within a bin of the exact ones in constant memory, and the pacer hands each second
// of ticks to its window sink.
// Wall-clock figures are only bounded loosely from below (sleeping never ends early);
// nothing here asserts how fast this machine is.
#include "twin/clock.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <algorithm>
#include <random>
#include <thread>
#include <vector>

namespace omnitwin::twin {
namespace {

TEST(Clock, RealtimePacerNeverWakesBeforeItsDeadline) {
  RealtimePacer p(1'000'000);
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
  RealtimePacer p(1'000'000);
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
  RealtimePacer p(1'000'000);
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
  RealtimePacer p(10'000'000);
  p.start();
  std::this_thread::sleep_for(std::chrono::microseconds(9'400));
  p.wait_until(0);
  p.tick(0);
  EXPECT_EQ(p.stats().overruns, 1u);
  EXPECT_GE(p.stats().jitter_max_us, 9'400.0);
}

// Bins: exact below 2048 µs, 64 per octave above; every value lies inside its bin.
TEST(Clock, LatenessBinsCoverEveryValueOnce) {
  EXPECT_EQ(LatenessHistogram::bin_of(0), 0u);
  EXPECT_EQ(LatenessHistogram::bin_of(2047), 2047u);
  EXPECT_EQ(LatenessHistogram::bin_of(2048), 2048u);
  EXPECT_EQ(LatenessHistogram::upper_edge_us(2048), 2080u) << "2048 + 2048/64";
  std::size_t last = 0;
  for (std::uint64_t us = 0; us < 1'000'000; us += 7) {
    const std::size_t b = LatenessHistogram::bin_of(us);
    ASSERT_GE(b, last) << us;
    ASSERT_LT(us, LatenessHistogram::upper_edge_us(b)) << us;
    if (b > 0) {
      ASSERT_GE(us, LatenessHistogram::upper_edge_us(b - 1)) << us;
    }
    last = b;
  }
  EXPECT_EQ(LatenessHistogram::bin_of(~0ull), LatenessHistogram::kBins - 1) << "beyond the last octave";
}

// Against the exact order statistics of random samples: never below, at most one bin above.
TEST(Clock, LatenessQuantilesAreWithinOneBinOfTheExactOnes) {
  std::mt19937_64 rng(7);
  std::lognormal_distribution<double> d(3.5, 1.2);  // a long tail, tens of µs to ms
  LatenessHistogram h;
  std::vector<std::int64_t> ns;
  for (int i = 0; i < 100'000; ++i) {
    ns.push_back(static_cast<std::int64_t>(d(rng) * 1000));
    h.add(ns.back());
  }
  h.add(-5'000);  // an early start counts as 0
  ns.push_back(0);
  std::sort(ns.begin(), ns.end());
  for (double q : {0.0, 0.5, 0.9, 0.99, 0.999, 1.0}) {
    // Nearest rank: the ceil(q·n)-th smallest (1-based).
    const auto at = static_cast<std::size_t>(std::ceil(q * static_cast<double>(ns.size())));
    const std::size_t rank = std::min(ns.size() - 1, at == 0 ? 0 : at - 1);
    const double exact = ns[rank] * 1e-3;
    const double got = h.quantile_us(q);
    EXPECT_GE(got, exact) << q;
    const double width = exact < 2048 ? 1.0 : exact / 64 + 1;
    EXPECT_LE(got, exact + width) << q;
  }
  EXPECT_EQ(h.count(), ns.size());
  EXPECT_DOUBLE_EQ(h.max_us(), ns.back() * 1e-3);
  double sum = 0;
  for (auto v : ns) sum += v;
  EXPECT_NEAR(h.mean_us(), sum * 1e-3 / ns.size(), 1e-9);
  h.clear();
  EXPECT_EQ(h.count(), 0u);
  EXPECT_EQ(h.quantile_us(0.99), 0.0);
}

// p99 of 100 samples is the 99th, not the largest: the rank was one too high, so every
// realtime.csv window of 100 ticks had late_p99_us = late_max_us (found in review).
TEST(Clock, TheP99OfAHundredSamplesIsTheNinetyNinthNotTheMaximum) {
  LatenessHistogram h;
  for (int i = 1; i <= 100; ++i) h.add(i * 5'000);  // 5, 10, … 500 µs, in 1 µs bins
  EXPECT_LT(h.quantile_us(0.99), h.max_us());
  EXPECT_GE(h.quantile_us(0.99), 495.0);
  EXPECT_LE(h.quantile_us(0.99), 496.0);
  EXPECT_GE(h.quantile_us(0.5), 250.0);
  EXPECT_LE(h.quantile_us(0.5), 251.0);
  EXPECT_EQ(h.quantile_us(1.0), 500.0);
  EXPECT_LE(h.quantile_us(0.0), 6.0);
}

// Each window of sim time reaches the sink once a tick falls beyond it; flush hands over the
// last; ticks, overruns and the maximum are those of the window's own ticks.
TEST(Clock, RealtimePacerHandsOverEachWindow) {
  RealtimePacer p(1'000'000);
  std::vector<LatenessWindow> got;
  p.set_window(5'000'000, [&](const LatenessWindow& w) { got.push_back(w); });
  p.start();
  for (SimTime t = 0; t < 12'000'000; t += 1'000'000) {
    if (t == 6'000'000) std::this_thread::sleep_for(std::chrono::milliseconds(30));  // one very late tick
    p.wait_until(t);
    p.tick(t);
  }
  ASSERT_EQ(got.size(), 2u);
  p.flush_window();
  ASSERT_EQ(got.size(), 3u);
  EXPECT_EQ(got[0].start, 0);
  EXPECT_EQ(got[1].start, 5'000'000);
  EXPECT_EQ(got[2].start, 10'000'000);
  EXPECT_EQ(got[0].ticks + got[1].ticks + got[2].ticks, 12u);
  EXPECT_EQ(got[2].ticks, 2u);
  // The late tick is the second window's: at least 29 ms late there. The first window is not
  // asserted free of overruns (one is only 0.5 ms late, and this host can stall for longer:
  // docs/reliability.md, sixteenth round), only free of a tick that late.
  EXPECT_GE(got[1].overruns, 1u);
  EXPECT_GE(got[1].max_us, 29'000.0);
  EXPECT_LT(got[0].max_us, 29'000.0);
  EXPECT_EQ(got[1].overruns + got[0].overruns + got[2].overruns, p.stats().overruns);
  p.flush_window();
  EXPECT_EQ(got.size(), 3u) << "an empty window is not handed over";
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
