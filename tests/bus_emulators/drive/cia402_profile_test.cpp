// Tests the profile generators (cia402_profile): the online trapezoid (lands exactly on the
// target, respects velocity/acceleration/deceleration, overshoots and returns when a target
// is too close to brake for), the PV velocity ramp and the TQ torque slope; then, on a drive
// stepping the axis model, profile position mode with the set-point handshake (bit 4 → bit 12),
// absolute and relative targets, target reached (bit 10), change immediately (bit 5), the
// buffered single set-point, change on set-point (bit 9), halt; profile velocity reaching its
// speed (bits 10, 12) and profile torque reaching its torque along the slope.
#include "bus_emulators/drive/cia402_profile.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "drive_rig.hpp"

namespace omnitwin::drive {
namespace {

using testing::Rig;

TEST(Trapezoid, ReachesTargetExactlyWithinLimits) {
  Trapezoid tr;
  tr.reset(0);
  const double dt = 0.001;
  double vmax_seen = 0, prev_v = 0, max_acc = 0;
  int n = 0;
  while (!tr.step(10000, 20000, 100000, 50000, dt) && n < 10000) {
    vmax_seen = std::max(vmax_seen, tr.vel);
    max_acc = std::max(max_acc, std::fabs(tr.vel - prev_v) / dt);
    prev_v = tr.vel;
    ++n;
  }
  EXPECT_DOUBLE_EQ(tr.pos, 10000);
  EXPECT_EQ(tr.vel, 0);
  EXPECT_NEAR(vmax_seen, 20000, 1e-6);
  EXPECT_LE(max_acc, 100000 * 1.0001);
  // t = 0.2 (acc) + 0.4 (dec) + (10000 − 2000 − 4000)/20000 = 0.8 s.
  EXPECT_NEAR(n * dt, 0.8, 0.01);
}

TEST(Trapezoid, ShortMoveIsTriangular) {
  Trapezoid tr;
  tr.reset(0);
  double vpeak = 0;
  int n = 0;
  while (!tr.step(-100, 1e6, 10000, 10000, 0.001) && n < 10000) {
    vpeak = std::min(vpeak, tr.vel);
    ++n;
  }
  EXPECT_DOUBLE_EQ(tr.pos, -100);
  EXPECT_NEAR(vpeak, -1000, 20);  // sqrt(a·d) for a symmetric triangle
}

TEST(Trapezoid, TooCloseTargetIsOvershotAndApproachedBack) {
  Trapezoid tr;
  tr.reset(0, 10000);  // moving at 10000, braking distance 1000
  double max_pos = 0;
  int n = 0;
  while (!tr.step(100, 10000, 50000, 50000, 0.001) && n < 10000) {
    max_pos = std::max(max_pos, tr.pos);
    ++n;
  }
  EXPECT_GT(max_pos, 900);
  EXPECT_DOUBLE_EQ(tr.pos, 100);
}

TEST(Ramps, VelocityRampUsesAccelerationAndDeceleration) {
  EXPECT_DOUBLE_EQ(ramp_velocity(0, 1000, 10000, 20000, 0.01), 100);
  EXPECT_DOUBLE_EQ(ramp_velocity(1000, 0, 10000, 20000, 0.01), 800);
  EXPECT_DOUBLE_EQ(ramp_velocity(-100, 1000, 10000, 20000, 0.01), 0);  // through zero
  EXPECT_DOUBLE_EQ(ramp_velocity(990, 1000, 10000, 20000, 0.01), 1000);
  EXPECT_DOUBLE_EQ(ramp_torque(0, 500, 1000, 0.1), 100);
  EXPECT_DOUBLE_EQ(ramp_torque(0, 500, 0, 0.1), 500);
  EXPECT_DOUBLE_EQ(ramp_torque(450, 400, 1000, 0.1), 400);
}

// ---- Profile position on the drive.

struct PpRig : Rig {
  PpRig() {
    enable();
    set_mode(Mode::pp);
    o().profile_velocity = 50000;
    o().profile_acceleration = 500000;
    o().profile_deceleration = 500000;
  }
  // Writes the target and raises bit 4 with the extra bits; returns after the acknowledge
  // and the master's clearing of bit 4.
  void go(std::int32_t target, std::uint16_t bits = 0) {
    o().target_position = target;
    o().controlword = cw::kEnableOperation | bits | cw::new_set_point;
    step();
    acked = (sw() & sw::set_point_ack) != 0;
    o().controlword = cw::kEnableOperation | bits;
    step();
  }
  bool acked = false;
};

TEST(ProfilePosition, AbsoluteMoveWithHandshakeAndTargetReached) {
  PpRig r;
  EXPECT_NE(r.sw() & sw::target_reached, 0);  // standing at enable
  r.o().target_position = 20000;
  r.o().controlword = cw::kEnableOperation | cw::new_set_point;
  r.step();
  EXPECT_NE(r.sw() & sw::set_point_ack, 0);
  EXPECT_EQ(r.sw() & sw::target_reached, 0);
  r.step();
  EXPECT_NE(r.sw() & sw::set_point_ack, 0);  // stays while bit 4 is high
  r.o().controlword = cw::kEnableOperation;
  r.step();
  EXPECT_EQ(r.sw() & sw::set_point_ack, 0);  // cleared after bit 4 falls
  ASSERT_TRUE(r.run_until([&] { return (r.sw() & sw::target_reached) != 0; }, 2.0));
  EXPECT_NEAR(r.o().position_actual, 20000, 10);
  EXPECT_EQ(r.o().position_demand, 20000);
  r.run(0.1);
  EXPECT_NEAR(r.o().position_actual, 20000, 1);
  EXPECT_NEAR(r.load_counts(), 20000, 1);
  // The move took about 0.4 + 0.1 s (cruise at 50000 counts/s with 0.1 s ramps).
}

TEST(ProfilePosition, RelativeMoveAddsToTheLastTarget) {
  PpRig r;
  r.go(10000);
  ASSERT_TRUE(r.acked);
  ASSERT_TRUE(r.run_until([&] { return (r.sw() & sw::target_reached) != 0; }, 2.0));
  r.go(-3000, cw::relative);
  ASSERT_TRUE(r.acked);
  ASSERT_TRUE(r.run_until([&] { return (r.sw() & sw::target_reached) != 0; }, 2.0));
  r.run(0.05);
  EXPECT_NEAR(r.o().position_actual, 7000, 1);
}

TEST(ProfilePosition, ChangeImmediatelyReplacesTheTargetMidMove) {
  PpRig r;
  r.go(40000);
  r.run(0.2);
  ASSERT_GT(r.o().position_actual, 3000);
  ASSERT_LT(r.o().position_actual, 20000);
  r.go(5000, cw::change_immediately);
  EXPECT_TRUE(r.acked);
  double max_pos = 0;
  ASSERT_TRUE(r.run_until(
      [&] {
        max_pos = std::max<double>(max_pos, r.o().position_actual);
        return (r.sw() & sw::target_reached) != 0;
      },
      3.0));
  r.run(0.05);
  EXPECT_NEAR(r.o().position_actual, 5000, 1);
  EXPECT_LT(max_pos, 40000 - 5000);  // never went to the first target
}

TEST(ProfilePosition, SingleSetPointIsBufferedUntilTheFirstTargetIsReached) {
  PpRig r;
  r.go(20000);
  r.run(0.05);
  // A second set-point while moving: taken into the buffer; acknowledge stays while full.
  r.go(-10000);
  EXPECT_TRUE(r.acked);
  EXPECT_NE(r.sw() & sw::set_point_ack, 0);
  double max_pos = 0;
  ASSERT_TRUE(r.run_until(
      [&] {
        max_pos = std::max<double>(max_pos, r.o().position_actual);
        return (r.sw() & sw::target_reached) != 0;
      },
      5.0));
  EXPECT_GT(max_pos, 19990);  // first target reached first
  r.run(0.05);
  EXPECT_NEAR(r.o().position_actual, -10000, 1);
  EXPECT_EQ(r.sw() & sw::set_point_ack, 0);
}

TEST(ProfilePosition, ChangeOnSetPointPassesTheFirstTargetWithoutStopping) {
  PpRig r;
  r.go(10000, cw::change_on_set_point);
  r.go(30000, cw::change_on_set_point);
  double min_speed_near_first = 1e9;
  ASSERT_TRUE(r.run_until(
      [&] {
        if (std::abs(r.o().position_actual - 10000) < 2000)
          min_speed_near_first = std::min<double>(min_speed_near_first, r.o().velocity_actual);
        return (r.sw() & sw::target_reached) != 0;
      },
      3.0));
  EXPECT_GT(min_speed_near_first, 40000);  // cruised through 10000
  r.run(0.05);
  EXPECT_NEAR(r.o().position_actual, 30000, 1);
}

TEST(ProfilePosition, HaltStopsAndResumes) {
  PpRig r;
  r.go(50000);
  r.run(0.3);
  r.o().controlword = cw::kEnableOperation | cw::halt;
  ASSERT_TRUE(r.run_until([&] { return (r.sw() & sw::target_reached) != 0; }, 1.0));
  r.run(0.05);
  const auto stopped = r.o().position_actual;
  EXPECT_LT(stopped, 40000);
  r.run(0.1);
  EXPECT_NEAR(r.o().position_actual, stopped, 2);
  EXPECT_EQ(r.drive.state(), State::operation_enabled);
  r.o().controlword = cw::kEnableOperation;
  ASSERT_TRUE(r.run_until([&] { return (r.sw() & sw::target_reached) != 0; }, 2.0));
  r.run(0.05);
  EXPECT_NEAR(r.o().position_actual, 50000, 1);
}

// ---- Profile velocity and torque on the drive.

TEST(ProfileVelocity, ReachesSpeedAlongTheRampAndReportsZeroSpeed) {
  Rig r;
  r.enable();
  r.set_mode(Mode::pv);
  EXPECT_NE(r.sw() & sw::speed_zero, 0);
  r.o().profile_acceleration = 100000;
  r.o().profile_deceleration = 200000;
  r.o().target_velocity = 30000;
  r.run(0.1);
  EXPECT_NEAR(r.o().velocity_demand, 10000, 200);  // 0.1 s at 100000 counts/s²
  EXPECT_EQ(r.sw() & sw::target_reached, 0);
  EXPECT_EQ(r.sw() & sw::speed_zero, 0);
  ASSERT_TRUE(r.run_until([&] { return (r.sw() & sw::target_reached) != 0; }, 0.5));
  EXPECT_NEAR(r.o().velocity_actual, 30000, 100);
  EXPECT_NEAR(r.last.velocity_rad_s, 30000 / r.drive.counts_per_load_rad(), 1e-6);
  r.o().target_velocity = 0;
  r.run(0.1);
  EXPECT_NEAR(r.o().velocity_demand, 10000, 200);  // decelerates at 200000
  ASSERT_TRUE(r.run_until([&] { return (r.sw() & sw::speed_zero) != 0; }, 0.5));
}

TEST(ProfileTorque, ReachesTorqueAlongTheSlope) {
  Rig r;
  r.enable();
  r.set_mode(Mode::tq);
  r.o().torque_slope = 2000;  // 200 %/s
  r.o().target_torque = 500;  // 50 % → 0.25 s
  r.run(0.1);
  EXPECT_TRUE(r.last.torque_mode);
  EXPECT_NEAR(r.o().torque_demand, 200, 3);
  EXPECT_NEAR(r.last.torque_nm, 0.2, 0.003);
  EXPECT_EQ(r.sw() & sw::target_reached, 0);
  ASSERT_TRUE(r.run_until([&] { return (r.sw() & sw::target_reached) != 0; }, 0.3));
  EXPECT_EQ(r.o().torque_demand, 500);
  r.step();  // the feedback lags one period
  EXPECT_NEAR(r.o().torque_actual, 500, 1);  // the axis model applied it
  EXPECT_GT(r.axis.velocity_rad_s(), 0);
  // max torque limits
  r.o().max_torque = 300;
  r.step();
  EXPECT_NEAR(r.last.torque_nm, 0.3, 1e-9);
}

}  // namespace
}  // namespace omnitwin::drive
