// Tests bus_emulators/mechatrolink3/m3_line: frames reach their station when their last bit
// arrives (one-way delay of m3_wire + frame time), broadcast reaches every slave and unicast
// only its own, slaves' frames reach the master (later by a fault's extra delay), deliveries come in time order, an
// unreachable slave and the fault hook drop or corrupt frames (the FCS then fails), and a
// full queue counts an overflow instead of allocating.
#include "bus_emulators/mechatrolink3/m3_line.hpp"

#include <gtest/gtest.h>

#include <stdexcept>
#include <vector>

namespace omnitwin::m3 {
namespace {

struct Got {
  int who;  // -1 master, else slave
  SimTime t;
  std::vector<std::uint8_t> bytes;
};

std::vector<std::uint8_t> frame(std::uint8_t dst, FrameType type = FrameType::detect, std::uint8_t src = kC1Master) {
  std::vector<std::uint8_t> b(kMaxFrame);
  std::vector<std::uint8_t> d(type == FrameType::sync || type == FrameType::detect_reply ? 8 : 0, 0);
  b.resize(encode(FrameSpec{.dst = dst, .src = src, .type = type, .data = d}, b));
  return b;
}

class M3Line : public ::testing::Test {
 protected:
  Line line{Topology::cascade_of(3, 10.0)};
  std::vector<Got> got;
  void SetUp() override {
    line.attach_master([this](std::span<const std::uint8_t> f, SimTime t) { got.push_back({-1, t, {f.begin(), f.end()}}); });
    for (int k = 0; k < 3; ++k)
      line.attach_slave(k, [this, k](std::span<const std::uint8_t> f, SimTime t) { got.push_back({k, t, {f.begin(), f.end()}}); });
  }
};

TEST_F(M3Line, UnicastReachesItsSlaveWhenTheLastBitArrives) {
  line.from_master(frame(0x05), 1'000);
  EXPECT_EQ(line.next_due(), 1'000 + (3 * 50 + 2 * 500) + frame_time_ns(0));
  line.advance(1'000'000);
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0].who, 2);
  EXPECT_EQ(got[0].t, 1'000 + 1'150 + frame_time_ns(0));
  EXPECT_EQ(line.next_due(), -1);
}

TEST_F(M3Line, AnExtraDelayMakesOneSlavesFramesLateUntilItIsCleared) {
  line.set_extra_delay(1, 50'000);
  line.from_slave(1, frame(kC1Master, FrameType::detect_reply, 0x04), 0);
  line.from_slave(0, frame(kC1Master, FrameType::detect_reply, 0x03), 0);
  line.advance(1'000'000);
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0].bytes[1], 0x03) << "the undelayed slave's frame comes first";
  EXPECT_EQ(got[1].t, 600 + frame_time_ns(8) + 50'000);
  got.clear();
  line.set_extra_delay(1, 0);
  line.from_slave(1, frame(kC1Master, FrameType::detect_reply, 0x04), 2'000'000);
  line.advance(3'000'000);
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0].t, 2'000'000 + 600 + frame_time_ns(8));
}

TEST_F(M3Line, BroadcastReachesEverySlaveNearestFirst) {
  line.from_master(frame(kBroadcast, FrameType::sync), 0);
  line.advance(1'000'000);
  ASSERT_EQ(got.size(), 3u);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(got[static_cast<std::size_t>(k)].who, k);
  EXPECT_LT(got[0].t, got[1].t);
}

TEST_F(M3Line, ASlavesFrameReachesTheMasterAndNothingIsEarly) {
  line.from_slave(1, frame(kC1Master, FrameType::detect_reply, 0x04), 10'000);
  line.advance(10'000 + 600 + frame_time_ns(8) - 1);
  EXPECT_TRUE(got.empty());
  line.advance(10'000 + 600 + frame_time_ns(8));
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0].who, -1);
}

TEST_F(M3Line, UnreachableSlavesAndTheFaultHookDropOrCorrupt) {
  line.set_reachable(2, false);
  line.from_master(frame(0x05), 0);
  line.from_slave(2, frame(kC1Master, FrameType::delay_reply, 0x05), 0);
  EXPECT_EQ(line.dropped(), 2u);
  line.set_fault_hook([](bool, int k, std::span<const std::uint8_t>) { return k == 0 ? Fate::corrupt : Fate::drop; });
  line.from_master(frame(0x03), 0);
  line.from_master(frame(0x04), 0);
  line.advance(1'000'000);
  ASSERT_EQ(got.size(), 1u);
  FrameView v;
  EXPECT_EQ(decode(got[0].bytes, v), FrameStatus::bad_fcs);
  EXPECT_EQ(line.corrupted(), 1u);
  EXPECT_EQ(line.dropped(), 3u);
}

TEST_F(M3Line, ACutCableDropsEveryStationBehindIt) {
  line.cut_cable(0);  // between slave 0 and slave 1
  line.from_master(frame(kBroadcast, FrameType::sync), 0);
  line.advance(1'000'000);
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0].who, 0);
  line.mend_cable();
  line.from_master(frame(kBroadcast, FrameType::sync), 2'000'000);
  line.advance(3'000'000);
  EXPECT_EQ(got.size(), 4u);
  Line star(Topology::star_of(3));
  star.cut_cable(0);  // the hub's cable to slave 1 only
  int reached = 0;
  for (int k = 0; k < 3; ++k) star.attach_slave(k, [&](std::span<const std::uint8_t>, SimTime) { ++reached; });
  star.from_master(frame(kBroadcast, FrameType::sync), 0);
  star.advance(1'000'000);
  EXPECT_EQ(reached, 2);
}

TEST_F(M3Line, AFullQueueCountsAnOverflow) {
  Line small(Topology::cascade_of(1), 2);
  for (int i = 0; i < 3; ++i) small.from_master(frame(0x03), i);
  EXPECT_EQ(small.overflow(), 1u);
}

TEST(M3LineSetUp, ABadTopologyIsAProgrammerError) {
  EXPECT_THROW(Line(Topology::cascade_of(0)), std::invalid_argument);
}

}  // namespace
}  // namespace omnitwin::m3
