// Tests bus_emulators/sender_gate.hpp: the first sender becomes the master and is always taken;
// another sender is counted, and refused only when asked; addresses of another length are
// another sender; an over-long address is compared on its first kMaxAddress bytes; with a
// handover time a new sender takes over from a master silent that long (a master started
// again on UDP), and never from an active one.
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
  EXPECT_TRUE(g.admit(master, 0, foreign, refused));
  EXPECT_TRUE(g.has_master());
  EXPECT_TRUE(g.admit(master, 0, foreign, refused));
  EXPECT_EQ(foreign, 0u);
  EXPECT_EQ(refused, 0u);
}

TEST(SenderGate, AnotherSenderIsCountedAndRefusedOnlyWhenAsked) {
  SenderGate g;
  std::uint64_t foreign = 0, refused = 0;
  const std::array<std::uint8_t, 6> master{2, 0, 0, 0, 0, 1}, other{2, 0, 0, 0, 0, 2};
  ASSERT_TRUE(g.admit(master, 0, foreign, refused));
  EXPECT_TRUE(g.admit(other, 0, foreign, refused));  // counted, taken
  EXPECT_EQ(foreign, 1u);
  EXPECT_EQ(refused, 0u);
  g.set_refuse(true);
  EXPECT_FALSE(g.admit(other, 0, foreign, refused));
  EXPECT_EQ(foreign, 2u);
  EXPECT_EQ(refused, 1u);
  EXPECT_TRUE(g.admit(master, 0, foreign, refused));
  EXPECT_EQ(foreign, 2u);
}

TEST(SenderGate, AnAddressOfAnotherLengthIsAnotherSender) {
  SenderGate g;
  g.set_refuse(true);
  std::uint64_t foreign = 0, refused = 0;
  const std::vector<std::uint8_t> v4(16, 7), v6(28, 7);  // the same bytes, a longer address
  ASSERT_TRUE(g.admit(v4, 0, foreign, refused));
  EXPECT_FALSE(g.admit(v6, 0, foreign, refused));
  EXPECT_FALSE(g.admit(std::span<const std::uint8_t>(v4.data(), 15), 0, foreign, refused));
  EXPECT_EQ(refused, 2u);
}

TEST(SenderGate, AnOverLongAddressIsComparedOnItsFirstBytes) {
  SenderGate g;
  g.set_refuse(true);
  std::uint64_t foreign = 0, refused = 0;
  std::vector<std::uint8_t> a(SenderGate::kMaxAddress + 8, 1);
  ASSERT_TRUE(g.admit(a, 0, foreign, refused));
  a.back() = 9;  // past the bytes kept
  EXPECT_TRUE(g.admit(a, 0, foreign, refused));
  a[0] = 9;
  EXPECT_FALSE(g.admit(a, 0, foreign, refused));
}

TEST(SenderGate, ANewSenderTakesOverFromAMasterSilentForTheHandoverTime) {
  SenderGate g;
  g.set_refuse(true);
  g.set_handover(500'000'000);
  std::uint64_t foreign = 0, refused = 0;
  const std::array<std::uint8_t, 6> first{2, 0, 0, 0, 0, 1}, again{2, 0, 0, 0, 0, 2}, third{2, 0, 0, 0, 0, 3};
  ASSERT_TRUE(g.admit(first, 1'000'000'000, foreign, refused));
  // 0.4 s after the master's last frame: still its bus.
  EXPECT_FALSE(g.admit(again, 1'400'000'000, foreign, refused));
  EXPECT_EQ(g.changes(), 0u);
  // 0.5 s: the new sender is the master; a third program is foreign.
  EXPECT_TRUE(g.admit(again, 1'500'000'000, foreign, refused));
  EXPECT_EQ(g.changes(), 1u);
  EXPECT_TRUE(g.admit(again, 1'600'000'000, foreign, refused));
  EXPECT_FALSE(g.admit(third, 1'700'000'000, foreign, refused));
  EXPECT_EQ(foreign, 2u);
  EXPECT_EQ(refused, 2u);
}

TEST(SenderGate, AnActiveMasterKeepsTheBusAndWithoutAHandoverTimeASilentOneToo) {
  SenderGate g;
  g.set_handover(500'000'000);
  std::uint64_t foreign = 0, refused = 0;
  const std::array<std::uint8_t, 6> master{2, 0, 0, 0, 0, 1}, other{2, 0, 0, 0, 0, 2};
  // The master sends every 0.1 s; another program between its frames for 2 s stays foreign.
  for (std::int64_t t = 0; t < 2'000'000'000; t += 100'000'000) {
    ASSERT_TRUE(g.admit(master, t, foreign, refused));
    EXPECT_TRUE(g.admit(other, t + 50'000'000, foreign, refused));
  }
  EXPECT_EQ(g.changes(), 0u);
  EXPECT_EQ(foreign, 20u);
  SenderGate never;  // the default: the first sender is the master for good
  ASSERT_TRUE(never.admit(master, 0, foreign, refused));
  never.admit(other, 3'600'000'000'000, foreign, refused);
  EXPECT_EQ(never.changes(), 0u);
  EXPECT_EQ(foreign, 21u);
}

// A master only stalled (SIGSTOP, a host stall) while another program sends: the other takes
// over after the handover time, but the master heard again takes the bus back, and the frames
// taken from the other meanwhile count as foreign. It stayed locked out for good, every frame
// of its own refused (found in review).
TEST(SenderGate, AStalledMasterHeardAgainTakesTheBusBack) {
  SenderGate g;
  g.set_refuse(true);
  g.set_handover(500'000'000);
  std::uint64_t foreign = 0, refused = 0;
  const std::array<std::uint8_t, 6> master{2, 0, 0, 0, 0, 1}, other{2, 0, 0, 0, 0, 2};
  ASSERT_TRUE(g.admit(master, 0, foreign, refused));
  EXPECT_TRUE(g.admit(other, 600'000'000, foreign, refused));  // the master stalled: taken over
  EXPECT_TRUE(g.admit(other, 800'000'000, foreign, refused));
  EXPECT_EQ(g.changes(), 1u);
  EXPECT_TRUE(g.admit(master, 1'000'000'000, foreign, refused));  // back
  EXPECT_EQ(g.changes(), 0u);
  EXPECT_EQ(foreign, 2u) << "the other's two frames while it held the bus";
  EXPECT_FALSE(g.admit(other, 1'100'000'000, foreign, refused));
  EXPECT_TRUE(g.admit(master, 1'200'000'000, foreign, refused));
  EXPECT_EQ(foreign, 3u);
  EXPECT_EQ(refused, 1u);
}

}  // namespace
}  // namespace omnitwin::bus_emulators
