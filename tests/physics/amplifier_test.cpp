// Tests physics/amplifier: the analog velocity amplifier's input stage — the speed setpoint
// is gain × (volts − zero volts), clamped to the motor's speed limit, with the input dead band
// taken out (zero inside, the band subtracted outside, odd about the zero voltage).
#include "physics/amplifier.hpp"

#include <gtest/gtest.h>

namespace omnitwin::physics {
namespace {

TEST(Driver, SetpointIsGainTimesOffsetVoltsAndClamped) {
  const DriverParams drv;  // 2.5 V zero, 8 rad/s/V
  MotorParams motor;
  motor.speed_limit = 10.0;
  EXPECT_DOUBLE_EQ(driver_setpoint(drv, motor, 2.5), 0.0);
  EXPECT_DOUBLE_EQ(driver_setpoint(drv, motor, 3.0), 4.0);
  EXPECT_DOUBLE_EQ(driver_setpoint(drv, motor, 2.0), -4.0);
  EXPECT_DOUBLE_EQ(driver_setpoint(drv, motor, 5.0), 10.0);   // 20 rad/s asked, 10 allowed
  EXPECT_DOUBLE_EQ(driver_setpoint(drv, motor, 0.0), -10.0);
}

TEST(Driver, DeadBandGivesZeroInsideAndSubtractsTheBandOutside) {
  // ±0.05 V around 2.5 V is standstill; beyond it the band is taken off, so the curve is
  // continuous (3.0 V: 0.45 V effective → 3.6 rad/s) and odd about the zero voltage.
  DriverParams drv;
  drv.dead_band = 0.05;
  const MotorParams motor;
  EXPECT_EQ(driver_setpoint(drv, motor, 2.5), 0.0);
  EXPECT_EQ(driver_setpoint(drv, motor, 2.54), 0.0);
  EXPECT_EQ(driver_setpoint(drv, motor, 2.46), 0.0);
  EXPECT_NEAR(driver_setpoint(drv, motor, 2.55), 0.0, 1e-12);
  EXPECT_NEAR(driver_setpoint(drv, motor, 3.0), 3.6, 1e-12);
  EXPECT_NEAR(driver_setpoint(drv, motor, 2.0), -3.6, 1e-12);
  // A dead band wider than the whole input range leaves the motor still.
  drv.dead_band = 3.0;
  EXPECT_EQ(driver_setpoint(drv, motor, 5.0), 0.0);
}

}  // namespace
}  // namespace omnitwin::physics
