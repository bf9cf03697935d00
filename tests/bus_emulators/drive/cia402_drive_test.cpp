// Tests the CiA 402 axis (cia402_drive) on the axis model: units (counts from counts_per_rev
// and gear_ratio), mode switching 0x6060 → 0x6061 only for modes advertised in 0x6502, CSP
// and CSV tracking a ramp, CST with torque offset, the following-error fault (0x6065 window
// for 0x6066 ms → fault, error code 0x8611, statusword bit 13), software position limits
// 0x607D (target clipped, stop at the limit, bit 11), polarity 0x607E, max motor speed 0x6080,
// digital inputs 0x60FD from modelled switches and scenario bits, digital outputs 0x60FE with
// mask driving the brake, the brake engaged unless the power stage is on, power cycle.
#include "bus_emulators/drive/cia402_drive.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "drive_rig.hpp"

namespace omnitwin::drive {
namespace {

using testing::Rig;
constexpr double kPi = 3.141592653589793;

TEST(Cia402Drive, PositionUnitsFollowCountsPerRevAndGearRatio) {
  DriveConfig c;
  c.counts_per_rev = 4096;
  c.gear_ratio = 10;
  Cia402Drive d(c);
  d.step(1'000'000, Feedback{0.5 * kPi, 2 * kPi, 0});  // quarter load turn, 1 load rev/s
  EXPECT_EQ(d.objects().position_actual, 10240);     // 2.5 motor revs
  EXPECT_EQ(d.objects().velocity_actual, 40960);
  EXPECT_EQ(d.objects().max_motor_speed, static_cast<std::uint32_t>(100 * 4096 / (2 * kPi)));
  EXPECT_EQ(d.objects().supported_modes, kAllModes);
  EXPECT_EQ(d.objects().supported_modes, 0x3ADu);
}

TEST(Cia402Drive, UnsupportedModeIsNotDisplayed) {
  DriveConfig c;
  c.supported_modes = mode_bit(Mode::csv) | mode_bit(Mode::pv);
  Rig r(c);
  r.enable();
  r.set_mode(Mode::csv);
  EXPECT_EQ(r.o().mode_display, 9);
  EXPECT_EQ(r.drive.mode(), Mode::csv);
  r.set_mode(Mode::csp);  // not advertised
  EXPECT_EQ(r.o().mode_display, 9);
  EXPECT_EQ(r.drive.mode(), Mode::csv);
  r.o().mode = 5;  // not a CiA 402 mode of this drive at all
  r.step();
  EXPECT_EQ(r.o().mode_display, 9);
  r.set_mode(Mode::pv);
  EXPECT_EQ(r.o().mode_display, 3);
}

TEST(Cia402Drive, CspTracksARampOnTheAxisModel) {
  Rig r;
  r.enable();
  r.set_mode(Mode::csp);
  double worst = 0;
  for (int k = 1; k <= 1000; ++k) {
    r.o().target_position = static_cast<std::int32_t>(20.0 * k);  // 20000 counts/s
    r.step();
    if (k > 100) worst = std::max(worst, std::fabs(r.o().target_position - r.load_counts()));
  }
  EXPECT_LT(worst, 60);  // lag of about one to two periods of feed-forward + servo
  EXPECT_NE(r.sw() & sw::set_point_ack, 0);  // CSP bit 12: follows the command value
  EXPECT_EQ(r.sw() & sw::following_error, 0);
  r.run(0.2);
  EXPECT_NEAR(r.o().position_actual, 20000, 1);
  EXPECT_EQ(r.o().position_demand, 20000);
}

// Set-points once per bus cycle of five drive periods: the drive interpolates between them,
// so its velocity command stays near the set-points' slope instead of jumping five-fold on
// the period a set-point arrives and resting on the other four.
TEST(Cia402Drive, CspInterpolatesSetPointsThatComeLessOftenThanItsPeriod) {
  Rig r;
  r.enable();
  r.set_mode(Mode::csp);
  const double slope = 20000.0;  // counts/s
  double worst_ff = 0;
  for (int k = 1; k <= 1000; ++k) {
    if (k % 5 == 0) r.o().target_position = static_cast<std::int32_t>(slope * k * 1e-3);
    r.step();
    if (k > 100) worst_ff = std::max(worst_ff, std::fabs(r.last.velocity_rad_s * r.drive.counts_per_load_rad() - slope));
  }
  EXPECT_LT(worst_ff, 0.5 * slope);  // without interpolation: 4 × slope on one period in five
  r.run(0.2);
  EXPECT_NEAR(r.o().position_actual, slope, 1);
}

TEST(Cia402Drive, CsvTracksAVelocityRampWithOffset) {
  Rig r;
  r.enable();
  r.set_mode(Mode::csv);
  r.o().velocity_offset = 1000;
  double worst = 0;
  for (int k = 1; k <= 500; ++k) {
    r.o().target_velocity = 100 * k;  // ramp to 50000 counts/s in 0.5 s
    r.step();
    if (k > 50) worst = std::max(worst, std::fabs(r.o().target_velocity + 1000.0 - r.o().velocity_actual));
  }
  EXPECT_LT(worst, 500);
  EXPECT_NEAR(r.last.velocity_rad_s * r.drive.counts_per_load_rad(), 51000, 1e-6);
  EXPECT_FALSE(r.last.torque_mode);
  EXPECT_EQ(r.o().velocity_demand, 51000);
}

TEST(Cia402Drive, CstAppliesTargetPlusOffsetAsTorque) {
  DriveConfig c;
  c.rated_torque_nm = 2;
  c.gear_ratio = 3;
  Rig r(c);
  r.enable();
  r.set_mode(Mode::cst);
  r.o().target_torque = 100;  // 10 %
  r.o().torque_offset = 50;
  r.step();
  EXPECT_TRUE(r.last.torque_mode);
  EXPECT_NEAR(r.last.torque_nm, 0.15 * 2 * 3, 1e-12);  // on the load shaft
  EXPECT_EQ(r.o().torque_demand, 150);
}

TEST(Cia402Drive, FollowingErrorFaultsAfterTheTimeout) {
  AxisModelConfig a;
  a.torque_limit_nm = 0.05;  // too weak to follow
  Rig r({}, a);
  r.enable();
  r.set_mode(Mode::csp);
  r.o().following_error_window = 1000;
  r.o().following_error_timeout = 20;
  r.o().target_position = 5000;  // a step the axis cannot follow
  r.step();
  EXPECT_EQ(r.drive.state(), State::operation_enabled);
  EXPECT_NE(r.sw() & sw::warning, 0);  // outside the window, timer running
  r.run(0.015);
  EXPECT_EQ(r.drive.state(), State::operation_enabled);
  ASSERT_TRUE(r.run_until([&] { return r.drive.state() != State::operation_enabled; }, 0.02));
  EXPECT_EQ(r.o().error_code, kErrorFollowing);
  EXPECT_EQ(r.o().error_code, 0x8611);
  ASSERT_TRUE(r.run_until([&] { return r.drive.state() == State::fault; }, 1.0));
  EXPECT_NE(r.sw() & sw::fault, 0);
  // Reset: back to switch on disabled and a fresh enable works.
  r.o().target_position = 0;
  r.o().controlword = cw::kFaultReset;
  r.step();
  EXPECT_EQ(r.drive.state(), State::switch_on_disabled);
}

TEST(Cia402Drive, FollowingErrorBit13InPpBeforeTheFault) {
  AxisModelConfig a;
  a.torque_limit_nm = 0.05;
  Rig r({}, a);
  r.enable();
  r.set_mode(Mode::pp);
  r.o().following_error_window = 200;
  r.o().following_error_timeout = 5;
  r.o().fault_reaction_option = 0;
  r.o().profile_velocity = 200000;
  r.o().profile_acceleration = 10000000;
  r.o().target_position = 100000;
  r.o().controlword = cw::kEnableOperation | cw::new_set_point;
  ASSERT_TRUE(r.run_until([&] { return r.drive.state() == State::fault; }, 1.0));
  EXPECT_EQ(r.o().error_code, 0x8611);
}

TEST(Cia402Drive, SoftwareLimitsClipPpTargetAndSetInternalLimit) {
  Rig r;
  r.enable();
  r.set_mode(Mode::pp);
  r.o().sw_limit_min = -5000;
  r.o().sw_limit_max = 8000;
  ASSERT_TRUE(r.pp_move(20000));
  r.run(0.05);
  EXPECT_NEAR(r.o().position_actual, 8000, 1);
  EXPECT_NE(r.sw() & sw::internal_limit, 0);
  // A target inside: bit 11 clears.
  ASSERT_TRUE(r.pp_move(0));
  EXPECT_EQ(r.sw() & sw::internal_limit, 0);
}

// 0x607D written with min above max (found by fuzzing: the CSP clamp was undefined then): the
// drive takes the range between the two, in PP and CSP alike, as it does for its physical limits.
TEST(Cia402Drive, SoftwareLimitsWrittenTheWrongWayRoundAreTheRangeBetweenThem) {
  Rig r;
  r.enable();
  r.set_mode(Mode::pp);
  r.o().sw_limit_min = 8000;
  r.o().sw_limit_max = -5000;
  ASSERT_TRUE(r.pp_move(20000));
  r.run(0.05);
  EXPECT_NEAR(r.o().position_actual, 8000, 1);
  EXPECT_NE(r.sw() & sw::internal_limit, 0);
  // CSP: a set-point inside the range is followed as it is; a ramp out past the range stops
  // at its edge. (The clamp taken as given answered the max, -5000, whatever the set-point.)
  Rig c;
  c.enable();
  c.o().sw_limit_min = 8000;
  c.o().sw_limit_max = -5000;
  c.set_mode(Mode::csp);
  for (int k = 1; k <= 100; ++k) {
    c.o().target_position = static_cast<std::int32_t>(20.0 * k);  // to 2000 at 20000 counts/s
    c.step();
  }
  c.run(0.2);
  EXPECT_NEAR(c.o().position_actual, 2000, 1);
  EXPECT_EQ(c.sw() & sw::internal_limit, 0);
  for (int k = 101; k <= 1000; ++k) {
    c.o().target_position = static_cast<std::int32_t>(20.0 * k);  // on to 20000
    c.step();
  }
  c.run(0.2);
  EXPECT_NEAR(c.o().position_actual, 8000, 1);
  EXPECT_NE(c.sw() & sw::internal_limit, 0);
}

TEST(Cia402Drive, SoftwareLimitsStopCsvAtTheLimit) {
  Rig r;
  r.enable();
  r.set_mode(Mode::csv);
  r.o().sw_limit_min = -10000;
  r.o().sw_limit_max = 10000;
  r.o().target_velocity = 50000;
  double peak = 0;
  for (int i = 0; i < 1000; ++i) {
    r.step();
    peak = std::max<double>(peak, r.o().position_actual);
  }
  EXPECT_LT(peak, 10000 + 400);  // servo lag at the quick stop deceleration
  EXPECT_NEAR(r.o().position_actual, 10000, 2);
  EXPECT_NEAR(r.o().velocity_actual, 0, 50);
  EXPECT_NE(r.sw() & sw::internal_limit, 0);
  r.o().target_velocity = -50000;  // away from the limit is allowed
  r.run(0.1);
  EXPECT_LT(r.o().position_actual, 8000);
}

TEST(Cia402Drive, PolarityInvertsPositionAndVelocity) {
  Rig r;
  r.o().polarity = 0xC0;
  r.enable();
  r.set_mode(Mode::pp);
  ASSERT_TRUE(r.pp_move(10000));
  r.run(0.05);
  EXPECT_NEAR(r.o().position_actual, 10000, 1);
  EXPECT_NEAR(r.load_counts(), -10000, 1);  // the physical axis turned the other way
  r.set_mode(Mode::csv);
  r.o().target_velocity = 20000;
  r.run(0.3);
  EXPECT_NEAR(r.o().velocity_actual, 20000, 100);
  EXPECT_LT(r.axis.velocity_rad_s(), 0);
  // Only bit 6: position counts up while the velocity reads negative.
  r.o().polarity = 0x40;
  r.step();
  EXPECT_NEAR(r.o().velocity_actual, 20000, 200);
  EXPECT_LT(r.o().position_actual, -10000);
}

TEST(Cia402Drive, MaxMotorSpeedClampsTheVelocitySetPoint) {
  Rig r;
  r.enable();
  r.set_mode(Mode::csv);
  r.o().max_motor_speed = 30000;
  r.o().target_velocity = 80000;
  r.run(0.2);
  EXPECT_EQ(r.o().velocity_demand, 30000);
  EXPECT_NEAR(r.o().velocity_actual, 30000, 100);
}

TEST(Cia402Drive, DigitalInputsFromSwitchesAndScenario) {
  DriveConfig c;
  c.switches.negative_limit = -1.0;
  c.switches.positive_limit = 1.0;
  c.switches.home = 0.5;
  Cia402Drive d(c);
  d.step(1'000'000, Feedback{0.0, 0, 0});
  EXPECT_EQ(d.objects().digital_inputs, 0u);
  d.step(2'000'000, Feedback{0.7, 0, 0});
  EXPECT_EQ(d.objects().digital_inputs, 4u);
  d.step(3'000'000, Feedback{1.2, 0, 0});
  EXPECT_EQ(d.objects().digital_inputs, 6u);
  d.step(4'000'000, Feedback{-1.2, 0, 0});
  EXPECT_EQ(d.objects().digital_inputs, 1u);
  d.set_external_inputs(0x2u | 0x100u);
  d.step(5'000'000, Feedback{-1.2, 0, 0});
  EXPECT_EQ(d.objects().digital_inputs, 0x103u);
}

TEST(Cia402Drive, BrakeEngagedUnlessPowerStageOnAndOutputMask) {
  Rig r;
  r.step();
  EXPECT_TRUE(r.last.brake_engaged);
  EXPECT_FALSE(r.last.power);
  EXPECT_EQ(r.drive.physical_outputs() & 1u, 1u);
  r.enable();
  EXPECT_FALSE(r.last.brake_engaged);
  // The host takes the brake output over through the mask.
  r.o().digital_outputs_mask = 1;
  r.o().digital_outputs = 1;
  r.step();
  EXPECT_TRUE(r.last.brake_engaged);
  r.o().digital_outputs = 0;
  r.step();
  EXPECT_FALSE(r.last.brake_engaged);
  // A disabled drive with the brake: the axis model holds it.
  r.o().digital_outputs_mask = 0;
  r.o().controlword = cw::kDisableVoltage;
  r.step();
  EXPECT_TRUE(r.last.brake_engaged);
  EXPECT_DOUBLE_EQ(r.last.velocity_rad_s, 0);
  // No brake fitted: never engaged.
  DriveConfig c;
  c.brake = false;
  Cia402Drive d(c);
  EXPECT_FALSE(d.step(1'000'000, {}).brake_engaged);
}

TEST(Cia402Drive, VelocityLoopTorqueDemandIsLimitedByMaxTorque) {
  Rig r;
  r.enable();
  r.set_mode(Mode::csv);
  r.o().max_torque = 100;  // 10 % of 1 Nm
  r.o().target_velocity = 100000;
  r.step();
  EXPECT_EQ(r.o().torque_demand, 100);
  EXPECT_NEAR(r.last.torque_limit_nm, 0.1, 1e-12);
  EXPECT_NE(r.sw() & sw::warning, 0);  // saturated
}

TEST(Cia402Drive, PowerCycleRestoresDefaultsAndUnhomes) {
  Rig r;
  r.enable();
  r.set_mode(Mode::hm);
  r.o().homing_method = 37;
  r.o().home_offset = 123;
  r.o().controlword = cw::kEnableOperation | cw::start_homing;
  r.step();
  EXPECT_TRUE(r.drive.homed());
  EXPECT_EQ(r.o().position_actual, 123);
  r.drive.power_cycle();
  EXPECT_FALSE(r.drive.homed());
  EXPECT_EQ(r.drive.state(), State::not_ready_to_switch_on);
  EXPECT_EQ(r.o().home_offset, 0);
  r.step();
  EXPECT_EQ(r.drive.state(), State::switch_on_disabled);
  EXPECT_EQ(r.o().position_actual, 0);
}

}  // namespace
}  // namespace omnitwin::drive
