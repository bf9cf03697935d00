// Tests bus_emulators/canopen/co_emcy: the EMCY frame layout, the error register 0x1001 and
// the pre-defined error field 0x1003, the reset EMCY when the last error clears, the inhibit
// time 0x1015 and a disabled EMCY COB-ID.
#include "bus_emulators/canopen/co_emcy.hpp"

#include <gtest/gtest.h>

#include <vector>

#include "tests/bus_emulators/canopen/co_test_od.hpp"

namespace omnitwin::canopen {
namespace {

constexpr SimTime kMs = 1'000'000;

struct EmcyTest : ::testing::Test {
  ObjectDictionary od;
  std::vector<std::pair<can::Frame, SimTime>> sent;
  SendFn send = [this](const can::Frame& f, SimTime t) {
    sent.emplace_back(f, t);
    return true;
  };
  void SetUp() override { test::build_node_od(od); }
};

TEST_F(EmcyTest, SignalsAnErrorAndItsEnd) {
  EmcyProducer e(od, 5);
  ASSERT_TRUE(e.raise(0x8611, 0, send, {1, 2, 3, 4, 5}));
  ASSERT_EQ(sent.size(), 1u);
  EXPECT_EQ(sent[0].first, can::make_data(0x085, {0x11, 0x86, 0x21, 1, 2, 3, 4, 5}));  // generic + profile bits
  EXPECT_EQ(od.entry(0x1001, 0)->as_int(), 0x21);
  EXPECT_EQ(od.entry(0x1003, 0)->as_int(), 1);
  EXPECT_EQ(od.entry(0x1003, 1)->as_int() & 0xFFFF, 0x8611);
  e.raise(0x8611, kMs, send);  // already active: nothing new
  EXPECT_EQ(sent.size(), 1u);
  ASSERT_TRUE(e.clear(0x8611, 2 * kMs, send));
  ASSERT_EQ(sent.size(), 2u);
  EXPECT_EQ(sent[1].first, can::make_data(0x085, {0, 0, 0, 0, 0, 0, 0, 0}));
  EXPECT_EQ(od.entry(0x1001, 0)->as_int(), 0);
  EXPECT_EQ(od.entry(0x1003, 0)->as_int(), 1);  // the history stays
}

TEST_F(EmcyTest, HistoryKeepsTheNewestFirstUpToItsSize) {
  EmcyProducer e(od, 5);
  for (std::uint16_t c : {0x8110, 0x8120, 0x8130, 0x8140, 0x8210}) e.raise(c, 0, send);
  EXPECT_EQ(od.entry(0x1003, 0)->as_int(), 4);
  EXPECT_EQ(od.entry(0x1003, 1)->as_int() & 0xFFFF, 0x8210);
  EXPECT_EQ(od.entry(0x1003, 4)->as_int() & 0xFFFF, 0x8120);
  EXPECT_EQ(od.entry(0x1001, 0)->as_int(), 0x11);  // generic + communication
}

TEST_F(EmcyTest, InhibitTimeSpacesTheMessages) {
  ASSERT_EQ(od.write(0x1015, 0, OdState::preop, test::le(50, 2)), SdoAbort::none);  // 5 ms
  EmcyProducer e(od, 5);
  e.raise(0x8110, 0, send);
  e.raise(0x8120, kMs, send);
  EXPECT_EQ(sent.size(), 1u);
  e.on_time(4 * kMs, send);
  EXPECT_EQ(sent.size(), 1u);
  e.on_time(5 * kMs, send);
  ASSERT_EQ(sent.size(), 2u);
  EXPECT_EQ(sent[1].second, 5 * kMs);
  EXPECT_EQ(sent[1].first.data[0], 0x20);
}

// Outside PRE-OPERATIONAL/OPERATIONAL nothing is sent: an EMCY still waiting for the inhibit
// time is dropped, and on the way back the active errors are signalled once each.
TEST_F(EmcyTest, StoppedDropsTheQueueAndTheActiveErrorsFollowOnTheWayBack) {
  ASSERT_EQ(od.write(0x1015, 0, OdState::preop, test::le(50, 2)), SdoAbort::none);  // 5 ms
  EmcyProducer e(od, 5);
  e.raise(0x8110, 0, send);
  e.raise(0x8120, kMs, send);  // waits for the inhibit time
  e.set_nmt_state(NmtState::stopped, 2 * kMs, send);
  e.on_time(10 * kMs, send);
  e.raise(0x2310, 11 * kMs, send);
  EXPECT_EQ(sent.size(), 1u);
  EXPECT_EQ(od.entry(0x1003, 0)->as_int(), 3);
  e.set_nmt_state(NmtState::pre_operational, 20 * kMs, send);
  for (SimTime t = 21 * kMs; t <= 40 * kMs; t += kMs) e.on_time(t, send);
  ASSERT_EQ(sent.size(), 4u);
  EXPECT_EQ(sent[3].second, 30 * kMs);  // spaced by the inhibit time
  EXPECT_EQ(sent[1].first, can::make_data(0x085, {0x10, 0x81, 0x13, 0, 0, 0, 0, 0}));
  EXPECT_EQ(sent[2].first.data[1], 0x81);
  EXPECT_EQ(sent[3].first.data[1], 0x23);
  e.set_nmt_state(NmtState::operational, 50 * kMs, send);  // nothing missed: nothing sent
  EXPECT_EQ(sent.size(), 4u);
}

TEST_F(EmcyTest, AnInvalidCobIdRecordsButDoesNotSend) {
  ASSERT_EQ(od.write(0x1014, 0, OdState::preop, test::le(0x80000085, 4)), SdoAbort::none);
  EmcyProducer e(od, 5);
  e.raise(0x8110, 0, send);
  EXPECT_TRUE(sent.empty());
  EXPECT_EQ(od.entry(0x1001, 0)->as_int(), 0x11);
}

// CiA 301: only 0 may be written to 0x1003:0, and it deletes the history; any other value is
// refused with 0x06090030.
TEST_F(EmcyTest, Writing0To1003DeletesTheHistoryAndOtherValuesAreRefused) {
  EmcyProducer e(od, 5);
  e.raise(0x8110, 0, send);
  e.raise(0x8120, 0, send);
  EXPECT_EQ(od.write(0x1003, 0, OdState::preop, test::le(5, 1)), SdoAbort::value_range);
  EXPECT_EQ(od.entry(0x1003, 0)->as_int(), 2);
  ASSERT_EQ(od.write(0x1003, 0, OdState::preop, test::le(0, 1)), SdoAbort::none);
  EXPECT_EQ(od.entry(0x1003, 0)->as_int(), 0);
  for (std::uint8_t s = 1; s <= 4; ++s) EXPECT_EQ(od.entry(0x1003, s)->as_int(), 0) << int{s};
  e.raise(0x8130, 0, send);
  EXPECT_EQ(od.entry(0x1003, 0)->as_int(), 1);
  EXPECT_EQ(od.entry(0x1003, 1)->as_int() & 0xFFFF, 0x8130);
  EXPECT_EQ(od.entry(0x1003, 2)->as_int(), 0);
}

// As a PDO's: the EMCY's identifier changes only while it is invalid (bit 31 set); a new
// identifier with bit 31 clear while valid, a 29-bit one, or 0 is refused with 0x06090030.
TEST_F(EmcyTest, TheCobIdChangesOnlyWhileTheEmcyIsInvalid) {
  EmcyProducer e(od, 5);
  EXPECT_EQ(od.write(0x1014, 0, OdState::preop, test::le(0x90, 4)), SdoAbort::value_range);
  EXPECT_EQ(od.entry(0x1014, 0)->as_int(), 0x85);
  EXPECT_EQ(od.write(0x1014, 0, OdState::preop, test::le(0x85, 4)), SdoAbort::none);  // the same: fine
  EXPECT_EQ(od.write(0x1014, 0, OdState::preop, test::le(0xA0000085, 4)), SdoAbort::value_range);  // 29-bit
  EXPECT_EQ(od.write(0x1014, 0, OdState::preop, test::le(0x80000000, 4)), SdoAbort::none);
  EXPECT_EQ(od.write(0x1014, 0, OdState::preop, test::le(0x00000000, 4)), SdoAbort::value_range);  // the NMT's
  ASSERT_EQ(od.write(0x1014, 0, OdState::preop, test::le(0x80000085, 4)), SdoAbort::none);
  ASSERT_EQ(od.write(0x1014, 0, OdState::preop, test::le(0x90, 4)), SdoAbort::none);
  e.raise(0x8110, 0, send);
  ASSERT_EQ(sent.size(), 1u);
  EXPECT_EQ(sent[0].first.id, 0x90u);
}

TEST(EmcyRegister, ClassesFollowCia301) {
  EXPECT_EQ(register_bit_of(0x2310), error_register::current);
  EXPECT_EQ(register_bit_of(0x3210), error_register::voltage);
  EXPECT_EQ(register_bit_of(0x4210), error_register::temperature);
  EXPECT_EQ(register_bit_of(0x8130), error_register::communication);
  EXPECT_EQ(register_bit_of(0x8611), error_register::device_profile);
  EXPECT_EQ(register_bit_of(0xFF01), error_register::manufacturer);
}

}  // namespace
}  // namespace omnitwin::canopen
