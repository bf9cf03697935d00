// bus_emulators/drive — CiA 402 homing methods (see cia402_homing.hpp).
#include "bus_emulators/drive/cia402_homing.hpp"

#include <algorithm>
#include <cmath>

namespace omnitwin::drive {

namespace {
// Switch patterns (see the header).
enum Kind { kNone = 0, kNl = 1, kPl = 2, kPosHome = 3, kNegHome = 4, kCam = 5 };

struct MethodRule {
  int kind, boundary, dir, init_dir;
};

// The rule of a switch method 1–14 (17–30 use the rule of method − 16 without index).
MethodRule rule_of(int m) {
  switch (m) {
    case 1: return {kNl, 0, +1, 0};
    case 2: return {kPl, 0, -1, 0};
    case 3: return {kPosHome, 0, -1, 0};
    case 4: return {kPosHome, 0, +1, 0};
    case 5: return {kNegHome, 0, +1, 0};
    case 6: return {kNegHome, 0, -1, 0};
    case 7: return {kCam, 0, -1, +1};
    case 8: return {kCam, 0, +1, +1};
    case 9: return {kCam, 1, -1, +1};
    case 10: return {kCam, 1, +1, +1};
    case 11: return {kCam, 1, +1, -1};
    case 12: return {kCam, 1, -1, -1};
    case 13: return {kCam, 0, +1, -1};
    case 14: return {kCam, 0, -1, -1};
    default: return {kNone, 0, +1, 0};
  }
}

// State of the switch in region 0 for the two-region patterns.
bool region0_state(int kind) { return kind == kNl || kind == kNegHome; }
}  // namespace

bool homing_method_supported(int m) noexcept {
  return (m >= 1 && m <= 14) || (m >= 17 && m <= 30) || m == 33 || m == 34 || m == 35 ||
         m == 37;
}

void Homing::reset(double pos) noexcept {
  phase_ = Phase::idle;
  traj_.reset(pos);
  has_home_ = false;
}

bool Homing::switch_state(const HomingSignals& s) const noexcept {
  switch (kind_) {
    case kNl: return s.nl;
    case kPl: return s.pl;
    case kPosHome:
    case kNegHome:
    case kCam: return s.home;
    default: return false;
  }
}

double Homing::switch_edge(const HomingSignals& s) const noexcept {
  switch (kind_) {
    case kNl: return s.nl_edge;
    case kPl: return s.pl_edge;
    default: return s.home_edge;
  }
}

double Homing::index_beyond(const HomingParams& p, double from, int dir) const noexcept {
  const double cpr = p.counts_per_rev > 0 ? p.counts_per_rev : 1;
  const double k = (from - p.index_offset) / cpr;
  if (dir > 0) {
    double kk = std::floor(k) + 1;
    return p.index_offset + kk * cpr;
  }
  double kk = std::ceil(k) - 1;
  return p.index_offset + kk * cpr;
}

void Homing::run_at(double v_target, double acc, double dt) noexcept {
  traj_.vel = ramp_velocity(traj_.vel, v_target, acc, acc, dt);
  traj_.pos += traj_.vel * dt;
  traj_.done = false;
}

void Homing::start(const HomingParams& p, const HomingSignals& s, double demand_pos,
                   double demand_vel) noexcept {
  traj_.reset(demand_pos, demand_vel);
  method_ = p.method;
  travel_ = 0;
  prev_pos_ = s.pos;
  has_home_ = false;
  latch_now_ = false;
  kind_ = kNone;
  if (!homing_method_supported(method_)) {
    phase_ = Phase::error;
    return;
  }
  if (method_ == 35 || method_ == 37) {
    home_ = s.pos;
    has_home_ = true;
    latch_now_ = true;
    traj_.reset(demand_pos, 0);
    phase_ = Phase::attained;
    return;
  }
  if (method_ == 33 || method_ == 34) {
    dir_ = method_ == 33 ? -1 : +1;
    use_index_ = true;
    index_target_ = index_beyond(p, s.pos, dir_);
    phase_ = Phase::index;
    return;
  }
  const int base = method_ <= 14 ? method_ : method_ - 16;
  use_index_ = method_ <= 14;
  const MethodRule r = rule_of(base);
  kind_ = r.kind;
  boundary_ = r.boundary;
  dir_ = r.dir;
  init_dir_ = r.init_dir;
  const bool st = switch_state(s);
  prev_state_ = st;
  if (kind_ == kCam) {
    region_ = st ? 1 : -1;
  } else {
    region_ = st == region0_state(kind_) ? 0 : 1;
  }
  phase_ = region_ < 0 ? Phase::locate : Phase::approach;
}

HomingOutput Homing::step(const HomingParams& p, const HomingSignals& s, bool abort,
                          double dt) noexcept {
  HomingOutput out;
  const double acc = std::max(p.acc, 1.0);
  const double stop_dec = p.stop_dec > 0 ? p.stop_dec : acc;
  const double move = s.pos - prev_pos_;
  const int mdir = move > 0 ? 1 : (move < 0 ? -1 : (traj_.vel > 0 ? 1 : (traj_.vel < 0 ? -1 : 0)));
  travel_ += std::fabs(move);
  prev_pos_ = s.pos;
  const bool st = switch_state(s);
  const bool changed = kind_ != kNone && st != prev_state_;
  prev_state_ = st;
  const bool searching =
      phase_ == Phase::locate || phase_ == Phase::approach || phase_ == Phase::index;
  if (abort && (searching || phase_ == Phase::move_home)) phase_ = Phase::idle;
  if (searching && travel_ > p.max_search) fail();

  // A limit switch in the direction of the commanded motion that the method does not use.
  auto limit_blocks = [&](double v) {
    if (v > 0 && s.pl && kind_ != kPl && !(phase_ == Phase::locate && init_dir_ > 0)) return true;
    if (v < 0 && s.nl && kind_ != kNl && !(phase_ == Phase::locate && init_dir_ < 0)) return true;
    return false;
  };
  // Search at v, or fail and stop on a limit switch the method does not use.
  auto search_at = [&](double v) {
    if (limit_blocks(v)) {
      fail();
      traj_.stop(stop_dec, dt);
    } else {
      run_at(v, acc, dt);
    }
  };

  switch (phase_) {
    case Phase::idle:
      traj_.stop(acc, dt);
      break;
    case Phase::locate: {
      const bool hit = init_dir_ > 0 ? s.pl : s.nl;
      if (changed && st) {
        region_ = 1;  // entered the cam
        phase_ = Phase::approach;
      } else if (hit) {
        region_ = init_dir_ > 0 ? 2 : 0;  // beyond the cam: reverse
        phase_ = Phase::approach;
      }
      if (phase_ == Phase::locate) {
        const double v = init_dir_ * p.v_switch;
        search_at(v);
        break;
      }
      [[fallthrough]];
    }
    case Phase::approach: {
      if (phase_ != Phase::approach) break;
      if (changed) {
        if (kind_ == kCam) {
          region_ = st ? 1 : (mdir > 0 ? 2 : 0);
        } else {
          region_ = st == region0_state(kind_) ? 0 : 1;
        }
        const int after = dir_ > 0 ? boundary_ + 1 : boundary_;
        if (mdir == dir_ && region_ == after) {
          const double edge = switch_edge(s);
          if (use_index_) {
            index_target_ = index_beyond(p, edge, dir_);
            phase_ = Phase::index;
          } else {
            home_ = edge;
            has_home_ = true;
            latch_now_ = true;
            phase_ = Phase::move_home;
          }
        }
      }
      if (phase_ == Phase::approach) {
        const int before = dir_ > 0 ? boundary_ : boundary_ + 1;
        double v = dir_ * p.v_zero;
        if (region_ < before) v = p.v_switch;
        if (region_ > before) v = -p.v_switch;
        search_at(v);
        break;
      }
      if (phase_ == Phase::move_home) {
        traj_.step(home_, std::max(p.v_zero, 1.0), acc, acc, dt);
        break;
      }
      [[fallthrough]];
    }
    case Phase::index: {
      if (phase_ != Phase::index) break;
      if ((dir_ > 0 && s.pos >= index_target_) || (dir_ < 0 && s.pos <= index_target_)) {
        home_ = index_target_;
        has_home_ = true;
        latch_now_ = true;
        phase_ = Phase::move_home;
        traj_.step(home_, std::max(p.v_zero, 1.0), acc, acc, dt);
        break;
      }
      const double v = dir_ * p.v_zero;
      search_at(v);
      break;
    }
    case Phase::move_home:
      if (traj_.step(home_, std::max(p.v_zero, 1.0), acc, acc, dt) &&
          std::fabs(s.pos - home_) <= 1.0) {
        phase_ = Phase::attained;
      }
      break;
    case Phase::attained:
      traj_.vel = 0;
      traj_.done = true;
      break;
    case Phase::error:
      traj_.stop(stop_dec, dt);
      break;
  }
  out.demand_pos = traj_.pos;
  out.demand_vel = traj_.vel;
  out.active = phase_ == Phase::locate || phase_ == Phase::approach || phase_ == Phase::index ||
               phase_ == Phase::move_home || traj_.vel != 0;
  out.attained = phase_ == Phase::attained;
  out.error = phase_ == Phase::error;
  out.latched = latch_now_;
  out.home_pos = home_;
  latch_now_ = false;
  return out;
}

}  // namespace omnitwin::drive
