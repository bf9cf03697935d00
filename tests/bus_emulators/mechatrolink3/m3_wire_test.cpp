// Tests bus_emulators/mechatrolink3/m3_wire: frame times at 100 Mbit/s, one-way delays and
// TR_DLY in a cascade (growing with each station passed) and a star (the same for every
// slave), the topology limits of seed 000 table 1, T_RSP and the cycle plan worked by hand,
// and the message naming the shortest cycle when a configuration does not fit.
#include "bus_emulators/mechatrolink3/m3_wire.hpp"

#include <gtest/gtest.h>

namespace omnitwin::m3 {
namespace {

TEST(M3Wire, FrameTimesAt100Mbits) {
  // 8 preamble/SFD + 5 header + 32 data + 4 FCS = 49 bytes of 80 ns.
  EXPECT_EQ(frame_time_ns(32), 3'920);
  EXPECT_EQ(frame_slot_ns(32), 3'920 + 960) << "12-byte inter-frame gap";
  EXPECT_EQ(frame_time_ns(0), 17 * 80);
  EXPECT_EQ(frame_time_ns(64), 81 * 80);
}

TEST(M3Wire, CascadeDelaysGrowWithEveryStationPassed) {
  const Topology t = Topology::cascade_of(3, 10.0);  // 10 m = 50 ns per cable
  EXPECT_EQ(one_way_delay_ns(t, 0), 50);
  EXPECT_EQ(one_way_delay_ns(t, 1), 2 * 50 + 500);
  EXPECT_EQ(one_way_delay_ns(t, 2), 3 * 50 + 2 * 500);
  EXPECT_EQ(tr_dly_ns(t, 2), 2 * 1'150);
}

TEST(M3Wire, StarDelaysAreTheSameForEqualCables) {
  Topology t = Topology::star_of(3, 10.0);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(one_way_delay_ns(t, k), 50 + 500 + 50) << k;
  t.cable_m[1] = 100.0;
  EXPECT_EQ(tr_dly_ns(t, 1), 2 * (50 + 500 + 500));
}

TEST(M3Wire, TopologyLimitsOfSeed000) {
  EXPECT_EQ(check(Topology::cascade_of(62, 100.0)), "");
  EXPECT_EQ(check(Topology::star_of(62, 100.0)), "");
  EXPECT_NE(check(Topology::cascade_of(63)), "");
  EXPECT_NE(check(Topology::cascade_of(0)), "");
  Topology t = Topology::cascade_of(4);
  t.cable_m[2] = 100.5;
  EXPECT_NE(check(t).find("slave 3"), std::string::npos) << check(t);
  t = Topology::star_of(4);
  t.master_cable_m = 120;
  EXPECT_NE(check(t).find("hub"), std::string::npos);
  t = Topology::cascade_of(4);
  t.forward_delay_ns = -1;
  EXPECT_NE(check(t), "");
}

CycleInputs inputs(int slaves, std::size_t bytes) {
  CycleInputs in;
  in.topology = Topology::cascade_of(slaves, 10.0);
  in.stations.assign(static_cast<std::size_t>(slaves), StationTiming{.data_bytes = bytes, .response_ns = 2'000});
  return in;
}

TEST(M3Wire, ResponseMonitoringTimeByHand) {
  const CycleInputs in = inputs(2, 32);
  // TR_DLY 100 + command 3920 + response 3920 + response time 2000 + margin 1000.
  EXPECT_EQ(t_rsp_ns(in, 0), 100 + 3'920 + 3'920 + 2'000 + 1'000);
  EXPECT_EQ(t_rsp_ns(in, 1), 1'200 + 3'920 + 3'920 + 2'000 + 1'000);
}

TEST(M3Wire, CyclePlanByHand) {
  const CycleInputs in = inputs(2, 32);
  ASSERT_EQ(check_inputs(in), "");
  const CyclePlan p = plan_cycle(in);
  ASSERT_EQ(p.t_rsp_ns.size(), 2u);
  const SimTime sync = (8 + 5 + 8 + 4 + 12) * 80;
  EXPECT_EQ(p.exchange_ns, sync + (10'940 + 960) + (12'040 + 960));
  EXPECT_EQ(p.retry_ns, 12'040 + 960) << "one slot for the slowest slave";
  EXPECT_EQ(p.int_offset_ns, p.exchange_ns + p.retry_ns);
  EXPECT_EQ(p.min_cycle_ns, p.int_offset_ns + 100'000);
}

TEST(M3Wire, MoreSlavesLongerDataAndMoreRetriesNeedLongerCycles) {
  const SimTime base = plan_cycle(inputs(8, 16)).min_cycle_ns;
  EXPECT_GT(plan_cycle(inputs(16, 16)).min_cycle_ns, base);
  EXPECT_GT(plan_cycle(inputs(8, 64)).min_cycle_ns, base);
  CycleInputs two = inputs(8, 16);
  two.retry_slots = 2;
  EXPECT_GT(plan_cycle(two).min_cycle_ns, base);
  CycleInputs star = inputs(8, 16);
  star.topology = Topology::star_of(8, 10.0);
  EXPECT_LT(plan_cycle(star).min_cycle_ns, base) << "no station passes another's frames in a star";
}

TEST(M3Wire, ATooShortCycleNamesTheShortestThatFits) {
  const CyclePlan p = plan_cycle(inputs(4, 48));
  EXPECT_EQ(check_cycle(p, p.min_cycle_ns), "");
  const std::string why = check_cycle(p, 125'000);
  ASSERT_NE(why, "");
  const SimTime us = (p.min_cycle_ns + 999) / 1000;
  EXPECT_NE(why.find("shortest cycle that fits is " + std::to_string(us) + " µs"), std::string::npos) << why;
  EXPECT_EQ(check_cycle(p, us * 1000), "");
}

TEST(M3Wire, InputsAreChecked) {
  CycleInputs in = inputs(3, 32);
  in.stations[1].data_bytes = 24;
  EXPECT_NE(check_inputs(in).find("slave 2"), std::string::npos);
  in = inputs(3, 32);
  in.stations.pop_back();
  EXPECT_NE(check_inputs(in), "");
  in = inputs(3, 32);
  in.retry_slots = 8;
  EXPECT_NE(check_inputs(in), "");
  in = inputs(3, 32);
  in.stations[0].response_ns = -5;
  EXPECT_NE(check_inputs(in), "");
}

}  // namespace
}  // namespace omnitwin::m3
