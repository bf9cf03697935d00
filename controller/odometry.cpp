// controller layer — odometry from the four counters; see odometry.hpp.
#include "controller/odometry.hpp"

#include <numbers>

#include "physics/kinematics.hpp"

namespace omnitwin::controller {

Odometry::Odometry(const OdometryConfig& config) : config_(config) {}

void Odometry::reset(const Pose2& pose, const WheelCounts& counts) {
  pose_ = pose;
  last_ = counts;
  delta_ = {};
  omega_.setZero();
  twist_.setZero();
}

void Odometry::update(const WheelCounts& counts) {
  // Wheel speeds from wrap-safe count differences.
  const double rad_per_count = 2.0 * std::numbers::pi / config_.counts_per_rev;
  for (int i = 0; i < 4; ++i) {
    delta_[i] = counts_delta(counts[i], last_[i]);
    omega_(i) = delta_[i] * rad_per_count / config_.period;
  }
  last_ = counts;
  // The yaw rate does not depend on phi: find the mid-sample heading first.
  const double phidot =
      physics::platform_twist(omega_, pose_.phi, config_.L, config_.r).z();
  const double phi_mid = pose_.phi + 0.5 * phidot * config_.period;
  // World twist at the midpoint heading, integrated over the sample.
  twist_ = physics::platform_twist(omega_, phi_mid, config_.L, config_.r);
  pose_.x += twist_.x() * config_.period;
  pose_.y += twist_.y() * config_.period;
  pose_.phi += twist_.z() * config_.period;
}

}  // namespace omnitwin::controller
