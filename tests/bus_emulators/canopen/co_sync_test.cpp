// Tests bus_emulators/canopen/co_sync: the SYNC producer's period and counter, SYNC decoding
// with its length check, and the TIME_OF_DAY stamp both ways.
#include "bus_emulators/canopen/co_sync.hpp"

#include <gtest/gtest.h>

#include <vector>

namespace omnitwin::canopen {
namespace {

constexpr SimTime kMs = 1'000'000;

TEST(SyncProducer, SendsEveryPeriodWithAWrappingCounter) {
  std::vector<std::pair<can::Frame, SimTime>> sent;
  SendFn send = [&](const can::Frame& f, SimTime t) {
    sent.emplace_back(f, t);
    return true;
  };
  SyncProducer p({cob::sync, kMs, 3});
  p.start(10 * kMs);
  EXPECT_EQ(p.on_time(9 * kMs, send), 0);
  EXPECT_EQ(p.on_time(14 * kMs, send), 5);
  ASSERT_EQ(sent.size(), 5u);
  EXPECT_EQ(sent[0].second, 10 * kMs);
  EXPECT_EQ(sent[4].second, 14 * kMs);
  std::vector<int> counters;
  for (auto& s : sent) counters.push_back(s.first.data[0]);
  EXPECT_EQ(counters, (std::vector<int>{1, 2, 3, 1, 2}));
  EXPECT_EQ(sent[0].first.id, 0x80u);
  EXPECT_EQ(sent[0].first.dlc, 1);
}

TEST(SyncProducer, WithoutCounterSendsNoData) {
  int n = 0;
  SyncProducer p({cob::sync, kMs, 0});
  p.send_one(0, [&](const can::Frame& f, SimTime) {
    EXPECT_EQ(f.dlc, 0);
    ++n;
    return true;
  });
  EXPECT_EQ(n, 1);
}

TEST(DecodeSync, ChecksTheLength) {
  std::uint8_t c = 99;
  EXPECT_EQ(decode_sync(can::make_data(0x80, {}), 0x80, 0, c), SyncDecode::ok);
  EXPECT_EQ(c, 0);
  EXPECT_EQ(decode_sync(can::make_data(0x80, {7}), 0x80, 10, c), SyncDecode::ok);
  EXPECT_EQ(c, 7);
  EXPECT_EQ(decode_sync(can::make_data(0x80, {7}), 0x80, 0, c), SyncDecode::bad_length);
  EXPECT_EQ(decode_sync(can::make_data(0x80, {}), 0x80, 10, c), SyncDecode::bad_length);
  EXPECT_EQ(decode_sync(can::make_data(0x81, {}), 0x80, 0, c), SyncDecode::not_sync);
}

TEST(TimeOfDay, EncodesAndDecodes) {
  const TimeOfDay t = time_of_day((15'000LL * 86'400'000 + 45'296'789LL) * 1'000'000);  // 12:34:56.789
  EXPECT_EQ(t.days, 15000);
  EXPECT_EQ(t.ms, 45'296'789u);
  const can::Frame f = encode_time(t);
  EXPECT_EQ(f, can::make_data(0x100, {0x95, 0x2C, 0xB3, 0x02, 0x98, 0x3A}));
  const auto back = decode_time(f);
  ASSERT_TRUE(back);
  EXPECT_EQ(back->ms, t.ms);
  EXPECT_EQ(back->days, t.days);
  EXPECT_FALSE(decode_time(can::make_data(0x100, {1, 2, 3})));
}

}  // namespace
}  // namespace omnitwin::canopen
