// Tests physics/kinematics: D_e and D_i of seed 002 (eq. 4-5, 4-7) against each other, the
// thesis's sign check along +X, and eq. 4-1 wheel by wheel.
#include "physics/kinematics.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "physics/platform_params.hpp"

namespace omnitwin::physics {
namespace {

constexpr double kL = 0.25, kR = 0.05;

TEST(Kinematics, InverseTimesDecouplingIsIdentityForAnyHeading) {
  for (double phi = -7.0; phi <= 7.0; phi += 0.37) {
    const Eigen::Matrix3d p = inverse_matrix(phi, kL) * decoupling_matrix(phi, kL);
    EXPECT_TRUE(p.isApprox(Eigen::Matrix3d::Identity(), 1e-12)) << "phi=" << phi << "\n" << p;
  }
}

TEST(Kinematics, ThesisSignCheckAlongWorldX) {
  // 4-4-2: along world +X axes 1 and 2 turn positive, axes 3 and 4 negative.
  const WheelVector w = wheel_speeds(Twist(0.1, 0, 0), 0.0, kL, kR);
  EXPECT_GT(w(0), 0);
  EXPECT_GT(w(1), 0);
  EXPECT_LT(w(2), 0);
  EXPECT_LT(w(3), 0);
  EXPECT_NEAR(std::abs(w(0)), 0.1 / std::sqrt(2.0) / kR, 1e-12);
}

TEST(Kinematics, CcwTurnMakesEveryRimSpeedMinusLPhidot) {
  const WheelVector v = decoupling_matrix(0.3, kL) * Twist(0, 0, 0.5);
  for (int i = 0; i < 4; ++i) EXPECT_DOUBLE_EQ(v(i), -kL * 0.5);
}

TEST(Kinematics, MatchesEquation41WheelByWheel) {
  // r·omega_i = [sin a_i, −cos a_i]·C_T·[Xdot_w, Ydot_w] − L·phidot.
  const double phi = 0.8;
  const Twist t(0.12, -0.07, 0.3);
  const WheelVector v = decoupling_matrix(phi, kL) * t;
  const double xm = std::cos(phi) * t(0) + std::sin(phi) * t(1);
  const double ym = -std::sin(phi) * t(0) + std::cos(phi) * t(1);
  for (int i = 0; i < 4; ++i) {
    const double a = wheel_alpha(i);
    EXPECT_NEAR(v(i), std::sin(a) * xm - std::cos(a) * ym - kL * t(2), 1e-12) << "wheel " << i;
  }
}

TEST(Kinematics, RoundTripThroughWheelSpeeds) {
  const Twist t(-0.2, 0.15, -0.4);
  const Twist back = platform_twist(wheel_speeds(t, 1.1, kL, kR), 1.1, kL, kR);
  EXPECT_TRUE(back.isApprox(t, 1e-12));
}

}  // namespace
}  // namespace omnitwin::physics
