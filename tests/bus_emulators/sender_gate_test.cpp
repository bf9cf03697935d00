// Tests bus_emulators/sender_gate.hpp: the first sender becomes the master and is always taken;
// another sender is counted, and refused only when asked; addresses of another length are
// another sender; an over-long address is compared on its first kMaxAddress bytes.
#include "bus_emulators/sender_gate.hpp"

#include <gtest/gtest.h>

#include <array>
#include <vector>

namespace omnitwin::bus_emulators {
namespace {

TEST(SenderGate, TheFirstSenderIsTheMasterAndIsAlwaysTaken) {
  SenderGate g;
  g.set_refuse(true);
  std::uint64_t foreign = 0, refused = 0;
  const std::array<std::uint8_t, 6> master{2, 0, 0, 0, 0, 1};
  EXPECT_FALSE(g.has_master());
  EXPECT_TRUE(g.admit(master, foreign, refused));
  EXPECT_TRUE(g.has_master());
  EXPECT_TRUE(g.admit(master, foreign, refused));
  EXPECT_EQ(foreign, 0u);
  EXPECT_EQ(refused, 0u);
}

TEST(SenderGate, AnotherSenderIsCountedAndRefusedOnlyWhenAsked) {
  SenderGate g;
  std::uint64_t foreign = 0, refused = 0;
  const std::array<std::uint8_t, 6> master{2, 0, 0, 0, 0, 1}, other{2, 0, 0, 0, 0, 2};
  ASSERT_TRUE(g.admit(master, foreign, refused));
  EXPECT_TRUE(g.admit(other, foreign, refused));  // counted, taken
  EXPECT_EQ(foreign, 1u);
  EXPECT_EQ(refused, 0u);
  g.set_refuse(true);
  EXPECT_FALSE(g.admit(other, foreign, refused));
  EXPECT_EQ(foreign, 2u);
  EXPECT_EQ(refused, 1u);
  EXPECT_TRUE(g.admit(master, foreign, refused));
  EXPECT_EQ(foreign, 2u);
}

TEST(SenderGate, AnAddressOfAnotherLengthIsAnotherSender) {
  SenderGate g;
  g.set_refuse(true);
  std::uint64_t foreign = 0, refused = 0;
  const std::vector<std::uint8_t> v4(16, 7), v6(28, 7);  // the same bytes, a longer address
  ASSERT_TRUE(g.admit(v4, foreign, refused));
  EXPECT_FALSE(g.admit(v6, foreign, refused));
  EXPECT_FALSE(g.admit(std::span<const std::uint8_t>(v4.data(), 15), foreign, refused));
  EXPECT_EQ(refused, 2u);
}

TEST(SenderGate, AnOverLongAddressIsComparedOnItsFirstBytes) {
  SenderGate g;
  g.set_refuse(true);
  std::uint64_t foreign = 0, refused = 0;
  std::vector<std::uint8_t> a(SenderGate::kMaxAddress + 8, 1);
  ASSERT_TRUE(g.admit(a, foreign, refused));
  a.back() = 9;  // past the bytes kept
  EXPECT_TRUE(g.admit(a, foreign, refused));
  a[0] = 9;
  EXPECT_FALSE(g.admit(a, foreign, refused));
}

}  // namespace
}  // namespace omnitwin::bus_emulators
