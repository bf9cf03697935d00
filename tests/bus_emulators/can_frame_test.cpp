// Tests bus_emulators/can/can_frame: identifier ranges per format, payload sizes per kind,
// equality over meaningful bytes only, and the text form used in logs.
#include "bus_emulators/can/can_frame.hpp"

#include <gtest/gtest.h>

namespace omnitwin::can {
namespace {

TEST(CanFrame, IdentifierRangeDependsOnFormat) {
  EXPECT_TRUE(make_data(0x7FF, {}).valid());
  EXPECT_THROW(make_data(0x800, {}), std::invalid_argument);
  EXPECT_TRUE(make_data(0x1FFFFFFF, {1}, true).valid());
  EXPECT_THROW(make_data(0x20000000, {}, true), std::invalid_argument);
  EXPECT_THROW(make_data(1, {1, 2, 3, 4, 5, 6, 7, 8, 9}), std::invalid_argument);
}

TEST(CanFrame, RemoteFramesCarryADlcButNoPayload) {
  const Frame r = make_remote(0x000, 2);
  EXPECT_EQ(r.dlc, 2);
  EXPECT_EQ(r.payload_size(), 0);
  EXPECT_THROW(make_remote(0x10, 9), std::invalid_argument);
}

TEST(CanFrame, EqualityIgnoresBytesBeyondTheDlc) {
  Frame a = make_data(0x102, {2, 0, 0, 0, 0});
  Frame b = a;
  b.data[7] = 0xAA;  // not on the wire
  EXPECT_EQ(a, b);
  b.data[4] = 1;
  EXPECT_FALSE(a == b);
}

TEST(CanFrame, TextFormMatchesTheThesisCaptures) {
  EXPECT_EQ(to_string(make_data(0x102, {0x02, 0, 0, 0, 0})), "0x102 [5] 02 00 00 00 00");
  EXPECT_EQ(to_string(make_remote(0x000)), "0x000 R [0]");
  EXPECT_EQ(to_string(make_data(0x1ABCDEF0, {0x11}, true)), "0x1ABCDEF0 X [1] 11");
}

}  // namespace
}  // namespace omnitwin::can
