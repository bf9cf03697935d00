// controller layer — paths of trapezoid-timed segments; see path.hpp.
#include "controller/path.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

namespace omnitwin::controller {

namespace {
constexpr double kPi = std::numbers::pi;

// Point on a circle of radius r about (cx, cy) at angle a, and its velocity for adot.
void circle_point(double cx, double cy, double r, double a, double adot, PathSample& out) {
  const double c = std::cos(a), s = std::sin(a);
  out.pose.x = cx + r * c;
  out.pose.y = cy + r * s;
  out.velocity.x() = -r * s * adot;
  out.velocity.y() = r * c * adot;
}
}  // namespace

Path::Path(const Pose2& start) : start_(start) {}

Pose2 Path::end_pose() const { return segments_.empty() ? start_ : segments_.back().end; }

double Path::segment_start_time(int i) const { return segments_.at(static_cast<size_t>(i)).t0; }

Path& Path::push(Segment seg) {
  // The segment starts at the current end; its end is its own sample at T (exact D's).
  seg.t0 = duration_;
  seg.start = end_pose();
  seg.end = evaluate(seg, seg.px.duration()).pose;
  duration_ += seg.px.duration();
  segments_.push_back(seg);
  return *this;
}

Path& Path::add_line(double dx, double dy, double dphi, double T) {
  Segment s;
  s.kind = Kind::line;
  s.px = Trapezoid(dx, T);
  s.py = Trapezoid(dy, T);
  s.pphi = Trapezoid(dphi, T);
  s.start = end_pose();  // evaluate() needs it before push() stamps it
  return push(s);
}

Path& Path::add_arc(double cx, double cy, double sweep, double dphi, double T) {
  // Centre absolute; the start angle is where the start point sits on the circle.
  Segment s;
  s.kind = Kind::arc;
  s.start = end_pose();
  s.cx = s.start.x + cx;
  s.cy = s.start.y + cy;
  s.radius = std::hypot(cx, cy);
  s.theta0 = std::atan2(-cy, -cx);
  s.px = Trapezoid(sweep, T);
  s.pphi = Trapezoid(dphi, T);
  return push(s);
}

Path& Path::add_rotate(double dphi, double T) { return add_line(0.0, 0.0, dphi, T); }

Path& Path::add_dwell(double T) { return add_line(0.0, 0.0, 0.0, T); }

Path& Path::add_square(double side, double T_per_side, bool ccw) {
  // Corners from the start along u (heading) and v (u turned ±90°); the last side goes
  // back to the start corner itself.
  const Pose2 p0 = end_pose();
  const double ux = std::cos(p0.phi), uy = std::sin(p0.phi);
  const double turn = ccw ? 1.0 : -1.0;
  const double vx = -turn * uy, vy = turn * ux;
  add_line(side * ux, side * uy, 0.0, T_per_side);
  add_line(side * vx, side * vy, 0.0, T_per_side);
  add_line(-side * ux, -side * uy, 0.0, T_per_side);
  const Pose2 p3 = end_pose();
  return add_line(p0.x - p3.x, p0.y - p3.y, 0.0, T_per_side);
}

Path& Path::add_circle(double radius, double T, bool ccw) {
  // Centre on the left (ccw) or right of the heading direction, one full turn.
  const double phi = end_pose().phi;
  const double side = ccw ? 1.0 : -1.0;
  const double nx = -std::sin(phi) * side * radius, ny = std::cos(phi) * side * radius;
  return add_arc(nx, ny, side * 2.0 * kPi, 0.0, T);
}

Path& Path::add_figure_eight(double radius, double T, bool ccw) {
  // Two circles tangent at the start point, centres on either side of the heading.
  Segment s;
  s.kind = Kind::eight;
  s.start = end_pose();
  s.dir = ccw ? 1.0 : -1.0;
  const double nx = -std::sin(s.start.phi) * s.dir * radius;
  const double ny = std::cos(s.start.phi) * s.dir * radius;
  s.radius = radius;
  s.cx = s.start.x + nx;
  s.cy = s.start.y + ny;
  s.theta0 = std::atan2(-ny, -nx);
  s.cx2 = s.start.x - nx;
  s.cy2 = s.start.y - ny;
  s.theta0_2 = std::atan2(ny, nx);
  // One trapezoid over the total angle of both circles.
  s.px = Trapezoid(4.0 * kPi, T);
  s.pphi = Trapezoid(0.0, T);
  return push(s);
}

PathSample Path::sample(double t) const {
  // Before the start / after the end: hold, zero velocity.
  PathSample out;
  if (segments_.empty()) {
    out.pose = start_;
    return out;
  }
  if (t <= 0.0) {
    out.pose = start_;
    out.segment = 0;
    return out;
  }
  if (t >= duration_) {
    out.pose = segments_.back().end;
    out.segment = segment_count() - 1;
    return out;
  }
  // Last segment whose start time is ≤ t (binary search, no allocation).
  const auto it = std::upper_bound(segments_.begin(), segments_.end(), t,
                                   [](double v, const Segment& s) { return v < s.t0; });
  const auto& seg = *(it - 1);
  out = evaluate(seg, t - seg.t0);
  out.segment = static_cast<int>(it - 1 - segments_.begin());
  return out;
}

PathSample Path::evaluate(const Segment& s, double tau) const {
  if (s.kind == Kind::arc) return eval_arc(s, tau);
  if (s.kind == Kind::eight) return eval_eight(s, tau);
  // Line: x, y, phi each on their own trapezoid.
  PathSample out;
  out.pose = {s.start.x + s.px.position(tau), s.start.y + s.py.position(tau),
              s.start.phi + s.pphi.position(tau)};
  out.velocity = {s.px.velocity(tau), s.py.velocity(tau), s.pphi.velocity(tau)};
  return out;
}

PathSample Path::eval_arc(const Segment& s, double tau) const {
  // Angle along its trapezoid; at tau = T the angle is exactly the sweep.
  PathSample out;
  const double a = s.px.position(tau);
  circle_point(s.cx, s.cy, s.radius, s.theta0 + a, s.px.velocity(tau), out);
  // A full sweep lands exactly on the start point (no rounding of cos/sin of 2π).
  if (tau >= s.px.duration() && std::fmod(std::abs(s.px.distance()), 2.0 * kPi) == 0.0) {
    out.pose.x = s.start.x;
    out.pose.y = s.start.y;
  }
  out.pose.phi = s.start.phi + s.pphi.position(tau);
  out.velocity.z() = s.pphi.velocity(tau);
  return out;
}

PathSample Path::eval_eight(const Segment& s, double tau) const {
  // First 2π on circle 1 (turning dir), then 2π on circle 2 (turning −dir).
  PathSample out;
  const double a = s.px.position(tau), adot = s.px.velocity(tau);
  if (a < 2.0 * kPi) {
    circle_point(s.cx, s.cy, s.radius, s.theta0 + s.dir * a, s.dir * adot, out);
  } else {
    const double b = a - 2.0 * kPi;
    circle_point(s.cx2, s.cy2, s.radius, s.theta0_2 - s.dir * b, -s.dir * adot, out);
  }
  if (tau >= s.px.duration()) {
    out.pose.x = s.start.x;
    out.pose.y = s.start.y;
  }
  out.pose.phi = s.start.phi;
  out.velocity.z() = 0.0;
  return out;
}

}  // namespace omnitwin::controller
