// Tests the CiA 402 power drive state machine (cia402_fsa): controlword command decoding
// (bits 7,3,2,1,0 per facts/cia402.md), every transition 0–16 taken by the controlword or
// its event, the statusword state bits of each state (golden values from the fact sheet's
// decoding table, with bit 4 voltage enabled and bit 9 remote), statusword decoding with
// don't-care bits, and the fault-reset rising-edge semantics of bit 7 — both on the Fsa
// alone and through a Cia402Drive's statusword.
#include "bus_emulators/drive/cia402_fsa.hpp"

#include <gtest/gtest.h>

#include <vector>

#include "bus_emulators/drive/cia402_drive.hpp"
#include "drive_rig.hpp"

namespace omnitwin::drive {
namespace {

std::vector<int> transitions(const Fsa& f) {
  int n = 0;
  const std::uint8_t* t = f.last_transitions(n);
  return std::vector<int>(t, t + n);
}

TEST(Cia402Fsa, DecodesControlwordCommands) {
  EXPECT_EQ(decode_controlword(0x0006), FsaCommand::shutdown);
  EXPECT_EQ(decode_controlword(0x000E), FsaCommand::shutdown);  // bit 3 don't care
  EXPECT_EQ(decode_controlword(0x0007), FsaCommand::switch_on);
  EXPECT_EQ(decode_controlword(0x000F), FsaCommand::enable_operation);
  EXPECT_EQ(decode_controlword(0x0000), FsaCommand::disable_voltage);
  EXPECT_EQ(decode_controlword(0x000D), FsaCommand::disable_voltage);  // 0--0-
  EXPECT_EQ(decode_controlword(0x0002), FsaCommand::quick_stop);
  EXPECT_EQ(decode_controlword(0x000B), FsaCommand::quick_stop);  // 0-01-
  EXPECT_EQ(decode_controlword(0x0080), FsaCommand::none);
  EXPECT_EQ(decode_controlword(0x008F), FsaCommand::none);
  EXPECT_EQ(decode_controlword(0x011F), FsaCommand::enable_operation);  // mode bits ignored
}

TEST(Cia402Fsa, DecodesStatuswordTableWithDontCares) {
  EXPECT_EQ(decode_statusword(0x0000), State::not_ready_to_switch_on);
  EXPECT_EQ(decode_statusword(0x0020), State::not_ready_to_switch_on);
  EXPECT_EQ(decode_statusword(0x0040), State::switch_on_disabled);
  EXPECT_EQ(decode_statusword(0x0260), State::switch_on_disabled);
  EXPECT_EQ(decode_statusword(0x0231), State::ready_to_switch_on);
  EXPECT_EQ(decode_statusword(0x0233), State::switched_on);
  EXPECT_EQ(decode_statusword(0x0637), State::operation_enabled);
  EXPECT_EQ(decode_statusword(0x0217), State::quick_stop_active);
  EXPECT_EQ(decode_statusword(0x000F), State::fault_reaction_active);
  EXPECT_EQ(decode_statusword(0x002F), State::fault_reaction_active);
  EXPECT_EQ(decode_statusword(0x0008), State::fault);
  EXPECT_EQ(decode_statusword(0x0238), State::fault);
  for (State s : {State::switch_on_disabled, State::ready_to_switch_on, State::switched_on,
                  State::operation_enabled, State::quick_stop_active,
                  State::fault_reaction_active, State::fault})
    EXPECT_EQ(decode_statusword(state_bits(s)), s) << to_string(s);
}

TEST(Cia402Fsa, PowerOnTakesTransitions0And1) {
  Fsa f;
  EXPECT_EQ(f.state(), State::not_ready_to_switch_on);
  f.step(0, {}, 2, 2);
  EXPECT_EQ(f.state(), State::switch_on_disabled);
  EXPECT_EQ(transitions(f), (std::vector<int>{0, 1}));
}

struct Case {
  State from;
  std::uint16_t controlword;
  int transition;
  State to;
};

TEST(Cia402Fsa, EveryControlwordTransition) {
  const Case cases[] = {
      {State::switch_on_disabled, cw::kShutdown, 2, State::ready_to_switch_on},
      {State::ready_to_switch_on, cw::kSwitchOn, 3, State::switched_on},
      {State::switched_on, cw::kEnableOperation, 4, State::operation_enabled},
      {State::operation_enabled, cw::kDisableOperation, 5, State::switched_on},
      {State::switched_on, cw::kShutdown, 6, State::ready_to_switch_on},
      {State::ready_to_switch_on, cw::kDisableVoltage, 7, State::switch_on_disabled},
      {State::ready_to_switch_on, cw::kQuickStop, 7, State::switch_on_disabled},
      {State::operation_enabled, cw::kShutdown, 8, State::ready_to_switch_on},
      {State::operation_enabled, cw::kDisableVoltage, 9, State::switch_on_disabled},
      {State::switched_on, cw::kDisableVoltage, 10, State::switch_on_disabled},
      {State::switched_on, cw::kQuickStop, 10, State::switch_on_disabled},
      {State::operation_enabled, cw::kQuickStop, 11, State::quick_stop_active},
      {State::quick_stop_active, cw::kDisableVoltage, 12, State::switch_on_disabled},
  };
  for (const Case& c : cases) {
    Fsa f;
    f.step(0x80, {}, 6, 2);  // power on, bit 7 high: no edge later
    f.force(c.from);
    const int t = f.step(c.controlword, {}, 6, 2);
    EXPECT_EQ(t, c.transition) << to_string(c.from) << " cw " << c.controlword;
    EXPECT_EQ(f.state(), c.to) << to_string(c.from) << " cw " << c.controlword;
  }
}

TEST(Cia402Fsa, SwitchOnPlusEnableOperationChains3And4) {
  Fsa f;
  f.step(0, {}, 2, 2);
  f.step(cw::kShutdown, {}, 2, 2);
  f.step(cw::kEnableOperation, {}, 2, 2);
  EXPECT_EQ(f.state(), State::operation_enabled);
  EXPECT_EQ(transitions(f), (std::vector<int>{3, 4}));
}

TEST(Cia402Fsa, IllegalCommandsLeaveTheState) {
  Fsa f;
  f.step(0, {}, 2, 2);
  f.step(cw::kEnableOperation, {}, 2, 2);  // not legal in switch on disabled
  EXPECT_EQ(f.state(), State::switch_on_disabled);
  f.step(cw::kSwitchOn, {}, 2, 2);
  EXPECT_EQ(f.state(), State::switch_on_disabled);
}

TEST(Cia402Fsa, QuickStopOptionsDecideTransition12Or16) {
  // Options 1–4: transition 12 once the stop finished.
  Fsa a;
  a.force(State::quick_stop_active);
  EXPECT_EQ(a.step(cw::kQuickStop, {}, 2, 2), kNoTransition);
  EXPECT_EQ(a.state(), State::quick_stop_active);
  FsaEvents done;
  done.stop_finished = true;
  EXPECT_EQ(a.step(cw::kQuickStop, done, 2, 2), 12);
  EXPECT_EQ(a.state(), State::switch_on_disabled);
  // Options 5–8: stays, enable operation → 16.
  Fsa b;
  b.force(State::quick_stop_active);
  EXPECT_EQ(b.step(cw::kQuickStop, done, 6, 2), kNoTransition);
  EXPECT_EQ(b.state(), State::quick_stop_active);
  EXPECT_EQ(b.step(cw::kEnableOperation, done, 6, 2), 16);
  EXPECT_EQ(b.state(), State::operation_enabled);
  // Option 0: 11 and 12 in one period.
  Fsa c;
  c.force(State::operation_enabled);
  c.step(cw::kQuickStop, {}, 0, 2);
  EXPECT_EQ(c.state(), State::switch_on_disabled);
  EXPECT_EQ(transitions(c), (std::vector<int>{11, 12}));
}

// A fault with the power stage off (here SWITCHED ON) has no motion to stop: 13 and 14 in the
// same period, so no period runs in FAULT REACTION ACTIVE, whose power stage is on (found by
// a protocol review: a watchdog fault of a disabled drive released its brake for a period).
TEST(Cia402Fsa, AFaultWithThePowerStageOffGoesToFaultAtOnce) {
  for (const State from : {State::switch_on_disabled, State::ready_to_switch_on, State::switched_on}) {
    Fsa f;
    f.step(0, {}, 2, 2);
    f.force(from);
    FsaEvents err;
    err.fault = true;
    EXPECT_EQ(f.step(cw::kSwitchOn, err, 2, 2), 14) << static_cast<int>(from);
    EXPECT_EQ(transitions(f), (std::vector<int>{13, 14}));
    EXPECT_EQ(f.state(), State::fault);
  }
}

TEST(Cia402Fsa, FaultReactionThenFaultThenResetOnRisingEdge) {
  Fsa f;
  f.step(0, {}, 2, 2);
  f.force(State::operation_enabled);
  FsaEvents err;
  err.fault = true;
  EXPECT_EQ(f.step(cw::kEnableOperation, err, 2, 2), 13);
  EXPECT_EQ(f.state(), State::fault_reaction_active);
  EXPECT_EQ(f.step(cw::kEnableOperation, {}, 2, 2), kNoTransition);  // still decelerating
  FsaEvents done;
  done.stop_finished = true;
  EXPECT_EQ(f.step(cw::kEnableOperation, done, 2, 2), 14);
  EXPECT_EQ(f.state(), State::fault);
  // Commands do not leave fault; bit 7 rising does.
  f.step(cw::kShutdown, {}, 2, 2);
  EXPECT_EQ(f.state(), State::fault);
  EXPECT_EQ(f.step(cw::kFaultReset, {}, 2, 2), 15);
  EXPECT_EQ(f.state(), State::switch_on_disabled);
  // Bit 7 still high: no command is taken, no second reset.
  f.step(cw::kFaultReset | cw::kShutdown, {}, 2, 2);
  EXPECT_EQ(f.state(), State::switch_on_disabled);
}

TEST(Cia402Fsa, FaultReactionOption0Chains13And14) {
  Fsa f;
  f.force(State::switched_on);
  FsaEvents err;
  err.fault = true;
  f.step(cw::kSwitchOn, err, 2, 0);
  EXPECT_EQ(f.state(), State::fault);
  EXPECT_EQ(transitions(f), (std::vector<int>{13, 14}));
}

TEST(Cia402Fsa, FaultResetNeedsAnEdgeNotALevel) {
  Fsa f;
  f.step(0, {}, 2, 0);
  FsaEvents err;
  err.fault = true;
  f.step(cw::kFaultReset, err, 2, 0);  // bit 7 rises while the error occurs
  EXPECT_EQ(f.state(), State::fault);
  f.step(cw::kFaultReset, {}, 2, 0);  // held high: no edge
  EXPECT_EQ(f.state(), State::fault);
  f.step(0, {}, 2, 0);
  EXPECT_EQ(f.state(), State::fault);
  f.step(cw::kFaultReset, {}, 2, 0);  // 0 → 1
  EXPECT_EQ(f.state(), State::switch_on_disabled);
}

// ---- Through the drive: statusword golden values for every transition.

using testing::Rig;

TEST(Cia402FsaDrive, StatuswordGoldenValuesAlongTransitions2To16) {
  Rig r;
  r.o().quick_stop_option = 6;  // hold in quick stop active (16 possible)
  r.step();
  EXPECT_EQ(r.sw(), 0x0250);  // switch on disabled
  r.o().controlword = cw::kShutdown;
  r.step();
  EXPECT_EQ(r.sw(), 0x0231);  // 2 → ready to switch on
  r.o().controlword = cw::kSwitchOn;
  r.step();
  EXPECT_EQ(r.sw(), 0x0233);  // 3 → switched on
  r.o().controlword = cw::kEnableOperation;
  r.step();
  EXPECT_EQ(r.sw(), 0x0237);  // 4 → operation enabled (mode none: no target reached)
  EXPECT_FALSE(r.last.brake_engaged);
  EXPECT_TRUE(r.last.power);
  r.o().controlword = cw::kDisableOperation;
  r.step();
  EXPECT_EQ(r.sw(), 0x0233);  // 5
  EXPECT_TRUE(r.last.brake_engaged);
  r.o().controlword = cw::kShutdown;
  r.step();
  EXPECT_EQ(r.sw(), 0x0231);  // 6
  r.o().controlword = cw::kDisableVoltage;
  r.step();
  EXPECT_EQ(r.sw(), 0x0250);  // 7
  r.o().controlword = cw::kShutdown;
  r.step();
  r.o().controlword = cw::kEnableOperation;
  r.step();  // 3+4
  EXPECT_EQ(r.sw(), 0x0237);
  r.o().controlword = cw::kShutdown;
  r.step();
  EXPECT_EQ(r.sw(), 0x0231);  // 8
  r.o().controlword = cw::kEnableOperation;
  r.step();
  r.o().controlword = cw::kDisableVoltage;
  r.step();
  EXPECT_EQ(r.sw(), 0x0250);  // 9
  r.o().controlword = cw::kShutdown;
  r.step();
  r.o().controlword = cw::kSwitchOn;
  r.step();
  r.o().controlword = cw::kQuickStop;
  r.step();
  EXPECT_EQ(r.sw(), 0x0250);  // 10
  r.o().controlword = cw::kShutdown;
  r.step();
  r.o().controlword = cw::kEnableOperation;
  r.step();
  r.o().controlword = cw::kQuickStop;
  r.step();
  EXPECT_EQ(r.sw(), 0x0617);  // 11 → quick stop active, standing: target reached
  r.o().controlword = cw::kEnableOperation;
  r.step();
  EXPECT_EQ(r.sw(), 0x0237);  // 16
  r.o().controlword = cw::kQuickStop;
  r.step();
  r.o().controlword = cw::kDisableVoltage;
  r.step();
  EXPECT_EQ(r.sw(), 0x0250);  // 12
  // 13, 14, 15.
  r.o().controlword = cw::kShutdown;
  r.step();
  r.o().controlword = cw::kEnableOperation;
  r.step();
  r.drive.raise_fault(0x1234);
  r.step();
  EXPECT_EQ(r.sw(), 0x021F);  // 13 → fault reaction active
  EXPECT_EQ(r.o().error_code, 0x1234);
  r.step();
  EXPECT_EQ(r.sw(), 0x0218);  // 14 → fault (the axis stood still)
  EXPECT_EQ(r.drive.state(), State::fault);
  EXPECT_TRUE(r.last.brake_engaged);
  r.o().controlword = cw::kFaultReset;
  r.step();
  EXPECT_EQ(r.sw(), 0x0250);  // 15
  EXPECT_EQ(r.o().error_code, 0);
}

TEST(Cia402FsaDrive, QuickStopOption2DeceleratesOnTheQuickStopRampThenDisables) {
  Rig r;
  r.enable();
  r.set_mode(Mode::pv);
  r.o().target_velocity = 50000;
  r.o().profile_acceleration = 500000;
  r.o().quick_stop_deceleration = 250000;  // 0.2 s from 50000 counts/s
  ASSERT_TRUE(r.run_until([&] { return r.o().velocity_actual >= 49000; }, 1.0));
  r.o().controlword = cw::kQuickStop;
  r.step();
  EXPECT_EQ(r.drive.state(), State::quick_stop_active);
  r.run(0.1);  // halfway: still decelerating, still in QSA
  EXPECT_EQ(r.drive.state(), State::quick_stop_active);
  EXPECT_NEAR(r.o().velocity_actual, 25000, 2500);
  ASSERT_TRUE(r.run_until([&] { return r.drive.state() == State::switch_on_disabled; }, 0.3));
  EXPECT_NEAR(r.axis.velocity_rad_s(), 0, 0.05);
}

TEST(Cia402FsaDrive, QuickStopOption6DeceleratesThenHolds) {
  Rig r;
  r.o().quick_stop_option = 6;
  r.enable();
  r.set_mode(Mode::pv);
  r.o().target_velocity = 40000;
  r.o().profile_acceleration = 400000;
  r.o().quick_stop_deceleration = 400000;
  ASSERT_TRUE(r.run_until([&] { return r.o().velocity_actual >= 39000; }, 1.0));
  r.o().controlword = cw::kQuickStop;
  r.step();
  const double x0 = r.load_counts();
  r.run(0.5);
  EXPECT_EQ(r.drive.state(), State::quick_stop_active);
  EXPECT_NE(r.sw() & sw::target_reached, 0);
  // v²/2a = 2000 counts of braking distance, then standing under power.
  EXPECT_NEAR(r.load_counts() - x0, 2000, 150);
  const double held = r.load_counts();
  r.run(0.2);
  EXPECT_NEAR(r.load_counts(), held, 1.0);
  EXPECT_TRUE(r.last.power);
  EXPECT_NEAR(r.last.velocity_rad_s, 0, 1e-3);
}

TEST(Cia402FsaDrive, FaultReactionDeceleratesBeforeFault) {
  Rig r;
  r.enable();
  r.set_mode(Mode::pv);
  r.o().target_velocity = 40000;
  r.o().quick_stop_deceleration = 200000;
  ASSERT_TRUE(r.run_until([&] { return r.o().velocity_actual >= 39000; }, 1.0));
  r.drive.raise_fault();
  r.step();
  EXPECT_EQ(r.drive.state(), State::fault_reaction_active);
  r.run(0.1);
  EXPECT_EQ(r.drive.state(), State::fault_reaction_active);
  ASSERT_TRUE(r.run_until([&] { return r.drive.state() == State::fault; }, 0.3));
  EXPECT_EQ(r.o().error_code, kErrorExternal);
}

TEST(Cia402FsaDrive, FaultResetEdgeOnlyInFault) {
  Rig r;
  r.enable();
  r.o().fault_reaction_option = 0;
  r.o().controlword = cw::kEnableOperation | cw::fault_reset;  // bit 7 high while running
  r.step();
  EXPECT_EQ(r.drive.state(), State::operation_enabled);  // commands with bit 7 are ignored
  r.drive.raise_fault();
  r.step();
  EXPECT_EQ(r.drive.state(), State::fault);
  r.run(0.01);  // bit 7 is held: no edge
  EXPECT_EQ(r.drive.state(), State::fault);
  r.o().controlword = 0;
  r.step();
  r.o().controlword = cw::kFaultReset;
  r.step();
  EXPECT_EQ(r.drive.state(), State::switch_on_disabled);
}

}  // namespace
}  // namespace omnitwin::drive
