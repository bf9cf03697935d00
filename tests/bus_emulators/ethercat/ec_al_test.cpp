// Tests bus_emulators/ethercat/ec_al: the AL state machine table — every legal and illegal
// transition, unknown requested states, the error flag with and without acknowledge, and names.
#include "bus_emulators/ethercat/ec_al.hpp"

#include <gtest/gtest.h>

namespace omnitwin::ethercat {
namespace {

constexpr AlState kAll[] = {AlState::init, AlState::preop, AlState::boot, AlState::safeop, AlState::op};

TEST(EcAl, LegalTransitionsAreExactlyTheListedOnes) {
  int legal = 0;
  for (AlState from : kAll) {
    for (AlState to : kAll) {
      if (from != to && al_transition_legal(from, to)) ++legal;
    }
  }
  EXPECT_EQ(legal, 11);
  EXPECT_TRUE(al_transition_legal(AlState::init, AlState::preop));
  EXPECT_TRUE(al_transition_legal(AlState::init, AlState::boot));
  EXPECT_TRUE(al_transition_legal(AlState::safeop, AlState::op));
  EXPECT_TRUE(al_transition_legal(AlState::op, AlState::init));
  EXPECT_TRUE(al_transition_legal(AlState::boot, AlState::init));
  EXPECT_FALSE(al_transition_legal(AlState::init, AlState::safeop));
  EXPECT_FALSE(al_transition_legal(AlState::init, AlState::op));
  EXPECT_FALSE(al_transition_legal(AlState::preop, AlState::op));
  EXPECT_FALSE(al_transition_legal(AlState::preop, AlState::boot));
  EXPECT_FALSE(al_transition_legal(AlState::boot, AlState::preop));
  EXPECT_FALSE(al_transition_legal(AlState::op, AlState::boot));
}

TEST(EcAl, DecisionsWithoutError) {
  AlDecision d = al_decide(AlState::init, false, 0x0002);
  EXPECT_EQ(d.transition, AlTransition::legal);
  EXPECT_EQ(d.target, AlState::preop);
  EXPECT_FALSE(d.clear_error);
  d = al_decide(AlState::init, false, 0x0008);
  EXPECT_EQ(d.transition, AlTransition::invalid);
  d = al_decide(AlState::preop, false, 0x0002);
  EXPECT_EQ(d.transition, AlTransition::stay);
  for (std::uint16_t bad : {0x0000, 0x0005, 0x0006, 0x0007, 0x0009, 0x000F}) {
    EXPECT_EQ(al_decide(AlState::preop, false, bad).transition, AlTransition::unknown_state) << bad;
  }
  // The acknowledge bit without a pending error changes nothing.
  d = al_decide(AlState::safeop, false, 0x0018);
  EXPECT_EQ(d.transition, AlTransition::legal);
  EXPECT_FALSE(d.clear_error);
}

TEST(EcAl, ErrorNeedsAcknowledgeExceptForInit) {
  EXPECT_EQ(al_decide(AlState::safeop, true, 0x0008).transition, AlTransition::ignored);
  EXPECT_EQ(al_decide(AlState::safeop, true, 0x0004).transition, AlTransition::ignored);
  AlDecision d = al_decide(AlState::safeop, true, 0x0001);
  EXPECT_EQ(d.transition, AlTransition::legal);
  EXPECT_TRUE(d.clear_error) << "INIT acknowledges the error (0xX1 is an acknowledge)";
  d = al_decide(AlState::safeop, true, 0x0014);
  EXPECT_EQ(d.transition, AlTransition::stay);
  EXPECT_TRUE(d.clear_error);
  d = al_decide(AlState::safeop, true, 0x0018);
  EXPECT_EQ(d.transition, AlTransition::legal);
  EXPECT_TRUE(d.clear_error);
  d = al_decide(AlState::preop, true, 0x0013);
  EXPECT_EQ(d.transition, AlTransition::invalid);
  EXPECT_TRUE(d.clear_error);
}

TEST(EcAl, NamesAndRanks) {
  EXPECT_STREQ(to_string(AlState::safeop), "SAFE-OP");
  EXPECT_STREQ(to_string(AlStatusCode::watchdog), "sync manager watchdog");
  EXPECT_STREQ(to_string(static_cast<AlStatusCode>(0x7777)), "?");
  EXPECT_LT(al_rank(AlState::preop), al_rank(AlState::safeop));
  EXPECT_EQ(al_rank(AlState::boot), al_rank(AlState::preop));
  EXPECT_TRUE(al_state_valid(8));
  EXPECT_FALSE(al_state_valid(5));
}

}  // namespace
}  // namespace omnitwin::ethercat
