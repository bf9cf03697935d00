// bus_emulators/drive — one CiA 402 servo axis (see cia402_drive.hpp).
#include "bus_emulators/drive/cia402_drive.hpp"

#include <algorithm>
#include <cmath>

namespace omnitwin::drive {

namespace {
constexpr double kTwoPi = 6.283185307179586;

std::int32_t wrap32(double v) {
  const auto i = static_cast<std::int64_t>(std::llround(v));
  return static_cast<std::int32_t>(static_cast<std::uint32_t>(static_cast<std::uint64_t>(i)));
}
std::int16_t sat16(double v) {
  return static_cast<std::int16_t>(std::clamp(std::lround(v), -32768L, 32767L));
}
bool known_mode(int m) {
  return m == 1 || m == 3 || m == 4 || m == 6 || m == 8 || m == 9 || m == 10;
}
// Deceleration for a stop option: 1/5 profile, 2/6 quick stop, 3/4/7/8 current limit (0 = at
// the torque limit, realised by a zero velocity set-point).
double stop_decel(int option, const Objects& o) {
  switch (option) {
    case 1:
    case 5: return o.profile_deceleration;
    case 2:
    case 6: return o.quick_stop_deceleration;
    default: return 0;
  }
}
}  // namespace

const char* to_string(Mode m) {
  switch (m) {
    case Mode::none: return "none";
    case Mode::pp: return "pp";
    case Mode::pv: return "pv";
    case Mode::tq: return "tq";
    case Mode::hm: return "hm";
    case Mode::csp: return "csp";
    case Mode::csv: return "csv";
    case Mode::cst: return "cst";
  }
  return "?";
}

Cia402Drive::Cia402Drive(const DriveConfig& config) : cfg_(config) { power_cycle(); }

void Cia402Drive::power_cycle() {
  obj_ = Objects{};
  k_pos_ = cfg_.counts_per_rev * cfg_.gear_ratio / kTwoPi;
  obj_.max_motor_speed = static_cast<std::uint32_t>(
      std::clamp(cfg_.max_speed_rad_s * cfg_.counts_per_rev / kTwoPi, 0.0, 4.0e9));
  obj_.supported_modes = cfg_.supported_modes;
  fsa_.reset();
  active_mode_ = Mode::none;
  offset_ = 0;
  pv_vel_ = tq_demand_ = vel_integral_ = 0;
  fe_time_ = pos_window_time_ = vel_window_time_ = 0;
  fe_exceeded_ = internal_limit_ = warning_ = false;
  stop_done_ = stop_hold_ = false;
  hm_prev_start_ = homed_ = false;
  demand_pos_valid_ = false;
  first_step_ = true;
  pending_fault_ = 0;
  physical_outputs_ = cfg_.brake ? 1u : 0u;
  csp_first_ = true;
}

void Cia402Drive::enter_mode(Mode m, double pos, double vel) {
  const double sp = (obj_.polarity & 0x80) ? -1.0 : 1.0;
  pp_.reset(sp * pos + offset_);
  hold_.reset(pos);
  homing_.reset(pos);
  pv_vel_ = vel;
  tq_demand_ = 0;
  csp_first_ = true;
  hm_prev_start_ = (obj_.controlword & cw::start_homing) != 0;
  pos_window_time_ = vel_window_time_ = 0;
  (void)m;
}

// Longest gap between CSP set-points still interpolated over [s]; a longer one is a jump.
constexpr double kMaxCspInterval = 0.1;

Command Cia402Drive::step(SimTime t, const Feedback& fb) {
  double dt = cfg_.period_s;
  if (!first_step_ && t > last_t_) dt = static_cast<double>(t - last_t_) * 1e-9;
  last_t_ = t;
  const double pos = fb.position_rad * k_pos_;  // physical [counts]
  const double vel = fb.velocity_rad_s * k_pos_;
  const double sp = (obj_.polarity & 0x80) ? -1.0 : 1.0;
  const double sv = (obj_.polarity & 0x40) ? -1.0 : 1.0;
  const double cpr_rad = cfg_.counts_per_rev / kTwoPi;  // counts per motor rad
  const double torque_per_unit = cfg_.rated_torque_nm / 1000.0;  // motor Nm per 0.1 %
  const double max_t_nm = obj_.max_torque * torque_per_unit;
  if (first_step_) {
    prev_pos_ = pos;
    enter_mode(active_mode_, pos, 0);
  }

  // ---- Inputs: modelled switches (exact edges, a touch-probe latch) or scenario bits.
  const Switches& sw_cfg = cfg_.switches;
  const double x = fb.position_rad;
  const bool m_nl = sw_cfg.negative_limit && x <= *sw_cfg.negative_limit;
  const bool m_pl = sw_cfg.positive_limit && x >= *sw_cfg.positive_limit;
  bool m_home = false;
  if (sw_cfg.home) {
    if (sw_cfg.home_end) m_home = x >= *sw_cfg.home && x <= *sw_cfg.home_end;
    else if (sw_cfg.home_active_below) m_home = x <= *sw_cfg.home;
    else m_home = x >= *sw_cfg.home;
  }
  const bool nl = m_nl || (external_inputs_ & 1u);
  const bool pl = m_pl || (external_inputs_ & 2u);
  const bool home = m_home || (external_inputs_ & 4u);
  if (!first_step_) {
    if (nl != prev_nl_) nl_edge_ = (m_nl != prev_m_nl_) ? *sw_cfg.negative_limit * k_pos_ : pos;
    if (pl != prev_pl_) pl_edge_ = (m_pl != prev_m_pl_) ? *sw_cfg.positive_limit * k_pos_ : pos;
    if (home != prev_home_) {
      if (m_home != prev_m_home_) {
        // The threshold crossed between the last and this position.
        double e = *sw_cfg.home;
        if (sw_cfg.home_end) {
          const double lo = std::min(prev_pos_, pos) / k_pos_, hi = std::max(prev_pos_, pos) / k_pos_;
          const bool in_a = e >= lo && e <= hi;
          const bool in_b = *sw_cfg.home_end >= lo && *sw_cfg.home_end <= hi;
          if (in_b && !in_a) e = *sw_cfg.home_end;
          else if (!in_a && !in_b &&
                   std::fabs(*sw_cfg.home_end - x) < std::fabs(*sw_cfg.home - x))
            e = *sw_cfg.home_end;
        }
        home_edge_ = e * k_pos_;
      } else {
        home_edge_ = pos;
      }
    }
  }
  prev_nl_ = nl; prev_pl_ = pl; prev_home_ = home;
  prev_m_nl_ = m_nl; prev_m_pl_ = m_pl; prev_m_home_ = m_home;
  obj_.digital_inputs = (external_inputs_ & ~7u) | (nl ? 1u : 0u) | (pl ? 2u : 0u) | (home ? 4u : 0u);

  // ---- Power drive state machine.
  FsaEvents ev;
  ev.fault = pending_fault_ != 0;
  ev.stop_finished = stop_done_;
  const State before = fsa_.state();
  fsa_.step(obj_.controlword, ev, obj_.quick_stop_option, obj_.fault_reaction_option);
  const State st = fsa_.state();
  int nt = 0;
  const std::uint8_t* tr = fsa_.last_transitions(nt);
  for (int i = 0; i < nt; ++i) {
    if (tr[i] == 13) obj_.error_code = pending_fault_;
    if (tr[i] == 15) obj_.error_code = 0;
  }
  if (ev.fault) pending_fault_ = 0;
  if (st != before && (st == State::quick_stop_active || st == State::fault_reaction_active)) {
    hold_.reset(demand_pos_valid_ ? demand_pos_ : pos, vel);
    stop_done_ = false;
  }
  if (st == State::operation_enabled && before != State::operation_enabled) {
    enter_mode(active_mode_, pos, 0);
    vel_integral_ = 0;
  }
  stop_done_ = false;

  // ---- Mode selection (0x6060 → 0x6061 only for supported modes).
  const int req = obj_.mode;
  if (req != static_cast<int>(active_mode_) && known_mode(req) &&
      (obj_.supported_modes & mode_bit(static_cast<Mode>(req)))) {
    active_mode_ = static_cast<Mode>(req);
    enter_mode(active_mode_, pos, vel);
  }
  obj_.mode_display = static_cast<std::int8_t>(active_mode_);

  // ---- Software position limits in the physical frame.
  const bool limits_on = obj_.sw_limit_min != 0 || obj_.sw_limit_max != 0;
  // A min above the max is taken as the range between them, as the physical limits below take
  // it (a controller warns and swaps them; found by fuzzing: std::clamp with its bounds the
  // wrong way round is undefined).
  const double user_lo = std::min<double>(obj_.sw_limit_min, obj_.sw_limit_max);
  const double user_hi = std::max<double>(obj_.sw_limit_min, obj_.sw_limit_max);
  double lim_lo = 0, lim_hi = 0;
  if (limits_on) {
    const double a = sp * (obj_.sw_limit_min - offset_), b = sp * (obj_.sw_limit_max - offset_);
    lim_lo = std::min(a, b);
    lim_hi = std::max(a, b);
  }
  internal_limit_ = false;
  auto limit_velocity = [&](double v) {
    if (!limits_on) return v;
    const double dec = std::max<double>(obj_.quick_stop_deceleration, 1.0);
    if (v > 0) {
      // Braking curve to the limit; beyond it, back in at the position gain.
      const double room = lim_hi - pos;
      const double vmax = room > 0 ? std::sqrt(2.0 * dec * room) : cfg_.pos_kp * room;
      if (v >= vmax) { internal_limit_ = true; return vmax; }
    } else if (v < 0) {
      const double room = pos - lim_lo;
      const double vmax = room > 0 ? std::sqrt(2.0 * dec * room) : cfg_.pos_kp * room;
      if (-v >= vmax) { internal_limit_ = true; return -vmax; }
    }
    return v;
  };

  // ---- The active mode / stop.
  const std::uint16_t c = obj_.controlword;
  const bool halt = (c & cw::halt) != 0;
  double cmd_vel = 0;          // physical [counts/s]
  double cmd_torque_user = 0;  // [0.1 %]
  bool torque_mode = false;
  position_controlled_ = false;
  double dpos = pos, dvel = 0;
  bool target_reached = false, bit12 = false, bit13 = false;
  const double halt_dec = obj_.halt_option == 1 ? obj_.profile_deceleration
                                                : static_cast<double>(obj_.quick_stop_deceleration);
  const double user_pos = sp * pos + offset_;

  if (st == State::operation_enabled) {
    switch (active_mode_) {
      case Mode::pp: {
        PpInput in;
        in.controlword = c;
        in.target = obj_.target_position;
        in.vmax = std::min(obj_.profile_velocity, obj_.max_profile_velocity);
        in.acc = obj_.profile_acceleration;
        in.dec = obj_.profile_deceleration;
        in.halt_dec = halt_dec;
        in.limits = limits_on;
        in.min_pos = user_lo;
        in.max_pos = user_hi;
        const PpOutput o = pp_.step(in, dt);
        dpos = sp * (o.demand_pos - offset_);
        dvel = sp * o.demand_vel;
        position_controlled_ = true;
        internal_limit_ = o.limited;
        bool in_window = std::fabs(pp_.current_target() - user_pos) <= obj_.position_window;
        if (o.at_target && in_window) pos_window_time_ += dt;
        else pos_window_time_ = 0;
        target_reached = (o.at_target && in_window &&
                          pos_window_time_ * 1000.0 + 1e-9 >= obj_.position_window_time) ||
                         (halt && o.halted);
        bit12 = o.set_point_ack;
        bit13 = fe_exceeded_;
        break;
      }
      case Mode::pv: {
        double target = halt ? 0.0 : sv * static_cast<double>(obj_.target_velocity);
        const double acc = obj_.profile_acceleration;
        const double dec = halt ? halt_dec : obj_.profile_deceleration;
        pv_vel_ = ramp_velocity(pv_vel_, target, acc, dec, dt);
        cmd_vel = limit_velocity(pv_vel_);
        pv_vel_ = cmd_vel;
        dvel = cmd_vel;
        const double user_target = halt ? 0.0 : obj_.target_velocity;
        const bool in_window = std::fabs(user_target - sv * vel) <= obj_.velocity_window;
        if (in_window) vel_window_time_ += dt;
        else vel_window_time_ = 0;
        target_reached =
            in_window && vel_window_time_ * 1000.0 + 1e-9 >= obj_.velocity_window_time;
        bit12 = std::fabs(vel) <= obj_.velocity_threshold;
        break;
      }
      case Mode::tq:
      case Mode::cst: {
        double target = obj_.target_torque;
        if (active_mode_ == Mode::tq) {
          if (halt) target = 0;
          tq_demand_ = ramp_torque(tq_demand_, target, obj_.torque_slope, dt);
          target_reached = tq_demand_ == target;
        } else {
          tq_demand_ = target + obj_.torque_offset;
          bit12 = true;  // CST: the drive follows the command value
        }
        cmd_torque_user = tq_demand_;
        // Software limits: no torque pushing further out.
        const double phys = sv * cmd_torque_user;
        if (limits_on && ((pos >= lim_hi && phys > 0) || (pos <= lim_lo && phys < 0))) {
          cmd_torque_user = 0;
          internal_limit_ = true;
        }
        torque_mode = true;
        break;
      }
      case Mode::hm: {
        HomingParams hp;
        hp.method = obj_.homing_method;
        hp.v_switch = obj_.homing_speed_switch;
        hp.v_zero = obj_.homing_speed_zero;
        hp.acc = obj_.homing_acceleration;
        hp.counts_per_rev = cfg_.counts_per_rev;
        hp.index_offset = cfg_.index_offset_rad / kTwoPi * cfg_.counts_per_rev;
        hp.max_search = cfg_.homing_max_search_rev * cfg_.counts_per_rev;
        hp.stop_dec = obj_.quick_stop_deceleration;
        HomingSignals hs;
        hs.pos = pos;
        hs.nl = nl;
        hs.pl = pl;
        hs.home = home;
        hs.nl_edge = nl_edge_;
        hs.pl_edge = pl_edge_;
        hs.home_edge = home_edge_;
        const bool start = (c & cw::start_homing) != 0;
        // Seed 004: the master clears bit 4 once the drive answered, so only the rising edge
        // matters (a falling edge does not interrupt); halt interrupts.
        if (start && !hm_prev_start_ && !halt) {
          homing_.start(hp, hs, demand_pos_valid_ ? demand_pos_ : pos, 0);
          homed_ = false;
        }
        hm_prev_start_ = start;
        const HomingOutput o = homing_.step(hp, hs, halt, dt);
        if (o.latched) offset_ = obj_.home_offset - sp * o.home_pos;
        if (o.attained) homed_ = true;
        dpos = o.demand_pos;
        dvel = o.demand_vel;
        position_controlled_ = true;
        target_reached = !o.active;
        bit12 = o.attained;
        bit13 = o.error;
        break;
      }
      case Mode::csp: {
        double target = obj_.target_position;
        if (limits_on) {
          const double cl = std::clamp(target, user_lo, user_hi);
          internal_limit_ = cl != target;
          target = cl;
        }
        const double phys = sp * (target - offset_);
        // Set-points come once per bus cycle, which may be several drive periods: the drive
        // interpolates linearly from the previous set-point to the new one over the interval
        // the set-points arrive at (one bus cycle of delay, as interpolating drives have),
        // with that slope as velocity feed-forward.
        if (csp_first_) {
          csp_from_ = csp_prev_target_ = phys;
          csp_change_t_ = t;
          csp_interval_ = dt;
          csp_first_ = false;
        } else if (phys != csp_prev_target_) {
          const double since = static_cast<double>(t - csp_change_t_) * 1e-9;
          csp_interval_ = std::clamp(since, dt, kMaxCspInterval);
          csp_from_ = csp_demand_;
          csp_prev_target_ = phys;
          csp_change_t_ = t;
        }
        // This period moves the demand from `done` to `along` of the way (a set-point arriving
        // every period is reached in that period, as without interpolation).
        const double done = static_cast<double>(t - csp_change_t_) * 1e-9 / csp_interval_;
        const double along = std::min(1.0, done + dt / csp_interval_);
        csp_demand_ = csp_from_ + (csp_prev_target_ - csp_from_) * along;
        const double ff = done < 1.0 ? (csp_prev_target_ - csp_from_) / csp_interval_ : 0.0;
        dpos = csp_demand_;
        dvel = ff + sv * obj_.velocity_offset;
        position_controlled_ = true;
        bit12 = true;  // the drive follows the command value
        bit13 = fe_exceeded_;
        break;
      }
      case Mode::csv: {
        cmd_vel = limit_velocity(sv * (static_cast<double>(obj_.target_velocity) + obj_.velocity_offset));
        dvel = cmd_vel;
        bit12 = true;
        break;
      }
      case Mode::none:
        dpos = hold_.pos;
        position_controlled_ = true;
        break;
    }
  } else if (st == State::quick_stop_active || st == State::fault_reaction_active) {
    const int option = st == State::quick_stop_active ? obj_.quick_stop_option
                                                      : obj_.fault_reaction_option;
    const double dec = stop_decel(option, obj_);
    if (dec > 0) {
      stop_done_ = hold_.stop(dec, dt);
      dpos = hold_.pos;
      dvel = hold_.vel;
      position_controlled_ = true;
    } else if (!stop_hold_) {
      // Current (voltage) limit: zero velocity at the torque limit, then hold.
      cmd_vel = 0;
      if (std::fabs(vel) <= std::max<double>(obj_.velocity_threshold, 1.0)) {
        stop_hold_ = true;
        hold_.reset(pos);
      }
      stop_done_ = stop_hold_;
    } else {
      dpos = hold_.pos;
      position_controlled_ = true;
      stop_done_ = true;
    }
    target_reached = stop_done_;
  }
  if (st != State::quick_stop_active && st != State::fault_reaction_active) stop_hold_ = false;
  if (!power_stage_on(st)) {
    hold_.reset(pos);
    vel_integral_ = 0;
  }

  // ---- Loops: position (P + feed-forward) → velocity (PI) → torque limit.
  if (position_controlled_) {
    cmd_vel = dvel + cfg_.pos_kp * (dpos - pos);
    if (active_mode_ == Mode::hm || st != State::operation_enabled) {
      // homing and stops run on the physical axis: no software limits
    } else if (limits_on && active_mode_ != Mode::pp && active_mode_ != Mode::csp) {
      cmd_vel = limit_velocity(cmd_vel);
    }
  }
  const double vmax = obj_.max_motor_speed;
  cmd_vel = std::clamp(cmd_vel, -vmax, vmax);
  double torque_nm = 0;  // motor, physical
  if (power_stage_on(st)) {
    if (torque_mode) {
      torque_nm = std::clamp(sv * cmd_torque_user * torque_per_unit, -max_t_nm, max_t_nm);
    } else {
      const double err = (cmd_vel - vel) / cpr_rad;  // motor rad/s
      vel_integral_ = std::clamp(vel_integral_ + cfg_.vel_ki * err * dt, -max_t_nm, max_t_nm);
      torque_nm = std::clamp(cfg_.vel_kp * err + vel_integral_, -max_t_nm, max_t_nm);
    }
  } else {
    cmd_vel = 0;
  }
  const bool saturated = max_t_nm > 0 && std::fabs(torque_nm) >= max_t_nm * 0.999 && !torque_mode;

  // ---- Following error (position-controlled modes in operation enabled).
  double fe_user = 0;
  if (position_controlled_ && st == State::operation_enabled) {
    fe_user = sp * (dpos - pos);
    if (obj_.following_error_window != 0xFFFFFFFFu && std::fabs(fe_user) > obj_.following_error_window) {
      fe_time_ += dt;
      if (fe_time_ * 1000.0 > obj_.following_error_timeout + 1e-9) {
        fe_exceeded_ = true;
        if (!pending_fault_) pending_fault_ = kErrorFollowing;
      }
    } else {
      fe_time_ = 0;
      fe_exceeded_ = false;
    }
  } else {
    fe_time_ = 0;
  }
  if (st == State::fault) fe_exceeded_ = false;
  warning_ = fe_time_ > 0 || saturated;

  // ---- Outputs, brake.
  const bool auto_brake = cfg_.brake && !power_stage_on(st);
  const std::uint32_t mask = obj_.digital_outputs_mask;
  physical_outputs_ = ((auto_brake ? 1u : 0u) & ~mask) | (obj_.digital_outputs & mask);
  Command out;
  out.power = power_stage_on(st);
  out.brake_engaged = cfg_.brake && (physical_outputs_ & 1u);
  out.torque_mode = torque_mode && out.power;
  out.velocity_rad_s = out.power && !torque_mode ? cmd_vel / k_pos_ : 0.0;
  out.torque_nm = out.power ? torque_nm * cfg_.gear_ratio : 0.0;
  out.torque_limit_nm = max_t_nm * cfg_.gear_ratio;

  // ---- Actual values and statusword.
  demand_pos_ = position_controlled_ ? dpos : pos;
  demand_pos_valid_ = position_controlled_;
  obj_.position_actual = wrap32(sp * pos + offset_);
  obj_.position_demand = wrap32(sp * demand_pos_ + offset_);
  obj_.velocity_actual = wrap32(sv * vel);
  obj_.velocity_demand = wrap32(sv * cmd_vel);
  obj_.following_error_actual = wrap32(fe_user);
  obj_.torque_demand = sat16(sv * torque_nm / torque_per_unit);
  obj_.torque_actual =
      sat16(sv * fb.torque_nm / std::max(cfg_.gear_ratio, 1e-12) / torque_per_unit);
  std::uint16_t word = state_bits(st) | sw::remote;
  if (warning_) word |= sw::warning;
  if (internal_limit_ && st == State::operation_enabled) word |= sw::internal_limit;
  if (st == State::operation_enabled || st == State::quick_stop_active) {
    if (target_reached) word |= sw::target_reached;
    if (st == State::operation_enabled) {
      if (bit12) word |= 1u << 12;
      if (bit13) word |= 1u << 13;
    }
  }
  obj_.statusword = word;
  prev_pos_ = pos;
  first_step_ = false;
  return out;
}

std::uint8_t error_class_bit(std::uint16_t code) {
  switch (code >> 12) {
    case 0x2: return 0x02;
    case 0x3: return 0x04;
    case 0x4: return 0x08;
    case 0x8: return (code & 0xFF00) == 0x8600 || (code & 0xFF00) == 0x8500 ? 0x20 : 0x10;
    case 0xF: return (code & 0xFF00) == 0xFF00 ? 0x80 : 0;
    default: return 0;
  }
}

bool quick_stop_option_supported(int code) noexcept { return code >= 0 && code <= 8; }
bool halt_option_supported(int code) noexcept { return code == 1 || code == 2; }
bool fault_reaction_option_supported(int code) noexcept { return code >= 0 && code <= 4; }

}  // namespace omnitwin::drive
