// bus_emulators/mechatrolink3 — the standard servo profile on the drive core; see m3_servo.hpp.
#include "bus_emulators/mechatrolink3/m3_servo.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "bus_emulators/drive/cia402_profile.hpp"

namespace omnitwin::m3 {

using namespace servo;  // the field layout (m3_servo_format.hpp)

namespace {

using drive::State;

bool faulted(State s) { return s == State::fault || s == State::fault_reaction_active; }

// The commands CMD_PAUSE and CMD_CANCEL act on (the profile: those that move by a profile of
// their own); the others ignore both bits.
bool stoppable(Command c) {
  return c == Command::posing || c == Command::feed || c == Command::ex_posing || c == Command::zret ||
         c == Command::velctrl;
}

}  // namespace

std::uint16_t servo_alarm_code(std::uint16_t drive_error) noexcept {
  return drive_error == drive::kErrorFollowing ? 0x0D00 : 0x0F00;
}

ServoProfile::ServoProfile(const ServoConfig& config)
    : cfg_(config), drive_(config.drive), max_torque_(drive_.objects().max_torque) {}

bool ServoProfile::servo_on() const { return drive_.state() == State::operation_enabled; }
bool ServoProfile::device_alarm() const { return faulted(drive_.state()); }
// CMDRDY is 0 while the drive is on its way to the state SV_ON or SV_OFF asked for.
bool ServoProfile::ready() const { return want_on_ == servo_on() || device_alarm(); }

void ServoProfile::stop(SimTime) {
  want_on_ = false;
  motion_ = Motion::none;
  vel_ramp_ = 0;
}

void ServoProfile::disconnect(SimTime t) {
  stop(t);
  sensor_on_ = paused_ = cancelled_ = new_set_point_ = latched_ = false;
  user_offset_ = target_ = latch_pos_ = tpos_requested_ = 0;
  home_lost_ = drive_.homed();
}

void ServoProfile::power_cycle() {
  drive_.power_cycle();
  want_on_ = sensor_on_ = paused_ = cancelled_ = fault_reset_ = new_set_point_ = false;
  motion_ = Motion::none;
  vel_ramp_ = 0;
  max_torque_ = drive_.objects().max_torque;
  motion_mode_ = 0;  // no motion command has run since this power-on
  user_offset_ = target_ = 0;
  last_error_ = 0;
  home_lost_ = false;
}

CmdAlarm ServoProfile::execute(Command c, std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp, SimTime) {
  if (common_format(c)) return run(c, cmd, rsp);  // bytes 4… are the command's own fields
  const std::uint32_t ctrl = get_u32(cmd, kSvcmdCtrl);
  paused_ = stoppable(c) && (ctrl & kCmdPause) != 0;
  cancelled_ = stoppable(c) && (ctrl & kCmdCancel) != 0;
  // CMD_CANCEL: the command is not taken; the motion in progress decelerates to a stop and
  // ends there (step()). Otherwise the command runs.
  const CmdAlarm a = cancelled_ ? (servo_on() ? CmdAlarm::normal : CmdAlarm::condition_error) : run(c, cmd, rsp);
  fill_status(cmd, rsp);
  // SVPRM_RD/WR use bytes 12… for their own fields; every other servo command carries monitors.
  if (c != Command::svprm_rd && c != Command::svprm_wr) fill_monitors(cmd, rsp);
  return a;
}

CmdAlarm ServoProfile::run(Command c, std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp) {
  switch (c) {
    case Command::smon: return CmdAlarm::normal;
    case Command::sens_on: sensor_on_ = true; return CmdAlarm::normal;
    case Command::sens_off:
      if (want_on_) return CmdAlarm::condition_error;
      sensor_on_ = false;
      return CmdAlarm::normal;
    case Command::sv_on:
      if (!sensor_on_ || device_alarm()) return CmdAlarm::condition_error;
      want_on_ = true;
      return CmdAlarm::normal;
    case Command::sv_off: stop(0); return CmdAlarm::normal;
    case Command::brk_on:
    case Command::brk_off: {
      if (want_on_) return CmdAlarm::condition_error;
      auto& o = drive_.objects();
      o.digital_outputs_mask |= 1u;
      o.digital_outputs = c == Command::brk_on ? (o.digital_outputs | 1u) : (o.digital_outputs & ~1u);
      return CmdAlarm::normal;
    }
    case Command::pos_set:
      if (!sensor_on_) return CmdAlarm::condition_error;
      user_offset_ = get_i32(cmd, kPosSetData) - drive_.objects().position_actual;
      return CmdAlarm::normal;
    case Command::velctrl:
    case Command::interpolate:
    case Command::trqctrl: return motion(c, cmd);
    case Command::posing: return posing(cmd, false);
    case Command::feed: return posing(cmd, true);
    case Command::svprm_rd:
    case Command::svprm_wr: return parameter(c, cmd, rsp, kPrmNo);
    case Command::alm_rd: return alarm_read(cmd, rsp, kAlmMode, kAlmData, kAlmCodesMain);
    case Command::alm_clr:
      put_u16(rsp, kAlmMode, get_u16(cmd, kAlmMode));
      if (get_u16(cmd, kAlmMode) > 1) return CmdAlarm::invalid_data;
      if (get_u16(cmd, kAlmMode) == 1) history_.fill(0);
      clear_alarms();
      return CmdAlarm::normal;
    case Command::id_rd: return id_read(cmd, rsp);
    case Command::zret: return zero_return(cmd);
    case Command::ex_posing: {
      // The same EX_POSING repeated every cycle goes on; a new one (another TPOS) starts over.
      const bool again = motion_ == Motion::ex_posing && (latched_ || get_i32(cmd, kPosTpos) == tpos_requested_);
      if (again) return servo_on() ? CmdAlarm::normal : CmdAlarm::condition_error;
      const CmdAlarm a = posing(cmd, false);
      if (a != CmdAlarm::normal) return a;
      motion_ = Motion::ex_posing;
      tpos_requested_ = get_i32(cmd, kPosTpos);
      latched_ = false;
      prev_dec_ = (drive_.objects().digital_inputs & 4u) != 0;  // an input already high is no edge
      return a;
    }
    case Command::config: return CmdAlarm::normal;  // parameters take effect when written
    default: return CmdAlarm::unsupported;  // MEM_RD/WR: no virtual memory modelled
  }
}

// A command's torque limit TLIM [0.1 %] over the parameter's (0101h): 0 leaves the
// parameter's, a larger one is capped at it.
void ServoProfile::apply_tlim(std::span<const std::uint8_t> cmd, std::size_t at) {
  const std::uint32_t tlim = get_u32(cmd, at);
  drive_.objects().max_torque =
      static_cast<std::uint16_t>(tlim == 0 ? max_torque_ : std::min<std::uint32_t>(tlim, max_torque_));
}

// VELCTRL, INTERPOLATE, TRQCTRL: cyclic set-points into the drive core's CSV, CSP, CST.
CmdAlarm ServoProfile::motion(Command c, std::span<const std::uint8_t> cmd) {
  if (!servo_on()) return CmdAlarm::condition_error;
  auto& o = drive_.objects();
  if (c == Command::velctrl) {
    const std::uint32_t acc = get_u32(cmd, kVelAccr), dec = get_u32(cmd, kVelDecr);
    if (acc > 0x7FFFFFFF || dec > 0x7FFFFFFF) return CmdAlarm::invalid_data;
    if (motion_ != Motion::velctrl) vel_ramp_ = o.velocity_actual;  // the ramp starts where the axis turns
    vref_ = get_i32(cmd, kVelVref);
    vel_acc_ = acc, vel_dec_ = dec;
    apply_tlim(cmd, kVelTlim);
    motion_ = Motion::velctrl;
  } else if (c == Command::interpolate) {
    target_ = get_i32(cmd, kIpTpos);
    o.target_position = target_ - user_offset_;
    o.velocity_offset = get_i32(cmd, kIpVff);
    apply_tlim(cmd, kIpTlim);
    motion_ = Motion::interpolate;
  } else {
    const std::int32_t tq = get_i32(cmd, kTrqTqref);
    if (std::abs(tq) > 32767) return CmdAlarm::invalid_data;
    o.target_torque = static_cast<std::int16_t>(tq);
    motion_ = Motion::trqctrl;
  }
  return CmdAlarm::normal;
}

// POSING and EX_POSING (to TPOS) and FEED (at TSPD, no end) through the drive core's PP and PV.
CmdAlarm ServoProfile::posing(std::span<const std::uint8_t> cmd, bool feed) {
  if (!servo_on()) return CmdAlarm::condition_error;
  auto& o = drive_.objects();
  const std::int32_t speed = get_i32(cmd, feed ? kFeedTspd : kPosTspd);
  const std::uint32_t acc = get_u32(cmd, feed ? kFeedAccr : kPosAccr), dec = get_u32(cmd, feed ? kFeedDecr : kPosDecr);
  if (acc > 0x7FFFFFFF || dec > 0x7FFFFFFF) return CmdAlarm::invalid_data;
  if (acc != 0) o.profile_acceleration = acc;
  if (dec != 0) o.profile_deceleration = dec;
  apply_tlim(cmd, feed ? kFeedTlim : kPosTlim);
  if (feed) {
    o.target_velocity = speed;
    motion_ = Motion::feed;
    return CmdAlarm::normal;
  }
  if (speed <= 0) return CmdAlarm::invalid_data;
  o.profile_velocity = static_cast<std::uint32_t>(speed);
  const std::int32_t tpos = get_i32(cmd, kPosTpos);
  new_set_point_ = motion_ != Motion::posing || tpos != target_;
  target_ = tpos;
  o.target_position = tpos - user_offset_;
  motion_ = Motion::posing;
  return CmdAlarm::normal;
}

// ZRET: the drive core's homing (HM), started by controlword bit 4 once the drive is in HM.
CmdAlarm ServoProfile::zero_return(std::span<const std::uint8_t> cmd) {
  if (!servo_on()) return CmdAlarm::condition_error;
  auto& o = drive_.objects();
  const auto method = static_cast<std::int8_t>(cmd[kZretMode]);
  const std::int32_t speed = get_i32(cmd, kZretTspd);
  const std::uint32_t acc = get_u32(cmd, kZretAccr);
  if (speed < 0 || acc > 0x7FFFFFFF) return CmdAlarm::invalid_data;
  if (method != 0) o.homing_method = method;
  if (speed > 0) {
    o.homing_speed_switch = static_cast<std::uint32_t>(speed);
    o.homing_speed_zero = std::max<std::uint32_t>(1, static_cast<std::uint32_t>(speed) / 10);
  }
  if (acc != 0) o.homing_acceleration = acc;
  apply_tlim(cmd, kZretTlim);
  if (motion_ != Motion::zret) {
    user_offset_ = 0;  // the home position becomes the origin
    target_ = 0;
  }
  motion_ = Motion::zret;
  return CmdAlarm::normal;
}

// SVPRM_RD/WR with NO at `at`, SIZE at+2, MODE at+3, PARAMETER at+4 (main command: 12;
// subcommand region: 4).
CmdAlarm ServoProfile::parameter(Command c, std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp,
                                 std::size_t at) {
  std::copy_n(cmd.begin() + static_cast<std::ptrdiff_t>(at), 4, rsp.begin() + static_cast<std::ptrdiff_t>(at));
  if (cmd[at + 2] != 4) return CmdAlarm::invalid_data;
  auto& o = drive_.objects();
  const auto value = get_u32(cmd, at + 4);
  std::uint32_t* field = nullptr;
  switch (static_cast<ServoParam>(get_u16(cmd, at))) {
    case ServoParam::following_error_window: field = &o.following_error_window; break;
    case ServoParam::acceleration: field = &o.profile_acceleration; break;
    case ServoParam::deceleration: field = &o.profile_deceleration; break;
    case ServoParam::quick_stop_deceleration: field = &o.quick_stop_deceleration; break;
    case ServoParam::max_velocity: field = &o.max_profile_velocity; break;
    case ServoParam::position_window: field = &o.position_window; break;
    case ServoParam::ex_posing_distance:
      if (c == Command::svprm_wr) ex_distance_ = static_cast<std::int32_t>(value);
      put_i32(rsp, at + 4, ex_distance_);
      return CmdAlarm::normal;
    case ServoParam::max_torque:
      if (c == Command::svprm_wr) {
        if (value > 65535) return CmdAlarm::invalid_data;
        max_torque_ = static_cast<std::uint16_t>(value);
        o.max_torque = max_torque_;
      }
      put_u32(rsp, at + 4, max_torque_);
      return CmdAlarm::normal;
    case ServoParam::cprm_sel_mon1:
    case ServoParam::cprm_sel_mon2: {
      std::uint8_t& sel = cprm_sel_mon_[get_u16(cmd, at) == static_cast<std::uint16_t>(ServoParam::cprm_sel_mon1) ? 0 : 1];
      if (c == Command::svprm_wr) {
        if (value > 0xF) return CmdAlarm::invalid_data;
        sel = static_cast<std::uint8_t>(value);
      }
      put_u32(rsp, at + 4, sel);
      return CmdAlarm::normal;
    }
    case ServoParam::counts_per_rev:
      if (c == Command::svprm_wr) return CmdAlarm::invalid_data;  // read only
      put_u32(rsp, at + 4, static_cast<std::uint32_t>(std::lround(cfg_.drive.counts_per_rev)));
      return CmdAlarm::normal;
    default: return CmdAlarm::invalid_data;
  }
  if (c == Command::svprm_wr) *field = value;
  put_u32(rsp, at + 4, *field);
  return CmdAlarm::normal;
}

// ALM_RD with ALM_RD_MOD (u16) at `at` and `count` codes (u16) from `codes` on (main command,
// common format: 4, 8, 12; subcommand region: 4, 8, 4). Mode 0: the alarm now (one code, 0
// for none); 1: the history, newest first.
CmdAlarm ServoProfile::alarm_read(std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp, std::size_t at,
                                  std::size_t codes, std::size_t count) const {
  const std::uint16_t mode = get_u16(cmd, at);
  put_u16(rsp, at, mode);
  if (mode > 1) return CmdAlarm::invalid_data;
  if (mode == 1) {
    for (std::size_t i = 0; i < std::min(count, history_.size()); ++i) put_u16(rsp, codes + 2 * i, history_[i]);
  } else if (device_alarm()) {
    put_u16(rsp, codes, servo_alarm_code(drive_.objects().error_code));
  }
  return CmdAlarm::normal;
}

void ServoProfile::clear_alarms() { fault_reset_ = device_alarm(); }

CmdAlarm ServoProfile::execute_sub(Command c, std::span<const std::uint8_t> sub, std::span<std::uint8_t> rsp) {
  const std::uint32_t ctrl = static_cast<std::uint32_t>(sub[1] | (sub[2] << 8) | (sub[3] << 16));
  switch (c) {
    case Command::smon:
      for (std::size_t i = 0; i < 3; ++i)
        put_i32(rsp, 4 + 4 * i, monitor(static_cast<std::uint8_t>((ctrl >> (12 + 4 * i)) & 0xF)));
      return CmdAlarm::normal;
    case Command::svprm_rd:
    case Command::svprm_wr: return parameter(c, sub, rsp, 4);
    case Command::alm_rd: return alarm_read(sub, rsp, 4, 8, 4);
    case Command::alm_clr:
      if (get_u16(sub, 4) > 1) return CmdAlarm::invalid_data;
      if (get_u16(sub, 4) == 1) history_.fill(0);
      clear_alarms();
      return CmdAlarm::normal;
    default: return CmdAlarm::unsupported;  // MEM_RD, MEM_WR: no virtual memory modelled
  }
}

// ID_RD (common format): ID_CODE 0 (ours: the device name), OFFSET, SIZE → the ID from byte 8.
CmdAlarm ServoProfile::id_read(std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp) const {
  std::copy_n(cmd.begin() + kIdCode, 4, rsp.begin() + kIdCode);
  const std::size_t offset = cmd[kIdOffset], size = get_u16(cmd, kIdSize);
  const std::size_t room = rsp.size() - kIdData;
  if (cmd[kIdCode] != 0 || size > room || offset >= 32) return CmdAlarm::invalid_data;
  for (std::size_t i = 0; i < size; ++i) {
    const std::size_t at = offset + i;
    rsp[kIdData + i] = at < cfg_.id.size() ? static_cast<std::uint8_t>(cfg_.id[at]) : 0;
  }
  return CmdAlarm::normal;
}

std::int32_t ServoProfile::monitor(std::uint8_t sel) const {
  const auto& o = drive_.objects();
  switch (sel) {
    case 0x0: return o.position_actual + user_offset_;   // APOS
    case 0x1: return o.position_demand + user_offset_;   // CPOS
    case 0x2: return o.following_error_actual;           // PERR
    case 0x3: return latch_pos_;                         // LPOS1
    case 0x5: return o.velocity_actual;                  // FSPD
    case 0x6: return o.velocity_demand;                  // CSPD
    case 0x7: return o.torque_actual;                    // TRQ [0.1 %]
    case 0x8: return device_alarm() ? servo_alarm_code(o.error_code) : 0;  // ALARM
    case 0x9: return target_;                            // MPOS: the commanded target
    default: return 0;                                   // unused codes
  }
}

namespace {

// SEL_MON1/2/3 of SVCMD_CTRL.
std::array<std::uint8_t, 3> selected_monitors(std::uint32_t ctrl) {
  return {static_cast<std::uint8_t>((ctrl >> kSelMon1Shift) & 0xF), static_cast<std::uint8_t>((ctrl >> kSelMon2Shift) & 0xF),
          static_cast<std::uint8_t>((ctrl >> kSelMon3Shift) & 0xF)};
}

}  // namespace

// Whether the motion that CMD_PAUSE or CMD_CANCEL stops has come to a stop: the VELCTRL ramp
// at zero, or the drive core's statusword bit 10 (with halt: the axis stands still).
bool ServoProfile::stopped() const {
  if (motion_ == Motion::none) return true;
  if (motion_ == Motion::velctrl) return vel_ramp_ == 0;
  return (drive_.objects().statusword & (1u << 10)) != 0;
}

// SVCMD_STAT (bytes 4-7) and SVCMD_IO (8-11), in the response to every servo command (not the
// common commands, whose format has neither, nor NOP, SYNC_SET, CONNECT, DISCONNECT, which the
// link answers with CMD_STAT alone).
void ServoProfile::fill_status(std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp) const {
  const std::uint32_t ctrl = get_u32(cmd, kSvcmdCtrl);
  const std::array<std::uint8_t, 3> sel = selected_monitors(ctrl);
  // PAUSE_CMP / CANCEL_CMP: 1 once the pause or the cancel is complete (the axis stopped).
  std::uint32_t stat = kPon | kMRdy | (sensor_on_ ? kPosRdy : 0) | (servo_on() ? kSvOn : 0) | (latched_ ? kLCmp1 : 0);
  if (paused_ && stopped()) stat |= kPauseCmp;
  if (cancelled_ && stopped()) stat |= kCancelCmp;
  stat |= static_cast<std::uint32_t>(sel[0]) << kSelMon1Shift | static_cast<std::uint32_t>(sel[1]) << kSelMon2Shift |
          static_cast<std::uint32_t>(sel[2]) << kSelMon3Shift;
  put_u32(rsp, kSvcmdStat, stat);
  const auto& o = drive_.objects();
  // PSET: a positioning motion whose target the axis is within the position window of; DEN:
  // its profile has reached the target (the distribution is done).
  const std::int64_t apos = static_cast<std::int64_t>(o.position_actual) + user_offset_;
  const std::int64_t cpos = static_cast<std::int64_t>(o.position_demand) + user_offset_;
  const bool reached = std::abs(apos - target_) <= static_cast<std::int64_t>(o.position_window);
  std::uint32_t io = ((o.digital_inputs >> 2) & 1u ? kIoDec : 0) | ((o.digital_inputs >> 1) & 1u ? kIoPot : 0) |
                     (o.digital_inputs & 1u ? kIoNot : 0) | ((drive_.physical_outputs() & 1u) ? kIoBrkOn : 0);
  const bool positioning = motion_ == Motion::posing || motion_ == Motion::interpolate ||
                           (motion_ == Motion::ex_posing && latched_);
  if (reached && positioning) io |= kIoPset;
  if (positioning && cpos == target_) io |= kIoDen;
  if (drive_.homed() && !home_lost_ && std::abs(apos) <= static_cast<std::int64_t>(o.position_window))
    io |= kIoZpoint;
  if (std::abs(o.velocity_actual) <= static_cast<std::int32_t>(o.velocity_threshold)) io |= kIoZspd;
  put_u32(rsp, kSvcmdIoIn, io);
}

// CPRM_SEL_MON1/2 (bytes 12, 16: the monitors servo parameters 0111h/0112h select, ours) and
// MONITOR1/2/3 (bytes 20, 24, 28) as SEL_MON1/2/3 select.
void ServoProfile::fill_monitors(std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp) const {
  put_i32(rsp, kCprmMon1, monitor(cprm_sel_mon_[0]));
  put_i32(rsp, kCprmMon2, monitor(cprm_sel_mon_[1]));
  const std::array<std::uint8_t, 3> sel = selected_monitors(get_u32(cmd, kSvcmdCtrl));
  for (std::size_t i = 0; i < 3; ++i) put_i32(rsp, kMonitor1 + 4 * i, monitor(sel[i]));
}

// The controlword for this period: the FSA one step towards servo on or off, the mode of the
// motion, halt for CMD_PAUSE, bit 4 pulsed for a new POSING target.
std::uint16_t ServoProfile::controlword() {
  const State st = drive_.state();
  if (faulted(st)) {
    const bool reset = fault_reset_;
    fault_reset_ = false;
    return reset ? drive::cw::kFaultReset : drive::cw::kDisableVoltage;
  }
  if (!want_on_) return drive::cw::kShutdown;
  std::uint16_t cw = drive::cw::kShutdown;
  if (st == State::ready_to_switch_on) cw = drive::cw::kSwitchOn;
  if (st == State::switched_on || st == State::operation_enabled) cw = drive::cw::kEnableOperation;
  if (st == State::quick_stop_active) cw = drive::cw::kDisableVoltage;
  if (paused_ || cancelled_) cw |= drive::cw::halt;
  // ZRET: bit 4 rises once the drive is in HM and is held (homing is not restarted by it).
  if (motion_ == Motion::zret && st == State::operation_enabled &&
      drive_.mode() == drive::Mode::hm)
    cw |= drive::cw::start_homing;
  if (new_set_point_ && st == State::operation_enabled) {
    cw |= drive::cw::new_set_point | drive::cw::change_immediately;
    new_set_point_ = false;
  }
  return cw;
}

// EX_POSING: the first rising edge of the latch input (DEC) fixes LPOS1 and the final target.
void ServoProfile::watch_latch() {
  const auto& o = drive_.objects();
  const bool dec = (o.digital_inputs & 4u) != 0;
  if (motion_ == Motion::ex_posing && !latched_ && dec && !prev_dec_) {
    latched_ = true;
    latch_pos_ = o.position_actual + user_offset_;
    target_ = latch_pos_ + ex_distance_;
    drive_.objects().target_position = target_ - user_offset_;
    new_set_point_ = true;
  }
  prev_dec_ = dec;
}

void ServoProfile::note_alarm(std::uint16_t code) {
  if (code == 0 || code == last_error_) return;
  std::rotate(history_.rbegin(), history_.rbegin() + 1, history_.rend());
  history_[0] = servo_alarm_code(code);
  last_error_ = code;
}

drive::Command ServoProfile::step(SimTime t, const drive::Feedback& fb) {
  auto& o = drive_.objects();
  static constexpr drive::Mode kModes[] = {drive::Mode::csv, drive::Mode::csv, drive::Mode::csp, drive::Mode::pp,
                                           drive::Mode::pv,  drive::Mode::cst, drive::Mode::hm, drive::Mode::pp};
  const double dt = last_step_ >= 0 && t > last_step_ ? static_cast<double>(t - last_step_) * 1e-9 : cfg_.drive.period_s;
  last_step_ = t;
  // CMD_CANCEL: once the axis has stopped, the motion is over (the axis holds).
  if (cancelled_ && stopped()) motion_ = Motion::none;
  o.mode = static_cast<std::int8_t>(kModes[static_cast<int>(motion_)]);
  if (motion_ == Motion::none) o.target_velocity = 0;  // no motion: hold at standstill
  else motion_mode_ = o.mode;
  if (motion_ == Motion::velctrl) {
    // VELCTRL: VREF through ACCR/DECR (0: at once); a pause or a cancel decelerates to 0 at
    // DECR, or at the deceleration parameter (0103h) when DECR is 0.
    // The drive core's PV ramp; a rate of 0 is a step (infinite rate).
    const bool stop = paused_ || cancelled_;
    const double target = stop ? 0.0 : static_cast<double>(vref_);
    const auto rate = [](double r) { return r > 0 ? r : std::numeric_limits<double>::infinity(); };
    const double dec = stop && vel_dec_ == 0 ? rate(o.profile_deceleration) : rate(vel_dec_);
    vel_ramp_ = drive::ramp_velocity(vel_ramp_, target, rate(vel_acc_), dec, dt);
    o.target_velocity = static_cast<std::int32_t>(std::lround(vel_ramp_));
  }
  o.controlword = controlword();
  const drive::Command out = drive_.step(t, fb);
  if (!drive_.homed()) home_lost_ = false;  // a new homing started: the drive's flag tells again
  watch_latch();
  if (device_alarm()) {
    note_alarm(o.error_code);
    want_on_ = false;
    motion_ = Motion::none;
  } else {
    last_error_ = 0;
  }
  return out;
}

}  // namespace omnitwin::m3
