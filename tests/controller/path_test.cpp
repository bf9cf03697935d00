// Tests controller/path: segments built from trapezoids — end poses and durations of line,
// arc, rotate, dwell, square, circle and figure-eight; positions continuous at every join;
// the circle and square close; the figure-eight is C1 and does not stop at its crossing;
// sampled velocity is the derivative of the sampled pose; holding before and after the path.
#include "controller/path.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>

namespace omnitwin::controller {
namespace {

constexpr double kPi = std::numbers::pi;

// A path that uses every kind of segment, starting at an odd pose.
Path mixed_path() {
  Path p({0.3, -0.2, 0.4});
  p.add_line(2.0, 0.5, 0.3, 20.0)
      .add_arc(0.0, 0.5, kPi / 2, -0.2, 5.0)
      .add_rotate(1.0, 2.0)
      .add_dwell(1.0)
      .add_square(0.5, 3.0, false)
      .add_circle(0.4, 6.0, true)
      .add_figure_eight(0.3, 8.0, true);
  return p;
}

TEST(Path, LineFollowsTheThesisProfileOnEachAxis) {
  Path p({1.0, 2.0, 0.5});
  p.add_line(2.0, -1.0, 0.6, 20.0);
  EXPECT_EQ(p.segment_count(), 1);
  EXPECT_DOUBLE_EQ(p.duration(), 20.0);
  const PathSample mid = p.sample(10.0);
  EXPECT_NEAR(mid.pose.x, 2.0, 1e-12);
  EXPECT_NEAR(mid.pose.y, 1.5, 1e-12);
  EXPECT_NEAR(mid.pose.phi, 0.8, 1e-12);
  EXPECT_NEAR(mid.velocity.x(), 0.15, 1e-12);
  EXPECT_NEAR(mid.velocity.y(), -0.075, 1e-12);
  EXPECT_EQ(mid.segment, 0);
  const Pose2 end = p.end_pose();
  EXPECT_DOUBLE_EQ(end.x, 3.0);
  EXPECT_DOUBLE_EQ(end.y, 1.0);
  EXPECT_DOUBLE_EQ(end.phi, 1.1);
}

TEST(Path, HoldsBeforeStartAndAfterEndWithZeroVelocity) {
  const Path p = mixed_path();
  const PathSample before = p.sample(-1.0), after = p.sample(p.duration() + 5.0);
  EXPECT_DOUBLE_EQ(before.pose.x, 0.3);
  EXPECT_TRUE(before.velocity.isZero());
  EXPECT_DOUBLE_EQ(after.pose.x, p.end_pose().x);
  EXPECT_DOUBLE_EQ(after.pose.y, p.end_pose().y);
  EXPECT_DOUBLE_EQ(after.pose.phi, p.end_pose().phi);
  EXPECT_TRUE(after.velocity.isZero());
  EXPECT_EQ(after.segment, p.segment_count() - 1);
}

TEST(Path, DurationsAddUpAndSegmentsAreCounted) {
  const Path p = mixed_path();
  // line, arc, rotate, dwell, 4 square sides, circle, eight.
  EXPECT_EQ(p.segment_count(), 10);
  EXPECT_DOUBLE_EQ(p.duration(), 20 + 5 + 2 + 1 + 4 * 3 + 6 + 8);
  EXPECT_DOUBLE_EQ(p.segment_start_time(4), 28.0);
  EXPECT_EQ(p.sample(28.5).segment, 4);
}

TEST(Path, PositionsAreContinuousAtEveryJoinAndSpeedIsZeroThere) {
  const Path p = mixed_path();
  for (int i = 1; i < p.segment_count(); ++i) {
    const double t = p.segment_start_time(i);
    const PathSample a = p.sample(t - 1e-9), b = p.sample(t), c = p.sample(t + 1e-9);
    EXPECT_NEAR(a.pose.x, b.pose.x, 1e-9) << i;
    EXPECT_NEAR(a.pose.y, b.pose.y, 1e-9) << i;
    EXPECT_NEAR(a.pose.phi, b.pose.phi, 1e-9) << i;
    EXPECT_NEAR(c.pose.x, b.pose.x, 1e-9) << i;
    EXPECT_NEAR(c.pose.y, b.pose.y, 1e-9) << i;
    EXPECT_LT(b.velocity.norm(), 1e-6) << i;
  }
}

TEST(Path, VelocityIsTheDerivativeOfThePose) {
  const Path p = mixed_path();
  const double h = 1e-6;
  for (double t = 0.05; t < p.duration(); t += 0.0937) {
    const PathSample s = p.sample(t), lo = p.sample(t - h), hi = p.sample(t + h);
    if (lo.segment != hi.segment) continue;
    EXPECT_NEAR((hi.pose.x - lo.pose.x) / (2 * h), s.velocity.x(), 1e-5) << t;
    EXPECT_NEAR((hi.pose.y - lo.pose.y) / (2 * h), s.velocity.y(), 1e-5) << t;
    EXPECT_NEAR((hi.pose.phi - lo.pose.phi) / (2 * h), s.velocity.z(), 1e-5) << t;
  }
}

TEST(Path, ArcCentreIsRelativeToItsStart) {
  Path p({1.0, 0.0, 0.0});
  p.add_arc(-1.0, 0.0, kPi / 2, 0.5, 4.0);  // centre at the origin, quarter turn ccw
  const Pose2 e = p.end_pose();
  EXPECT_NEAR(e.x, 0.0, 1e-12);
  EXPECT_NEAR(e.y, 1.0, 1e-12);
  EXPECT_DOUBLE_EQ(e.phi, 0.5);
  for (double t = 0; t <= 4.0; t += 0.25) {
    const PathSample s = p.sample(t);
    EXPECT_NEAR(std::hypot(s.pose.x, s.pose.y), 1.0, 1e-12);
  }
  EXPECT_GT(p.sample(2.0).velocity.y(), 0.0);  // leaves (1, 0) going +Y
}

TEST(Path, CircleClosesWithItsCentreLeftOfTheHeading) {
  for (bool ccw : {true, false}) {
    Path p({0.5, 0.5, kPi / 2});  // heading +Y: left is −X
    p.add_circle(0.4, 10.0, ccw);
    EXPECT_DOUBLE_EQ(p.end_pose().x, 0.5);
    EXPECT_DOUBLE_EQ(p.end_pose().y, 0.5);
    EXPECT_DOUBLE_EQ(p.end_pose().phi, kPi / 2);
    const double cx = ccw ? 0.1 : 0.9;
    for (double t = 0; t <= 10.0; t += 0.1) {
      const PathSample s = p.sample(t);
      EXPECT_NEAR(std::hypot(s.pose.x - cx, s.pose.y - 0.5), 0.4, 1e-12);
      EXPECT_DOUBLE_EQ(s.pose.phi, kPi / 2);
    }
    // It leaves along the heading, and reaches the far side at half time.
    EXPECT_GT(p.sample(0.5).velocity.y(), 0.0);
    EXPECT_NEAR(std::abs(p.sample(0.5).velocity.x()), 0.0, 0.05 * p.sample(0.5).velocity.y());
    EXPECT_NEAR(p.sample(5.0).pose.x, ccw ? -0.3 : 1.3, 1e-12);
  }
}

TEST(Path, SquareStartsAlongTheHeadingAndTurnsToTheChosenSide) {
  Path p({1.0, 1.0, kPi / 2});  // heading +Y
  p.add_square(0.5, 2.0, true);
  ASSERT_EQ(p.segment_count(), 4);
  // Corners: up, then left (−X), then down, then back.
  const Pose2 c1 = p.sample(2.0).pose, c2 = p.sample(4.0).pose, c3 = p.sample(6.0).pose;
  EXPECT_NEAR(c1.x, 1.0, 1e-12);
  EXPECT_NEAR(c1.y, 1.5, 1e-12);
  EXPECT_NEAR(c2.x, 0.5, 1e-12);
  EXPECT_NEAR(c2.y, 1.5, 1e-12);
  EXPECT_NEAR(c3.x, 0.5, 1e-12);
  EXPECT_NEAR(c3.y, 1.0, 1e-12);
  EXPECT_NEAR(p.end_pose().x, 1.0, 1e-15);
  EXPECT_NEAR(p.end_pose().y, 1.0, 1e-15);
  for (double t = 0; t <= 8.0; t += 0.3) EXPECT_DOUBLE_EQ(p.sample(t).pose.phi, kPi / 2);
  Path cw({0.0, 0.0, 0.0});
  cw.add_square(1.0, 1.0, false);  // +X then −Y
  EXPECT_NEAR(cw.sample(2.0).pose.x, 1.0, 1e-12);
  EXPECT_NEAR(cw.sample(2.0).pose.y, -1.0, 1e-12);
}

TEST(Path, FigureEightIsC1AndKeepsMovingThroughItsCrossing) {
  for (bool ccw : {true, false}) {
    Path p({0.0, 0.0, 0.0});
    p.add_figure_eight(0.5, 20.0, ccw);
    ASSERT_EQ(p.segment_count(), 1);
    // Crosses the start point at half time, moving along +X at cruise speed.
    const PathSample mid = p.sample(10.0);
    EXPECT_NEAR(mid.pose.x, 0.0, 1e-12);
    EXPECT_NEAR(mid.pose.y, 0.0, 1e-12);
    const double cruise = 0.5 * 4 * kPi / (20.0 * 2.0 / 3.0);  // R·Vmax in angle
    EXPECT_NEAR(mid.velocity.x(), cruise, 1e-9);
    EXPECT_NEAR(mid.velocity.y(), 0.0, 1e-9);
    // C1: velocity just either side of the crossing agrees.
    const PathSample a = p.sample(10.0 - 1e-7), b = p.sample(10.0 + 1e-7);
    EXPECT_NEAR((a.velocity - b.velocity).norm(), 0.0, 1e-6);
    // First lobe on the left (y ≥ 0 for ccw), second on the right.
    const double sign = ccw ? 1.0 : -1.0;
    double top = -1e9, bottom = 1e9;
    for (double t = 0.0; t <= 20.0; t += 0.001) {
      const double y = p.sample(t).pose.y * sign;
      if (t < 10.0) top = std::max(top, y);
      else bottom = std::min(bottom, y);
    }
    EXPECT_NEAR(top, 1.0, 1e-5);      // lobe 1: diameter 2R above
    EXPECT_NEAR(bottom, -1.0, 1e-5);  // lobe 2: diameter 2R below
    // Never stops inside, ends where it began with zero speed.
    for (double t = 0.1; t < 19.9; t += 0.1) EXPECT_GT(p.sample(t).velocity.norm(), 1e-3) << t;
    EXPECT_EQ(p.end_pose().x, 0.0);
    EXPECT_EQ(p.end_pose().y, 0.0);
    EXPECT_EQ(p.end_pose().phi, 0.0);
  }
}

TEST(Path, EmptyPathHoldsItsStart) {
  const Path p({1.0, 2.0, 3.0});
  EXPECT_EQ(p.segment_count(), 0);
  EXPECT_DOUBLE_EQ(p.duration(), 0.0);
  const PathSample s = p.sample(1.0);
  EXPECT_EQ(s.segment, -1);
  EXPECT_DOUBLE_EQ(s.pose.phi, 3.0);
  EXPECT_TRUE(s.velocity.isZero());
}

}  // namespace
}  // namespace omnitwin::controller
