// Tests bus_emulators/ethercat/ec_dc: the drifting local clock, system time with offset, the
// difference register's sign convention, the drift control loop converging from ±50 ppm (and
// staying monotonic), SYNC0 schedules (start, cycle, single shot, start in the past), and the
// same through an Esc's registers with on_sync0 callbacks at the configured cycle; arithmetic
// modulo 2^64 with far-apart samples and offsets, and the minimum SYNC0 cycle.
#include "bus_emulators/ethercat/ec_dc.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <limits>
#include <vector>

#include "bus_emulators/ethercat/ec_esc.hpp"
#include "bus_emulators/ethercat/ec_registers.hpp"

namespace omnitwin::ethercat {
namespace {

TEST(EcDc, LocalClockDriftsAndSystemTimeAddsTheOffset) {
  DcClock c(50e-6, 1'000, 0);
  EXPECT_EQ(c.local(0), 1'000);
  EXPECT_EQ(c.local(1'000'000'000), 1'000 + 1'000'050'000);
  c.set_offset(5'000);
  EXPECT_EQ(c.system(1'000'000'000), 1'000 + 1'000'050'000 + 5'000);
  EXPECT_EQ(c.sim_time_of_system(c.system(777'777)), 777'777);
  c.reset(2'000'000'000);
  EXPECT_EQ(c.local(2'000'000'000), 1'000);
  EXPECT_EQ(c.offset(), 0u);
}

TEST(EcDc, DriftChangeKeepsTheClockContinuous) {
  DcClock c(0, 0, 0);
  c.set_drift(100e-6, 1'000'000'000);
  EXPECT_EQ(c.local(1'000'000'000), 1'000'000'000);
  EXPECT_EQ(c.local(2'000'000'000), 2'000'100'000);
  EXPECT_EQ(c.drift(), 100e-6);
}

TEST(EcDc, DifferenceRegisterSign) {
  DcClock c(0, 0, 0);
  c.sample(1'000 - 30, true, 1'000);  // local 1000, received 970: local greater
  EXPECT_EQ(c.last_difference(), 30);
  EXPECT_EQ(c.difference_register(), 30u);
  c.reset_loop(1'000);
  c.sample(1'100, true, 1'000);  // local smaller
  EXPECT_EQ(c.difference_register(), 0x80000000u | 100u);
  // 32-bit samples compare the low words.
  DcClock d(0, 0x1'0000'0010LL, 0);
  d.sample(0x0000'0000, false, 0);
  EXPECT_EQ(d.last_difference(), 0x10);
}

TEST(EcDc, DriftLoopConvergesAndStaysMonotonic) {
  for (double drift : {50e-6, -50e-6}) {
    DcClock ref(0, 0, 0);
    DcClock c(drift, 0, 0);
    c.set_delay(700);
    std::int64_t last_local = c.local(0);
    std::int64_t worst_tail = 0, first = 0;
    for (int k = 1; k <= 3000; ++k) {
      const SimTime t = static_cast<SimTime>(k) * 1'000'000;
      c.sample(static_cast<std::uint64_t>(ref.system(t - 700)), true, t);
      if (k == 20) first = std::llabs(c.last_difference());
      if (k > 2000) worst_tail = std::max<std::int64_t>(worst_tail, std::llabs(c.last_difference()));
      const std::int64_t l = c.local(t);
      ASSERT_GT(l, last_local);
      last_local = l;
    }
    EXPECT_GT(first, 200) << drift;  // it did drift before the loop caught up
    EXPECT_LT(worst_tail, 10) << drift;
    EXPECT_NEAR(c.correction(), -drift, 1e-6);  // 1 ns quantisation dithers ≈ 0.5 ppm
    // An offset step is taken as it is (no loop kick); a speed-counter reset zeroes the correction.
    const SimTime t = 3001 * 1'000'000LL;
    c.set_offset(c.offset() + 1'000'000);
    c.sample(static_cast<std::uint64_t>(ref.system(t - 700)), true, t);
    EXPECT_NEAR(c.correction(), -drift, 1e-6);
    c.reset_loop(t);
    EXPECT_EQ(c.correction(), 0.0);
  }
}

// SYNC1 below the SYNC0 cycle follows every SYNC0 pulse by its cycle; at a multiple of it,
// every n-th SYNC0 pulse plus the remainder.
TEST(EcDc, Sync1FollowsSync0) {
  DcClock c(0, 0, 0);
  c.configure_sync(0x07, 1'000'000, 1'000'000, 0);
  c.configure_sync1(true, 250'000);
  EXPECT_TRUE(c.sync1_active());
  std::vector<SimTime> s0, s1;
  SimTime when = 0;
  for (SimTime t = 0; t <= 3'500'000; t += 50'000) {
    while (c.pop_sync0(t, when)) s0.push_back(when);
    if (c.pop_sync1(t, when)) s1.push_back(when);
  }
  EXPECT_EQ(s0, (std::vector<SimTime>{1'000'000, 2'000'000, 3'000'000}));
  EXPECT_EQ(s1, (std::vector<SimTime>{1'250'000, 2'250'000, 3'250'000}));
  c.configure_sync(0x07, 1'000'000, 1'000'000, 0);
  c.configure_sync1(true, 2'100'000);  // every 2nd SYNC0 pulse, 100 µs after it
  s1.clear();
  for (SimTime t = 0; t <= 5'500'000; t += 50'000) {
    while (c.pop_sync0(t, when)) {
    }
    if (c.pop_sync1(t, when)) s1.push_back(when);
  }
  EXPECT_EQ(s1, (std::vector<SimTime>{1'100'000, 3'100'000, 5'100'000}));
  c.configure_sync1(false, 250'000);
  EXPECT_FALSE(c.sync1_active());
}

TEST(EcDc, Sync0Schedule) {
  DcClock c(0, 0, 0);
  c.configure_sync(0x03, 5'000'000, 1'000'000, 0);
  EXPECT_TRUE(c.sync0_active());
  SimTime when = 0;
  EXPECT_FALSE(c.pop_sync0(4'999'999, when));
  std::vector<SimTime> pulses;
  while (c.pop_sync0(8'000'000, when)) pulses.push_back(when);
  EXPECT_EQ(pulses, (std::vector<SimTime>{5'000'000, 6'000'000, 7'000'000, 8'000'000}));
  EXPECT_EQ(c.next_sync0(), 9'000'000u);
  c.configure_sync(0x03, 2'500'000, 0, 3'000'000);  // single shot already in the past: fires at once
  EXPECT_TRUE(c.pop_sync0(3'000'000, when));
  EXPECT_FALSE(c.pop_sync0(100'000'000, when));
  c.configure_sync(0x03, 1'000'000, 1'000'000, 3'500'000);  // past start: next boundary
  EXPECT_EQ(c.next_sync0(), 4'000'000u);
  c.configure_sync(0x01, 0, 1'000'000, 0);  // cyclic unit without SYNC0
  EXPECT_FALSE(c.sync0_active());
}

class Counter : public EscApplication {
 public:
  std::vector<SimTime> pulses;
  AlStatusCode on_al_request(AlState, AlState, SimTime) override { return AlStatusCode::none; }
  void on_mailbox(std::span<const std::uint8_t>, SimTime) override {}
  void on_outputs(std::span<const std::uint8_t>, SimTime) override {}
  void on_sync0(SimTime t) override { pulses.push_back(t); }
};

void apwr(Esc& e, std::uint16_t ado, const std::vector<std::uint8_t>& d, SimTime t) {
  std::array<std::uint8_t, 64> buf{};
  PduBuilder b(buf);
  b.add(Cmd::apwr, 0, 0, ado, static_cast<std::uint16_t>(d.size()), d.data());
  const std::size_t n = b.finish();
  PduView v;
  ASSERT_EQ(parse_pdu(std::span(buf.data(), n), v), PduError::ok);
  e.process(v.datagrams[0], t);
  ASSERT_EQ(v.datagrams[0].wkc(), 1);
}

// Two wide samples ±2^63 apart: e − e_prev does not wrap (the correction saturates the right
// way: the local copy is far behind, so the clock speeds up), and |INT64_MIN| saturates 0x092C.
TEST(EcDc, FarApartSamplesSaturateTheCorrectionAndTheDifference) {
  DcClock c(0, 0, 0);
  c.sample(0, true, 1'000);  // e = +1000
  EXPECT_EQ(c.last_difference(), 1'000);
  const std::uint64_t far = 2'000 + (std::uint64_t{1} << 63) - 100;  // e = −(2^63 − 100)
  c.sample(far, true, 2'000);
  EXPECT_EQ(c.last_difference(), -static_cast<std::int64_t>((std::uint64_t{1} << 63) - 100));
  EXPECT_DOUBLE_EQ(c.correction(), DcClock::kMaxCorrection);
  EXPECT_EQ(c.difference_register(), 0xFFFFFFFFu);  // 31-bit magnitude saturated, local smaller

  DcClock d(0, 0, 0);
  d.sample(d.system(500) - (std::uint64_t{1} << 63), true, 500);  // e = INT64_MIN
  EXPECT_EQ(d.last_difference(), std::numeric_limits<std::int64_t>::min());
  EXPECT_EQ(d.difference_register(), 0xFFFFFFFFu);
}

// System time = local + offset modulo 2^64; the inverse works across the wrap, and a target
// beyond the sim time range is answered with the range's end, not a wrapped (negative) time.
TEST(EcDc, SystemTimeWrapsAndTheInverseStaysInRange) {
  DcClock c(0, 1'000, 0);
  c.set_offset(0x7FFF'FFFF'FFFF'FF00ull);
  EXPECT_EQ(static_cast<std::uint64_t>(c.system(1'000)), 0x7FFF'FFFF'FFFF'FF00ull + 2'000u);
  EXPECT_EQ(c.sim_time_of_system(c.system(777)), 777);
  DcClock slow(-1e-3, 0, 0);  // 0.999: INT64_MAX of system time lies beyond the SimTime range
  const SimTime far = slow.sim_time_of_system(std::numeric_limits<std::int64_t>::max() - 10);
  EXPECT_GT(far, 0);
  EXPECT_EQ(far, DcClock::kSimTimeLimit);
}

// A non-zero SYNC0 cycle below the minimum is an invalid configuration: no pulses at all.
TEST(EcDc, Sync0CycleBelowTheMinimumIsRefused) {
  DcClock c(0, 0, 0);
  c.configure_sync(0x03, 0, 1, 0);  // 1 ns
  EXPECT_FALSE(c.sync0_active());
  EXPECT_TRUE(c.sync0_invalid());
  SimTime when = 0;
  EXPECT_FALSE(c.pop_sync0(1'000'000, when));
  c.configure_sync(0x03, 0, DcClock::kMinSyncCycleNs - 1, 0);
  EXPECT_TRUE(c.sync0_invalid());
  c.configure_sync(0x03, 0, DcClock::kMinSyncCycleNs, 0);  // the minimum itself is fine
  EXPECT_TRUE(c.sync0_active());
  EXPECT_FALSE(c.sync0_invalid());
  EXPECT_TRUE(c.pop_sync0(0, when));
  c.configure_sync(0x03, 0, 0, 0);  // single shot: no cycle, valid
  EXPECT_FALSE(c.sync0_invalid());
  c.configure_sync(0x01, 0, 1, 0);  // SYNC0 not requested: nothing to refuse
  EXPECT_FALSE(c.sync0_invalid());
}

TEST(EcDc, EscSync0PulsesAtTheConfiguredCycle) {
  Counter app;
  EscConfig cfg;
  cfg.power_on_time_ns = 123'000;
  Esc e(cfg, &app);
  std::vector<std::uint8_t> d8(8), d4(4);
  put_u64(d8.data(), 1'000'000);
  apwr(e, reg::kDcSystemTimeOffset, d8, 0);  // system = local + 1 ms
  EXPECT_EQ(e.system_time(0), 1'123'000);
  apwr(e, reg::kDcActivation, {0}, 0);
  put_u32(d4.data(), 250'000);
  apwr(e, reg::kDcSync0Cycle, d4, 0);
  put_u64(d8.data(), 2'123'000);  // system time 2.123 ms = sim time 1 ms
  apwr(e, reg::kDcStartTime, d8, 0);
  apwr(e, reg::kDcActivation, {0x03}, 0);
  EXPECT_EQ(e.read8(reg::kDcActivationStatus) & 1, 1);
  EXPECT_EQ(e.next_event_time(), 1'000'000);
  e.advance(2'000'000);
  EXPECT_EQ(e.next_event_time(), 2'250'000);
  EXPECT_EQ(app.pulses, (std::vector<SimTime>{1'000'000, 1'250'000, 1'500'000, 1'750'000, 2'000'000}));
  EXPECT_EQ(e.read64(reg::kDcStartTime), 3'373'000u);  // next SYNC0 (system time)
  EXPECT_EQ(e.read8(reg::kDcSync0Status) & 1, 1);
  apwr(e, reg::kDcActivation, {0}, 2'100'000);
  e.advance(5'000'000);
  EXPECT_EQ(app.pulses.size(), 5u);
  EXPECT_EQ(e.next_event_time(), kNoEscEvent);
}

TEST(EcDc, EscIgnoresASync0CycleBelowTheMinimum) {
  Counter app;
  Esc e(EscConfig{}, &app);
  std::vector<std::uint8_t> d4(4), d8(8);
  put_u32(d4.data(), 1);  // 1 ns
  apwr(e, reg::kDcSync0Cycle, d4, 0);
  put_u64(d8.data(), 1'000);
  apwr(e, reg::kDcStartTime, d8, 0);
  apwr(e, reg::kDcActivation, {0x03}, 0);
  EXPECT_EQ(e.read8(reg::kDcActivationStatus) & 1, 0);  // not activated
  e.advance(1'000'000);
  EXPECT_TRUE(app.pulses.empty());
  EXPECT_EQ(e.next_event_time(), kNoEscEvent);
}

}  // namespace
}  // namespace omnitwin::ethercat
