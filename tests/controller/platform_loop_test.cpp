// Tests controller/platform_loop: the fig. 4-13 platform loop closed around an ideal
// kinematic plant (commanded wheel speeds integrated exactly into wheel angles and HCTL-style
// counts; the true pose integrated from the same wheel speeds). It tracks the thesis move
// (2 m in 20 s) and ends within 1 mm of the goal after settling, with and without
// feed-forward; it tracks a path with turns and a rotation; the limits hold and the
// integrators do not wind up; the wheel commands are D_e(phi)·twist in both units.
#include "controller/platform_loop.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

#include "physics/kinematics.hpp"

namespace omnitwin::controller {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

// Ideal plant: wheels turn exactly at the commanded speed for one period; the true pose
// follows D_i(phi)·(r·ω) integrated in fine substeps.
struct KinematicPlant {
  explicit KinematicPlant(const PlatformLoopConfig& c) : cfg(c) {}
  PlatformLoopConfig cfg;
  Eigen::Vector4d angles = Eigen::Vector4d::Zero();
  Pose2 pose;

  WheelCounts counts() const {
    WheelCounts c{};
    for (int i = 0; i < 4; ++i)
      c[i] = static_cast<int32_t>(std::floor(angles(i) * cfg.counts_per_rev / kTwoPi));
    return c;
  }
  void advance(const Eigen::Vector4d& omega) {
    const int n = 20;
    const double h = cfg.period / n;
    for (int k = 0; k < n; ++k) {
      const double phidot = physics::platform_twist(omega, pose.phi, cfg.L, cfg.r).z();
      const Eigen::Vector3d v =
          physics::platform_twist(omega, pose.phi + 0.5 * h * phidot, cfg.L, cfg.r);
      pose.x += v.x() * h;
      pose.y += v.y() * h;
      pose.phi += v.z() * h;
    }
    angles += omega * cfg.period;
  }
};

struct RunResult {
  Pose2 true_end, odom_end;
  double max_error = 0.0;  // max |(ex, ey)| of true pose vs reference while on the path [m]
  double max_speed = 0.0;  // max |(xdot, ydot)| commanded [m/s]
  double max_yaw = 0.0;    // max |phidot| commanded [rad/s]
};

// Runs the loop from the path's start for path duration + settle [s].
RunResult run(const PlatformLoopConfig& cfg, const Path& path, double settle,
              Pose2 plant_start) {
  KinematicPlant plant{cfg};
  plant.pose = plant_start;
  PlatformLoop loop(cfg, path);
  loop.reset(path.start_pose(), plant.counts());
  RunResult r;
  const int n = static_cast<int>(std::lround((path.duration() + settle) / cfg.period));
  for (int k = 1; k <= n; ++k) {
    const double t = k * cfg.period;
    const PlatformLoopOutput out = loop.step(t, plant.counts());
    r.max_speed = std::max(r.max_speed, out.twist_command.head<2>().norm());
    r.max_yaw = std::max(r.max_yaw, std::abs(out.twist_command.z()));
    plant.advance(out.wheel_rad_s);
    const PathSample ref = path.sample(t + cfg.period);
    if (t < path.duration())
      r.max_error = std::max(r.max_error,
                             std::hypot(ref.pose.x - plant.pose.x, ref.pose.y - plant.pose.y));
  }
  r.true_end = plant.pose;
  r.odom_end = loop.odometry().pose();
  return r;
}

PlatformLoopConfig thesis_config(bool feedforward) {
  PlatformLoopConfig cfg;
  cfg.feedforward = feedforward;
  return cfg;
}

TEST(PlatformLoop, ThesisLineEndsWithinOneMillimetreWithAndWithoutFeedforward) {
  Path path;
  path.add_line(2.0, 0.0, 0.0, 20.0);
  for (bool ff : {true, false}) {
    const RunResult r = run(thesis_config(ff), path, 10.0, path.start_pose());
    EXPECT_NEAR(r.true_end.x, 2.0, 1e-3) << "ff=" << ff;
    EXPECT_NEAR(r.true_end.y, 0.0, 1e-3) << "ff=" << ff;
    EXPECT_NEAR(r.true_end.phi, 0.0, 1e-3) << "ff=" << ff;
    EXPECT_NEAR(r.odom_end.x, 2.0, 1e-3) << "ff=" << ff;
    // Tracking on the way: feed-forward within a few counts, PI alone within centimetres.
    EXPECT_LT(r.max_error, ff ? 2e-3 : 0.05) << "ff=" << ff;
    std::printf("ff=%d max tracking error %.3f mm, end error %.3f mm\n", ff, r.max_error * 1e3,
                std::hypot(r.true_end.x - 2.0, r.true_end.y) * 1e3);
  }
}

TEST(PlatformLoop, FeedforwardTracksTighterThanPiAlone) {
  Path path;
  path.add_line(2.0, 0.0, 0.0, 20.0);
  const RunResult with = run(thesis_config(true), path, 0.0, path.start_pose());
  const RunResult without = run(thesis_config(false), path, 0.0, path.start_pose());
  EXPECT_LT(with.max_error * 5.0, without.max_error);
}

TEST(PlatformLoop, TracksTurnsAndRotationWhileTranslating) {
  Path path({0.5, -0.5, 0.3});
  path.add_line(1.0, 0.5, 1.2, 10.0).add_square(0.6, 4.0, true).add_circle(0.5, 12.0, false)
      .add_figure_eight(0.4, 16.0, true);
  const RunResult r = run(thesis_config(true), path, 8.0, path.start_pose());
  const Pose2 goal = path.end_pose();
  EXPECT_NEAR(r.true_end.x, goal.x, 1e-3);
  EXPECT_NEAR(r.true_end.y, goal.y, 1e-3);
  EXPECT_NEAR(r.true_end.phi, goal.phi, 1e-3);
  EXPECT_LT(r.max_error, 5e-3);
}

// Found in review: a 720° turn in 3 s asks 4.2 rad/s of a 2 rad/s yaw limit; the heading
// error grew past 180°, was wrapped to its short way round and the platform stopped a whole
// turn short. The plan, the odometry and the error are unwrapped: every planned turn is made.
TEST(PlatformLoop, ARotateFasterThanTheYawLimitCompletesEveryPlannedTurn) {
  Path path;
  path.add_rotate(2.0 * kTwoPi, 3.0);
  const RunResult r = run(thesis_config(false), path, 10.0, path.start_pose());  // 3 s behind: settles slowly
  EXPECT_NEAR(r.true_end.phi, 2.0 * kTwoPi, 1e-3);
  EXPECT_NEAR(r.odom_end.phi, 2.0 * kTwoPi, 1e-3);
  EXPECT_LE(r.max_yaw, 2.0 + 1e-12);
}

// A start heading past a turn (400°) is the plan's own start, not 40°: the platform turns by
// the planned −30° from there, not by a wrapped difference.
TEST(PlatformLoop, AStartHeadingPastOneTurnIsTrackedAsPlanned) {
  constexpr double kDeg = std::numbers::pi / 180.0;
  Path path({0.0, 0.0, 400.0 * kDeg});
  path.add_line(1.0, 0.5, -30.0 * kDeg, 10.0);
  const RunResult r = run(thesis_config(false), path, 2.0, path.start_pose());
  EXPECT_NEAR(r.true_end.x, 1.0, 1e-3);
  EXPECT_NEAR(r.true_end.y, 0.5, 1e-3);
  EXPECT_NEAR(r.true_end.phi, 370.0 * kDeg, 1e-3);
}

// Before reset(), the odometry already says the path's start pose: a fieldbus master reports
// it from its first tick, and (0, 0, 0) there read as an error of the whole start offset in
// platform_odometry (111.8 cm for a start at (1, 0.5), 190° for a start at 190°; found in
// review).
TEST(PlatformLoop, OdometryStartsAtThePathsStartPose) {
  constexpr double kDeg = std::numbers::pi / 180.0;
  Path path({1.0, 0.5, 190.0 * kDeg});
  path.add_line(1.0, 0.0, 0.0, 10.0);
  const PlatformLoop loop(thesis_config(false), path);
  EXPECT_DOUBLE_EQ(loop.odometry().pose().x, 1.0);
  EXPECT_DOUBLE_EQ(loop.odometry().pose().y, 0.5);
  EXPECT_DOUBLE_EQ(loop.odometry().pose().phi, 190.0 * kDeg);
}

TEST(PlatformLoop, LimitsHoldAndIntegratorsDoNotWindUp) {
  // The platform starts 1 m off and 1 rad off its (standing) reference with tight limits.
  PlatformLoopConfig cfg = thesis_config(true);
  cfg.max_speed = 0.1;
  cfg.max_yaw_rate = 0.2;
  Path path;
  path.add_dwell(20.0);
  PlatformLoop loop(cfg, path);
  KinematicPlant plant{cfg};
  loop.reset({1.0, 0.0, 1.0}, plant.counts());  // odometry believes it is 1 m, 1 rad off
  double min_x = 1e9;
  for (int k = 1; k <= 3000; ++k) {
    const PlatformLoopOutput out = loop.step(k * cfg.period, plant.counts());
    EXPECT_LE(out.twist_command.head<2>().norm(), cfg.max_speed + 1e-12);
    EXPECT_LE(std::abs(out.twist_command.z()), cfg.max_yaw_rate + 1e-12);
    plant.advance(out.wheel_rad_s);
    min_x = std::min(min_x, loop.odometry().pose().x);
    // While saturated for ~10 s the integrals stay small (no wind-up).
    EXPECT_LT(loop.integral().head<2>().norm(), 0.1) << k;
  }
  // Overshoot past the reference stays within a few millimetres, and it settles on it.
  EXPECT_GT(min_x, -5e-3);
  EXPECT_NEAR(loop.odometry().pose().x, 0.0, 1e-3);
  EXPECT_NEAR(loop.odometry().pose().phi, 0.0, 1e-3);
}

TEST(PlatformLoop, WheelCommandsAreDeTimesTheTwistInBothUnits) {
  PlatformLoopConfig cfg = thesis_config(true);
  Path path({0.0, 0.0, 0.7});
  path.add_line(1.0, 0.5, 0.4, 5.0);
  PlatformLoop loop(cfg, path);
  loop.reset(path.start_pose(), {0, 0, 0, 0});
  const PlatformLoopOutput out = loop.step(2.5, {0, 0, 0, 0});
  const Eigen::Vector4d expect =
      physics::wheel_speeds(out.twist_command, out.odom_pose.phi, cfg.L, cfg.r);
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(out.wheel_rad_s(i), expect(i), 1e-12);
    EXPECT_NEAR(out.wheel_counts_per_sample[i], expect(i) * 2000 * 0.01 / kTwoPi, 1e-12);
  }
  // The error is reference minus odometry, here the planned pose itself.
  EXPECT_NEAR(out.error.x(), out.reference.pose.x, 1e-12);
  EXPECT_NEAR(out.error.z(), out.reference.pose.phi - 0.7, 1e-12);
}

}  // namespace
}  // namespace omnitwin::controller
