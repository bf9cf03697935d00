// Tests controller/odometry: counter readings synthesised from known wheel motion (wheel
// angles integrated exactly for a constant world twist, then floored to counts like the
// HCTL-2032) give back the known pose — straight, rotation, combined — within the counts'
// quantisation, also across the 32-bit counter wrap; the twist and delta accessors.
#include "controller/odometry.hpp"

#include <gtest/gtest.h>

#include <climits>
#include <cmath>
#include <numbers>

#include "physics/kinematics.hpp"

namespace omnitwin::controller {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;
// Quantisation bounds: one count on every wheel is r·2π/cpr/L = 6.3e-4 rad of heading; that
// heading error held over a 2 m run is ~1 mm of cross-track position.
constexpr double kPhiTol = 6.3e-4, kPosTol = 1e-3;

// Wheel angles for a constant world twist from phi0 over t, exactly: D_e(phi) is
// A·sin phi + B·cos phi + C, so its integral is A·∫sin + B·∫cos + C·t.
Eigen::Vector4d wheel_angles(const Eigen::Vector3d& twist, double phi0, double t,
                             const OdometryConfig& c) {
  using physics::decoupling_matrix;
  using M = physics::DecouplingMatrix;
  const M d0 = decoupling_matrix(0.0, c.L), dpi = decoupling_matrix(std::numbers::pi, c.L);
  const M C = 0.5 * (d0 + dpi), B = 0.5 * (d0 - dpi);
  const M A = decoupling_matrix(std::numbers::pi / 2, c.L) - C;
  const double w = twist.z();
  const double phi = phi0 + w * t;
  const double is = w == 0.0 ? std::sin(phi0) * t : (std::cos(phi0) - std::cos(phi)) / w;
  const double ic = w == 0.0 ? std::cos(phi0) * t : (std::sin(phi) - std::sin(phi0)) / w;
  return (A * is + B * ic + C * t) * twist / c.r;
}

// Counter readings for wheel angles, floored to edges and offset by `base` (mod 2^32).
WheelCounts counts_of(const Eigen::Vector4d& angles, const OdometryConfig& c, int32_t base) {
  WheelCounts out{};
  for (int i = 0; i < 4; ++i) {
    const auto e = static_cast<int64_t>(std::floor(angles(i) * c.counts_per_rev / kTwoPi));
    out[i] = static_cast<int32_t>(static_cast<uint32_t>(base) + static_cast<uint32_t>(e));
  }
  return out;
}

// Runs odometry for `seconds` of a constant world twist from `start`; returns the odometry.
Odometry drive(const Eigen::Vector3d& twist, const Pose2& start, double seconds,
               int32_t base = 0, const OdometryConfig& cfg = {}) {
  Odometry odo(cfg);
  odo.reset(start, counts_of(Eigen::Vector4d::Zero(), cfg, base));
  const int n = static_cast<int>(std::lround(seconds / cfg.period));
  for (int k = 1; k <= n; ++k)
    odo.update(counts_of(wheel_angles(twist, start.phi, k * cfg.period, cfg), cfg, base));
  return odo;
}

TEST(Odometry, StraightLineAlongWorldX) {
  const Odometry o = drive({0.1, 0.0, 0.0}, {}, 20.0);
  EXPECT_NEAR(o.pose().x, 2.0, kPosTol);
  EXPECT_NEAR(o.pose().y, 0.0, kPosTol);
  EXPECT_NEAR(o.pose().phi, 0.0, kPhiTol);
  EXPECT_NEAR(o.twist().x(), 0.1, 0.02);  // one sample's speed, quantised to counts
}

TEST(Odometry, RotationOnTheSpot) {
  const Odometry o = drive({0.0, 0.0, 0.5}, {1.0, -1.0, 0.2}, 10.0);
  EXPECT_NEAR(o.pose().x, 1.0, kPosTol);
  EXPECT_NEAR(o.pose().y, -1.0, kPosTol);
  EXPECT_NEAR(o.pose().phi, 5.2, kPhiTol);
  // Turning ccw makes every wheel count down (kinematics.hpp sign convention).
  for (int d : o.delta_counts()) EXPECT_LT(d, 0);
}

TEST(Odometry, TranslationWhileTurning) {
  const Odometry o = drive({0.1, 0.05, 0.3}, {0.0, 0.0, -0.4}, 10.0);
  EXPECT_NEAR(o.pose().x, 1.0, kPosTol);
  EXPECT_NEAR(o.pose().y, 0.5, kPosTol);
  EXPECT_NEAR(o.pose().phi, 2.6, kPhiTol);
}

TEST(Odometry, MidpointHeadingMakesTurningTranslationAccurateAtFineResolution) {
  // With a very fine encoder the quantisation vanishes and what is left is the integration
  // error of the midpoint rule: well below a micrometre here.
  OdometryConfig fine;
  fine.counts_per_rev = 1 << 24;
  const Odometry o = drive({0.1, 0.05, 0.3}, {0.0, 0.0, -0.4}, 10.0, 0, fine);
  EXPECT_NEAR(o.pose().x, 1.0, 1e-6);
  EXPECT_NEAR(o.pose().y, 0.5, 1e-6);
  EXPECT_NEAR(o.pose().phi, 2.6, 1e-6);
}

TEST(Odometry, SameResultAcrossThe32BitCounterWrap) {
  const Odometry plain = drive({0.1, 0.05, 0.3}, {}, 5.0);
  const Odometry wrapped = drive({0.1, 0.05, 0.3}, {}, 5.0, INT32_MAX - 1000);
  EXPECT_DOUBLE_EQ(wrapped.pose().x, plain.pose().x);
  EXPECT_DOUBLE_EQ(wrapped.pose().y, plain.pose().y);
  EXPECT_DOUBLE_EQ(wrapped.pose().phi, plain.pose().phi);
}

TEST(Odometry, DeltaCountsGiveWheelSpeedsAndTwist) {
  const OdometryConfig cfg;
  Odometry odo(cfg);
  odo.reset({}, {INT32_MAX, 0, 0, INT32_MIN});
  // Wheels 1, 2 +10 counts, 3, 4 −10 counts (wheel 1 and 4 across the wrap): pure +X.
  odo.update({INT32_MIN + 9, 10, -10, INT32_MAX - 9});
  EXPECT_EQ(odo.delta_counts()[0], 10);
  EXPECT_EQ(odo.delta_counts()[3], -10);
  const double w = 10 * kTwoPi / 2000 / 0.01;
  EXPECT_NEAR(odo.wheel_speeds()(0), w, 1e-12);
  EXPECT_NEAR(odo.twist().x(), std::sqrt(2.0) * cfg.r * w, 1e-12);
  EXPECT_NEAR(odo.twist().y(), 0.0, 1e-12);
  EXPECT_NEAR(odo.twist().z(), 0.0, 1e-12);
  EXPECT_NEAR(odo.pose().x, odo.twist().x() * 0.01, 1e-15);
}

TEST(Odometry, CountsDeltaIsWrapSafe) {
  EXPECT_EQ(counts_delta(INT32_MIN, INT32_MAX), 1);
  EXPECT_EQ(counts_delta(INT32_MAX, INT32_MIN), -1);
  EXPECT_EQ(counts_delta(5, -7), 12);
}

}  // namespace
}  // namespace omnitwin::controller
