// controller layer — the platform loop of seed 002, fig. 4-13.
//
// Each control sample: odometry from the four counters (D_i), the planned pose from the
// path, a PI per world axis (x, y, phi) on the pose error plus, optionally, the planned
// velocity as feed-forward, limited in speed and yaw rate (the heading error is unwrapped, so
// every planned turn is made in full), then D_e(phi) splits the world twist into four wheel
// commands for the slaves. Configuration is fixed in a struct; the integrators and the
// odometry are the only state; step() does not allocate.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>

#include "controller/odometry.hpp"
#include "controller/path.hpp"

namespace omnitwin::controller {

struct PlatformLoopConfig {
  double period = 0.010;                 // control sample period [s]
  std::array<double, 3> kp{6.0, 6.0, 6.0};  // x, y [1/s]; phi [1/s]
  std::array<double, 3> ki{6.0, 6.0, 6.0};  // x, y [1/s²]; phi [1/s²]
  bool feedforward = false;              // add the planned world velocity (the thesis: no)
  double max_speed = 0.5;                // |(xdot, ydot)| limit of the command [m/s]
  double max_yaw_rate = 2.0;             // |phidot| limit of the command [rad/s]
  double L = 0.25;                       // wheel-to-centre distance [m]
  double r = 0.05;                       // wheel radius [m]
  int counts_per_rev = 2000;             // counter counts per wheel revolution (4·lines)
};

struct PlatformLoopOutput {
  PathSample reference;                                   // planned pose/velocity at t
  Pose2 odom_pose;                                        // odometry pose [m, m, rad]
  Eigen::Vector3d odom_twist = Eigen::Vector3d::Zero();   // odometry world twist
  Eigen::Vector3d error = Eigen::Vector3d::Zero();        // ref − odom (phi unwrapped)
  Eigen::Vector3d twist_command = Eigen::Vector3d::Zero();  // limited world twist command
  Eigen::Vector4d wheel_rad_s = Eigen::Vector4d::Zero();    // wheel commands [rad/s]
  std::array<double, 4> wheel_counts_per_sample{};          // ω·cpr·period/2π [counts/sample]
  bool saturated = false;                                 // a limit was active this sample
};

class PlatformLoop {
 public:
  // Keeps its own copy of the path (construction allocates; step() does not). The odometry
  // starts at the path's start pose with every count zero.
  PlatformLoop(const PlatformLoopConfig& config, const Path& path);

  // Odometry starts at `start` with these counter readings; integrators cleared. `start.phi`
  // is on the plan's unwrapped heading (the path's start pose, not one wrapped to ±π). RT-safe.
  void reset(const Pose2& start, const WheelCounts& counts);
  // One control sample at t [s] since path start with the counters read now. RT-safe.
  PlatformLoopOutput step(double t, const WheelCounts& counts);

  const Odometry& odometry() const { return odometry_; }
  const Path& path() const { return path_; }
  const PlatformLoopConfig& config() const { return config_; }
  const Eigen::Vector3d& integral() const { return integral_; }  // I terms [m/s, rad/s]

 private:
  // PI + feed-forward with limits and conditional integration; fills out.twist_command.
  void control(PlatformLoopOutput& out);

  PlatformLoopConfig config_;
  Path path_;
  Odometry odometry_;
  Eigen::Vector3d integral_ = Eigen::Vector3d::Zero();
};

}  // namespace omnitwin::controller
