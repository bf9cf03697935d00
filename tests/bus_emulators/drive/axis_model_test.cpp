// Tests the 1-DOF motor + load model (axis_model): the velocity servo settles on its set-point
// with the configured first-order time constant, torque mode accelerates the inertia by
// (torque − friction)/J, static friction holds an axis against a smaller torque, the torque
// limit (own and the Command's) caps the servo, the brake holds, and an unpowered axis coasts
// down under friction only.
#include "bus_emulators/drive/axis_model.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace omnitwin::drive {
namespace {

Command velocity(double v) {
  Command c;
  c.power = true;
  c.brake_engaged = false;
  c.velocity_rad_s = v;
  return c;
}
Command torque(double t) {
  Command c;
  c.power = true;
  c.brake_engaged = false;
  c.torque_mode = true;
  c.torque_nm = t;
  return c;
}

TEST(AxisModel, VelocityServoIsFirstOrder) {
  AxisModelConfig cfg;
  cfg.servo_time_constant_s = 0.01;
  AxisModel a(cfg);
  for (int i = 0; i < 10; ++i) a.step(velocity(10), 0.001);  // one time constant
  EXPECT_NEAR(a.velocity_rad_s(), 10 * (1 - std::exp(-1.0)), 0.3);
  for (int i = 0; i < 100; ++i) a.step(velocity(10), 0.001);
  EXPECT_NEAR(a.velocity_rad_s(), 10, 1e-3);
  EXPECT_GT(a.position_rad(), 0.5);
  // Holding the set-point needs the friction torque: viscous·v + Coulomb.
  EXPECT_NEAR(a.applied_torque_nm(), cfg.viscous_nm_s * 10 + cfg.coulomb_nm, 1e-3);
}

TEST(AxisModel, TorqueModeAcceleratesTheInertia) {
  AxisModelConfig cfg;
  cfg.inertia_kg_m2 = 0.01;
  cfg.viscous_nm_s = 0;
  cfg.coulomb_nm = 0.1;
  AxisModel a(cfg);
  for (int i = 0; i < 100; ++i) a.step(torque(0.6), 0.001);
  EXPECT_NEAR(a.velocity_rad_s(), (0.6 - 0.1) / 0.01 * 0.1, 1e-6);   // 5 rad/s
  EXPECT_NEAR(a.position_rad(), 0.5 * 50 * 0.1 * 0.1, 1e-3);        // ½·a·t²
  EXPECT_NEAR(a.feedback().torque_nm, 0.6, 1e-12);
}

TEST(AxisModel, StaticFrictionHoldsAgainstASmallTorque) {
  AxisModelConfig cfg;
  cfg.coulomb_nm = 0.1;
  AxisModel a(cfg, 1.0);
  for (int i = 0; i < 100; ++i) a.step(torque(0.09), 0.001);
  EXPECT_DOUBLE_EQ(a.position_rad(), 1.0);
  EXPECT_DOUBLE_EQ(a.velocity_rad_s(), 0);
}

TEST(AxisModel, TorqueLimitCapsTheServo) {
  AxisModelConfig cfg;
  cfg.inertia_kg_m2 = 0.01;
  cfg.viscous_nm_s = 0;
  cfg.coulomb_nm = 0;
  cfg.torque_limit_nm = 1.0;
  AxisModel a(cfg);
  Command c = velocity(100);
  c.torque_limit_nm = 0.5;  // the drive's 0x6072
  for (int i = 0; i < 100; ++i) a.step(c, 0.001);
  EXPECT_NEAR(a.velocity_rad_s(), 0.5 / 0.01 * 0.1, 1e-6);
  EXPECT_NEAR(a.applied_torque_nm(), 0.5, 1e-12);
}

TEST(AxisModel, BrakeHoldsAndUnpoweredAxisCoasts) {
  AxisModelConfig cfg;
  cfg.inertia_kg_m2 = 0.01;
  cfg.viscous_nm_s = 0;
  cfg.coulomb_nm = 0.05;
  AxisModel a(cfg);
  for (int i = 0; i < 200; ++i) a.step(velocity(5), 0.001);
  ASSERT_NEAR(a.velocity_rad_s(), 5, 1e-3);
  Command off;  // no power, brake released
  off.brake_engaged = false;
  for (int i = 0; i < 100; ++i) a.step(off, 0.001);
  EXPECT_NEAR(a.velocity_rad_s(), 5 - 0.05 / 0.01 * 0.1, 1e-3);  // friction only
  for (int i = 0; i < 2000; ++i) a.step(off, 0.001);
  EXPECT_DOUBLE_EQ(a.velocity_rad_s(), 0);  // stops, does not reverse
  Command braked = velocity(5);
  braked.brake_engaged = true;
  const double x = a.position_rad();
  for (int i = 0; i < 100; ++i) a.step(braked, 0.001);
  EXPECT_DOUBLE_EQ(a.position_rad(), x);
}

}  // namespace
}  // namespace omnitwin::drive
