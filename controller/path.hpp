// controller layer — paths of trapezoid-timed segments (seed 002 §4-3; DESIGN §7).
//
// The master's command calculation: a path is a start pose and a list of segments, each
// starting where the previous one ended and running its own trapezoid (Ta = T/3) over its
// own duration, so speed is zero at every join except inside a figure-eight, which is one
// segment with one trapezoid over its whole length. Building allocates; sample() does not,
// so it can run every control tick. World frame, metres and radians, phi ccw-positive.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "controller/trapezoid.hpp"

namespace omnitwin::controller {

struct Pose2 {
  double x = 0.0, y = 0.0, phi = 0.0;  // world [m, m, rad]
};

struct PathSample {
  Pose2 pose;                                        // planned pose
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();  // world (xdot, ydot, phidot) [m/s, rad/s]
  int segment = -1;  // active segment index; the last one past the end; −1 for an empty path
};

class Path {
 public:
  explicit Path(const Pose2& start = {});

  // Straight move by (dx, dy) [m] with a heading change dphi [rad] over T [s]: x, y and phi
  // each follow their own trapezoid at the same time (the thesis's x, y, phi planning).
  Path& add_line(double dx, double dy, double dphi, double T);
  // Arc about the centre (cx, cy) [m], given relative to the segment's start point, sweeping
  // `sweep` [rad, ccw > 0] along a trapezoid in angle; the heading changes by dphi [rad]
  // along the same trapezoid shape. sweep = 0 is a pure dphi turn.
  Path& add_arc(double cx, double cy, double sweep, double dphi, double T);
  // Turn on the spot by dphi [rad] over T [s].
  Path& add_rotate(double dphi, double T);
  // Stand still for T [s].
  Path& add_dwell(double T);
  // Square of side `side` [m]: four line segments of T_per_side [s] each. The first side runs
  // along the platform's current heading direction (cos phi, sin phi); after each side the
  // direction turns 90° left (ccw = true) or right. The heading itself stays fixed (the omni
  // platform translates); the fourth side returns to the start point.
  Path& add_square(double side, double T_per_side, bool ccw = true);
  // Full circle of `radius` [m] over T [s] starting at the current point and leaving it along
  // the current heading direction; the centre is to the left (ccw) or right of that direction.
  // One trapezoid in angle; the heading stays fixed.
  Path& add_circle(double radius, double T, bool ccw = true);
  // Figure-eight of two tangent circles of `radius` [m] through the current point, both
  // leaving it along the current heading direction: first the circle with its centre on the
  // left (ccw = true; mirrored if false), then the one on the right. ONE trapezoid over the
  // total angle 4π (equal radii, so over the arc length): the speed does not stop at the
  // crossing and the path is C1 there. The heading stays fixed.
  Path& add_figure_eight(double radius, double T, bool ccw = true);

  double duration() const { return duration_; }      // total [s]
  Pose2 start_pose() const { return start_; }
  Pose2 end_pose() const;                              // where the last segment ends
  int segment_count() const { return static_cast<int>(segments_.size()); }
  double segment_start_time(int i) const;              // [s] from path start

  // Planned pose and world velocity at t [s] from path start. t < 0 gives the start pose,
  // t ≥ duration() the end pose, both with zero velocity. Real-time safe (no allocation).
  PathSample sample(double t) const;

 private:
  enum class Kind { line, arc, eight };
  struct Segment {
    Kind kind = Kind::line;
    double t0 = 0.0;   // start time on the path [s]
    Pose2 start, end;
    Trapezoid px, py, pphi;  // line: x, y, phi; arc/eight: px = angle, pphi = heading
    double cx = 0.0, cy = 0.0, radius = 0.0, theta0 = 0.0;  // arc / first circle (absolute)
    double cx2 = 0.0, cy2 = 0.0, theta0_2 = 0.0;            // figure-eight second circle
    double dir = 1.0;  // figure-eight: +1 if the first circle is ccw, −1 if cw
  };

  Path& push(Segment seg);                          // stamps t0 and end, appends
  PathSample evaluate(const Segment& s, double tau) const;  // tau: time into the segment
  PathSample eval_arc(const Segment& s, double tau) const;
  PathSample eval_eight(const Segment& s, double tau) const;

  Pose2 start_;
  double duration_ = 0.0;
  std::vector<Segment> segments_;
};

}  // namespace omnitwin::controller
