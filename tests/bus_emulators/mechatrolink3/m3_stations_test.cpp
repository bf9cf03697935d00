// Tests bus_emulators/mechatrolink3/m3_stations: N slaves built on the line, slave k at address
// 03h + k and powered on (phase 1), their frames wired both ways (a DETECT to each address is
// answered by that station alone, at the line's time), and advance() reaching every link.
#include "bus_emulators/mechatrolink3/m3_stations.hpp"

#include <gtest/gtest.h>

#include <vector>

namespace omnitwin::m3 {
namespace {

TEST(M3Stations, EverySlaveIsOnTheLineAtItsAddressAndAnswers) {
  M3Stations st(StationsConfig{.topology = Topology::cascade_of(3, 10.0), .servo = {}, .response_ns = 2'000});
  ASSERT_EQ(st.size(), 3);
  std::vector<std::uint8_t> from;
  std::vector<SimTime> at;
  st.line().attach_master([&](std::span<const std::uint8_t> f, SimTime t) {
    FrameView v;
    ASSERT_EQ(decode(f, v), FrameStatus::ok);
    from.push_back(v.src);
    at.push_back(t);
  });
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(st.link(k).address(), kFirstSlave + k);
    EXPECT_EQ(st.link(k).phase(), Phase::p1) << "powered on";
    std::vector<std::uint8_t> b(kMaxFrame);
    b.resize(encode(FrameSpec{.dst = static_cast<std::uint8_t>(kFirstSlave + k), .src = kC1Master,
                              .type = FrameType::detect, .sequence = 0, .retry = false, .data = {}},
                    b));
    st.line().from_master(b, 0);
    for (SimTime due = st.line().next_due(); due >= 0; due = st.line().next_due()) st.line().advance(due);
  }
  EXPECT_EQ(from, (std::vector<std::uint8_t>{0x03, 0x04, 0x05}));
  const Topology topo = Topology::cascade_of(3, 10.0);
  EXPECT_EQ(at[2], tr_dly_ns(topo, 2) + frame_time_ns(0) + frame_time_ns(8) + 2'000);
  st.advance(1'000'000);  // no phase 3 yet: nothing to check, nothing changes
  EXPECT_EQ(st.link(0).comm_alarm(), CommAlarm::normal);
}

}  // namespace
}  // namespace omnitwin::m3
