// controller layer — the platform loop of seed 002, fig. 4-13; see platform_loop.hpp.
#include "controller/platform_loop.hpp"

#include <cmath>
#include <numbers>

#include "physics/kinematics.hpp"

namespace omnitwin::controller {

namespace {
OdometryConfig odometry_config(const PlatformLoopConfig& c) {
  return OdometryConfig{c.period, c.L, c.r, c.counts_per_rev};
}
}  // namespace

PlatformLoop::PlatformLoop(const PlatformLoopConfig& config, const Path& path)
    : config_(config), path_(path), odometry_(odometry_config(config)) {
  // Until reset() with the counters at the start, the odometry says the path's start pose:
  // a master reporting it before its start read (0, 0, 0), an error of the whole start offset.
  odometry_.reset(path_.start_pose(), WheelCounts{});
}

void PlatformLoop::reset(const Pose2& start, const WheelCounts& counts) {
  odometry_.reset(start, counts);
  integral_.setZero();
}

PlatformLoopOutput PlatformLoop::step(double t, const WheelCounts& counts) {
  // Feedback: odometry from the counters (D_i).
  PlatformLoopOutput out;
  odometry_.update(counts);
  out.odom_pose = odometry_.pose();
  out.odom_twist = odometry_.twist();
  // Reference and world pose error. The heading error is not wrapped: the plan and the
  // odometry are both unwrapped from the same start heading, so a turn of several
  // revolutions (or one the yaw limit leaves behind by more than π) is made in full.
  out.reference = path_.sample(t);
  const Pose2& ref = out.reference.pose;
  out.error = {ref.x - out.odom_pose.x, ref.y - out.odom_pose.y, ref.phi - out.odom_pose.phi};
  // PI (+ feed-forward) → limited world twist.
  control(out);
  // D_e(phi_odom): wheel commands in rad/s and counts per sample.
  out.wheel_rad_s = physics::wheel_speeds(out.twist_command, out.odom_pose.phi, config_.L,
                                          config_.r);
  const double counts_per_rad = config_.counts_per_rev / (2.0 * std::numbers::pi);
  for (int i = 0; i < 4; ++i)
    out.wheel_counts_per_sample[i] = out.wheel_rad_s(i) * counts_per_rad * config_.period;
  return out;
}

void PlatformLoop::control(PlatformLoopOutput& out) {
  // Unlimited command with the integrators advanced by this sample's error.
  const Eigen::Vector3d& e = out.error;
  Eigen::Vector3d candidate, u;
  for (int j = 0; j < 3; ++j) {
    candidate(j) = integral_(j) + config_.ki[j] * e(j) * config_.period;
    u(j) = config_.kp[j] * e(j) + candidate(j);
  }
  if (config_.feedforward) u += out.reference.velocity;
  // Limits: translational speed magnitude (direction kept) and yaw rate.
  const double speed = std::hypot(u.x(), u.y());
  const bool xy_sat = speed > config_.max_speed;
  const bool yaw_sat = std::abs(u.z()) > config_.max_yaw_rate;
  if (xy_sat) u.head<2>() *= config_.max_speed / speed;
  if (yaw_sat) u.z() = std::copysign(config_.max_yaw_rate, u.z());
  // Conditional integration: keep the step unless the axis is saturated and its error
  // pushes the same way as its command.
  const bool sat[3] = {xy_sat, xy_sat, yaw_sat};
  for (int j = 0; j < 3; ++j)
    if (!(sat[j] && e(j) * u(j) > 0.0)) integral_(j) = candidate(j);
  out.saturated = xy_sat || yaw_sat;
  out.twist_command = u;
}

}  // namespace omnitwin::controller
