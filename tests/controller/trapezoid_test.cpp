// Tests controller/trapezoid: seed 002's trapezoidal profile (eq. 4-9 … 4-13) — Ta, Vmax,
// Amax, the positions at Ta, T/2, T − Ta and T for the thesis move (2 m in 20 s), the D/T
// average speed, negative and zero distances, clamping outside [0, T].
#include "controller/trapezoid.hpp"

#include <gtest/gtest.h>

#include <stdexcept>

namespace omnitwin::controller {
namespace {

TEST(Trapezoid, ThesisMoveEquationValues) {
  const Trapezoid p(2.0, 20.0);
  EXPECT_DOUBLE_EQ(p.accel_time(), 20.0 / 3.0);
  EXPECT_DOUBLE_EQ(p.vmax(), 0.15);                  // 2/(20 − 20/3)
  EXPECT_DOUBLE_EQ(p.amax(), 0.15 / (20.0 / 3.0));   // 0.0225
  EXPECT_NEAR(p.position(20.0 / 3.0), 0.5, 1e-12);   // ½·Vmax·Ta
  EXPECT_NEAR(p.position(10.0), 1.0, 1e-12);         // half way at T/2
  EXPECT_NEAR(p.position(40.0 / 3.0), 1.5, 1e-12);   // D − ½·Vmax·Ta
  EXPECT_EQ(p.position(20.0), 2.0);                  // exactly D
  EXPECT_DOUBLE_EQ(p.velocity(10.0), 0.15);
  EXPECT_NEAR(p.velocity(20.0 / 6.0), 0.075, 1e-12);  // half way up the ramp
  EXPECT_DOUBLE_EQ(p.acceleration(1.0), p.amax());
  EXPECT_DOUBLE_EQ(p.acceleration(19.0), -p.amax());
}

TEST(Trapezoid, AverageSpeedIsDistanceOverDuration) {
  // Integrate the velocity numerically: the area is D, the mean D/T.
  const Trapezoid p(-0.7, 3.3);
  const int n = 33000;
  double area = 0.0;
  for (int k = 0; k < n; ++k) area += p.velocity((k + 0.5) * 3.3 / n) * (3.3 / n);
  EXPECT_NEAR(area, -0.7, 1e-6);
  EXPECT_NEAR(area / 3.3, -0.7 / 3.3, 1e-7);
}

TEST(Trapezoid, PositionIsContinuousAndVelocityIsItsDerivative) {
  const Trapezoid p(1.3, 4.0);
  const double h = 1e-6;
  for (double t = 0.01; t < 4.0; t += 0.0173) {
    const double dp = (p.position(t + h) - p.position(t - h)) / (2 * h);
    EXPECT_NEAR(dp, p.velocity(t), 1e-6) << t;
  }
  for (double t : {4.0 / 3.0, 8.0 / 3.0})  // the phase joins
    EXPECT_NEAR(p.position(t + 1e-12), p.position(t - 1e-12), 1e-9);
}

TEST(Trapezoid, NegativeAndZeroDistances) {
  const Trapezoid n(-2.0, 20.0);
  EXPECT_DOUBLE_EQ(n.vmax(), -0.15);
  EXPECT_EQ(n.position(20.0), -2.0);
  EXPECT_NEAR(n.position(10.0), -1.0, 1e-12);
  const Trapezoid z(0.0, 5.0);
  for (double t = -1.0; t < 7.0; t += 0.5) {
    EXPECT_EQ(z.position(t), 0.0);
    EXPECT_EQ(z.velocity(t), 0.0);
  }
}

TEST(Trapezoid, TimeIsClampedToTheMove) {
  const Trapezoid p(2.0, 20.0);
  EXPECT_EQ(p.position(-3.0), 0.0);
  EXPECT_EQ(p.velocity(-3.0), 0.0);
  EXPECT_EQ(p.position(25.0), 2.0);
  EXPECT_EQ(p.velocity(25.0), 0.0);
  EXPECT_EQ(p.velocity(0.0), 0.0);
  EXPECT_EQ(p.velocity(20.0), 0.0);
}

TEST(Trapezoid, RejectsNonPositiveDuration) {
  EXPECT_THROW(Trapezoid(1.0, 0.0), std::invalid_argument);
  EXPECT_THROW(Trapezoid(1.0, -1.0), std::invalid_argument);
}

}  // namespace
}  // namespace omnitwin::controller
