// bus_emulators/drive — profile generators (see cia402_profile.hpp).
#include "bus_emulators/drive/cia402_profile.hpp"

#include <algorithm>
#include <cmath>

#include "bus_emulators/drive/cia402_fsa.hpp"

namespace omnitwin::drive {

bool Trapezoid::step(double target, double vmax, double acc, double dec, double dt,
                     double end_vel) noexcept {
  acc = std::max(acc, 1e-9);
  dec = std::max(dec, 1e-9);
  vmax = std::max(vmax, 0.0);
  end_vel = std::clamp(end_vel, 0.0, vmax);
  const double s = target - pos;
  const double dir = s >= 0 ? 1.0 : -1.0;
  const double dist = std::fabs(s);
  const double v = vel * dir;  // speed toward the target (negative: moving away)
  double vn = 0;
  if (v < 0) {
    vn = std::min(v + dec * dt, 0.0);  // moving away: brake first
  } else {
    const double vref = std::sqrt(2.0 * dec * dist + end_vel * end_vel);
    vn = std::min({vmax, v + acc * dt, vref});
    // Never brake harder than dec (a target too close is overshot); the (dec·dt)²/v term
    // covers the discretisation of the sqrt braking curve in its last periods.
    const double dv = dec * dt;
    vn = std::max({vn, v - dv - dv * dv / std::max(v, 1e-9), 0.0});
  }
  const double travel = vn * dt;
  if (v >= 0 && travel >= dist) {
    if (end_vel > 0) {            // pass the target at speed (change on set-point)
      pos = target;
      vel = dir * std::max(vn, end_vel);
      done = true;
      return true;
    }
    if (vn <= 2.0 * dec * dt * (1.0 + 1e-9) + 1e-12) {  // lands within this period
      pos = target;
      vel = 0;
      done = true;
      return true;
    }
  }
  pos += dir * travel;
  vel = dir * vn;
  done = false;
  return false;
}

bool Trapezoid::stop(double dec, double dt) noexcept {
  dec = std::max(dec, 1e-9);
  const double speed = std::max(std::fabs(vel) - dec * dt, 0.0);
  vel = vel > 0 ? speed : -speed;
  pos += vel * dt;
  done = speed == 0;
  return done;
}

double ramp_velocity(double current, double target, double acc, double dec, double dt) noexcept {
  acc = std::max(acc, 1e-9);
  dec = std::max(dec, 1e-9);
  if (current != 0 && (current > 0) != (target > 0) && target != 0) {
    // Opposite sign: slow down to zero first.
    const double speed = std::max(std::fabs(current) - dec * dt, 0.0);
    return current > 0 ? speed : -speed;
  }
  if (std::fabs(target) >= std::fabs(current)) {
    const double step = acc * dt;
    return target > current ? std::min(current + step, target) : std::max(current - step, target);
  }
  const double step = dec * dt;
  return target > current ? std::min(current + step, target) : std::max(current - step, target);
}

double ramp_torque(double current, double target, double slope, double dt) noexcept {
  if (slope <= 0) return target;
  const double step = slope * dt;
  return target > current ? std::min(current + step, target) : std::max(current - step, target);
}

void ProfilePosition::reset(double pos) noexcept {
  traj_.reset(pos);
  target_ = pos;
  buffered_ = pos;
  last_accepted_ = pos;
  active_ = false;
  has_buffer_ = false;
  ack_ = false;
  limited_ = false;
  // prev_bit4_ kept: a set-point bit already high is no new edge.
}

PpOutput ProfilePosition::step(const PpInput& in, double dt) noexcept {
  const std::uint16_t c = in.controlword;
  const bool bit4 = (c & cw::new_set_point) != 0;
  const bool immediately = (c & cw::change_immediately) != 0;
  const bool relative = (c & cw::relative) != 0;
  const bool change_on_sp = (c & cw::change_on_set_point) != 0;
  const bool halt = (c & cw::halt) != 0;

  if (bit4 && !prev_bit4_ && !has_buffer_) {
    double t = relative ? last_accepted_ + in.target : in.target;
    bool clamped = false;
    if (in.limits) {
      const double c2 = std::clamp(t, in.min_pos, in.max_pos);
      clamped = c2 != t;
      t = c2;
    }
    if (immediately || !active_) {
      target_ = t;
      active_ = true;
      limited_ = clamped;
    } else {
      buffered_ = t;
      has_buffer_ = true;
      buffered_limited_ = clamped;
    }
    last_accepted_ = t;
    ack_ = true;
  }
  if (!bit4) ack_ = false;
  prev_bit4_ = bit4;

  PpOutput out;
  if (halt) {
    out.halted = traj_.stop(in.halt_dec, dt);
  } else if (active_) {
    double end_vel = 0;
    if (has_buffer_ && change_on_sp) {
      const bool same_dir = (buffered_ - target_) * (target_ - traj_.pos) > 0;
      end_vel = same_dir ? in.vmax : 0;
    }
    if (traj_.step(target_, in.vmax, in.acc, in.dec, dt, end_vel)) {
      if (has_buffer_) {
        target_ = buffered_;
        limited_ = buffered_limited_;
        has_buffer_ = false;
      } else {
        active_ = false;
      }
    }
  }
  out.demand_pos = traj_.pos;
  out.demand_vel = traj_.vel;
  out.set_point_ack = ack_ || has_buffer_;
  out.at_target = !halt && !active_ && traj_.done;
  out.limited = limited_;
  return out;
}

}  // namespace omnitwin::drive
