// controller layer — odometry from the four HCTL-2032 counters (seed 002, eq. 4-6/4-7).
//
// The master's feedback path: each control sample it receives the four 32-bit counter
// readings, turns their wrap-safe differences into wheel speeds and, through D_i(phi),
// into the world twist, which it integrates into the pose. Fixed configuration in a struct,
// the pose and last readings as state; no allocation after construction.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>

#include "controller/path.hpp"

namespace omnitwin::controller {

using WheelCounts = std::array<int32_t, 4>;  // counter readings of wheels 1..4 [counts]

// Wrap-safe now − before of two 32-bit counter readings [counts]. Real-time safe.
inline int32_t counts_delta(int32_t now, int32_t before) {
  return static_cast<int32_t>(static_cast<uint32_t>(now) - static_cast<uint32_t>(before));
}

struct OdometryConfig {
  double period = 0.010;     // control sample period [s]
  double L = 0.25;           // wheel-to-centre distance [m]
  double r = 0.05;           // wheel radius [m]
  int counts_per_rev = 2000; // counter counts per wheel revolution (4·lines)
};

class Odometry {
 public:
  explicit Odometry(const OdometryConfig& config);

  // Starts at `pose` with these counter readings as the reference. Real-time safe.
  void reset(const Pose2& pose, const WheelCounts& counts);
  // One sample: delta counts → wheel speeds ω = Δ·2π/cpr/period [rad/s] → world twist
  // D_i(phi_mid)·(r·ω) → pose += twist·period, with phi_mid the heading halfway through the
  // sample (midpoint rule). Real-time safe.
  void update(const WheelCounts& counts);

  const Pose2& pose() const { return pose_; }
  const Eigen::Vector3d& twist() const { return twist_; }        // world [m/s, m/s, rad/s]
  const Eigen::Vector4d& wheel_speeds() const { return omega_; }  // [rad/s]
  const std::array<int32_t, 4>& delta_counts() const { return delta_; }  // last sample
  const OdometryConfig& config() const { return config_; }

 private:
  OdometryConfig config_;
  Pose2 pose_;
  WheelCounts last_{};
  std::array<int32_t, 4> delta_{};
  Eigen::Vector4d omega_ = Eigen::Vector4d::Zero();
  Eigen::Vector3d twist_ = Eigen::Vector3d::Zero();
};

}  // namespace omnitwin::controller
