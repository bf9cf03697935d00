// controller/mechatrolink3 — one servo axis seen by the master application; see m3_servo_axis.hpp.
#include "controller/mechatrolink3/m3_servo_axis.hpp"

#include <fmt/format.h>

#include <algorithm>

#include "bus_emulators/mechatrolink3/m3_servo_format.hpp"

namespace omnitwin::m3 {

namespace {

using namespace servo;  // the profile's field layout (bus_emulators/mechatrolink3/m3_servo_format.hpp)

// ID_RD: the first 16 characters of the device name.
constexpr std::uint16_t kIdSizeRead = 16;

// SVCMD_CTRL with the monitors the axis reads: SEL_MON1 APOS, SEL_MON2 FSPD.
constexpr std::uint32_t kSelMon = sel_mon(static_cast<std::uint32_t>(Monitor::apos), static_cast<std::uint32_t>(Monitor::fspd));

Command command_of(AxisStep s, bool position_mode) {
  switch (s) {
    case AxisStep::disconnect:
    case AxisStep::release: return Command::disconnect;
    case AxisStep::connect: return Command::connect;
    case AxisStep::sync_set: return Command::sync_set;
    case AxisStep::id_rd: return Command::id_rd;
    case AxisStep::params: return Command::svprm_wr;
    case AxisStep::sens_on: return Command::sens_on;
    case AxisStep::sv_on: return Command::sv_on;
    case AxisStep::running: return position_mode ? Command::interpolate : Command::velctrl;
    case AxisStep::sv_off: return Command::sv_off;
    case AxisStep::alm_clr: return Command::alm_clr;
    default: return Command::nop;
  }
}

}  // namespace

const char* to_string(AxisStep s) {
  switch (s) {
    case AxisStep::disconnect: return "DISCONNECT";
    case AxisStep::connect: return "CONNECT";
    case AxisStep::sync_set: return "SYNC_SET";
    case AxisStep::id_rd: return "ID_RD";
    case AxisStep::params: return "SVPRM_WR";
    case AxisStep::sens_on: return "SENS_ON";
    case AxisStep::sv_on: return "SV_ON";
    case AxisStep::running: return "running";
    case AxisStep::sv_off: return "SV_OFF";
    case AxisStep::release: return "DISCONNECT (release)";
    case AxisStep::released: return "released";
    case AxisStep::failed: return "failed";
    case AxisStep::alm_clr: return "ALM_CLR";
  }
  return "?";
}

ServoAxis::ServoAxis(std::string name, ServoAxisConfig config, Log log)
    : name_(std::move(name)), cfg_(std::move(config)), log_(std::move(log)) {}

void ServoAxis::go(AxisStep next, SimTime t) {
  step_ = next;
  if (log_) log_(t, fmt::format("{}: {}", name_, next == AxisStep::failed ? "failed: " + why_ : to_string(next)));
}

// Whether the response answers command c as accepted; a CMD_ALM alarm in start-up fails the axis.
bool ServoAxis::accepted(Command c, std::span<const std::uint8_t> rsp, SimTime t) {
  if (rsp[0] != static_cast<std::uint8_t>(c)) return false;  // not yet the answer to this command
  // The shut-down goes on whatever the answer: a slave that refused SV_OFF is still disconnected.
  if (!is_alarm(stat_.cmd_alm) || stopping_) return true;
  if (c == Command::connect && stat_.cmd_alm == CmdAlarm::phase_error) {
    // Already connected: an earlier CONNECT of ours took effect but its answers were lost.
    // DISCONNECT and connect again rather than give up.
    if (log_) log_(t, fmt::format("{}: CONNECT answered with a phase error: already connected; disconnecting first", name_));
    go(AxisStep::disconnect, t);
    return false;
  }
  why_ = fmt::format("{} answered with CMD_ALM {:X}h ({})", to_string(c), static_cast<int>(stat_.cmd_alm),
                     to_string(stat_.cmd_alm));
  go(AxisStep::failed, t);
  return false;
}

void ServoAxis::on_interrupt(std::span<const std::uint8_t> rsp, bool fresh, std::span<std::uint8_t> cmd, SimTime t) {
  if (fresh) {
    stat_ = unpack_stat(get_u16(rsp, 2));
    apos_ = get_i32(rsp, kMonitor1);
    fspd_ = get_i32(rsp, kMonitor2);
    if (recover(rsp, t)) return write(cmd);
    const Command c = command_of(step_, cfg_.position_mode);
    const bool ok = step_ != AxisStep::released && step_ != AxisStep::failed && accepted(c, rsp, t);
    switch (ok ? step_ : AxisStep::failed) {
      case AxisStep::disconnect: go(AxisStep::connect, t); break;
      case AxisStep::connect: go(cfg_.synchronous ? AxisStep::sync_set : recovering_ ? AxisStep::sens_on : AxisStep::id_rd, t); break;
      case AxisStep::sync_set: go(recovering_ ? AxisStep::sens_on : AxisStep::id_rd, t); break;
      case AxisStep::alm_clr: go(cfg_.synchronous ? AxisStep::sync_set : AxisStep::sens_on, t); break;
      case AxisStep::id_rd:
        device_.assign(rsp.begin() + kIdData, std::find(rsp.begin() + kIdData, rsp.begin() + kIdData + kIdSizeRead, std::uint8_t{0}));
        if (log_) log_(t, fmt::format("{}: device \"{}\"", name_, device_));
        go(AxisStep::params, t);
        break;
      case AxisStep::params:
        if (++param_ >= cfg_.params.size()) go(AxisStep::sens_on, t);
        break;
      case AxisStep::sens_on: go(AxisStep::sv_on, t); break;
      case AxisStep::sv_on:
        if (stat_.cmdrdy && (get_u32(rsp, kSvcmdStat) & kSvOn) != 0) {
          recovering_ = false;
          vff_ = 0, anchor_ = true;  // INTERPOLATE from where the servo stands, not from an old target
          go(AxisStep::running, t);
        }
        break;
      case AxisStep::running:
        if (stop_written_) go(AxisStep::sv_off, t);  // the zero-speed command was answered
        break;
      case AxisStep::sv_off: go(AxisStep::release, t); break;
      case AxisStep::release: go(AxisStep::released, t); break;
      default: break;
    }
    if (step_ == AxisStep::params && cfg_.params.empty()) go(AxisStep::sens_on, t);
    if (step_ == AxisStep::running && anchor_) position_ = apos_, anchor_ = false;
  }
  write(cmd);
  if (stopping_ && step_ == AxisStep::running && !anchor_) stop_written_ = true;
}

void ServoAxis::shutdown(SimTime t) {
  if (stopping_) return;
  stopping_ = true;
  hold();
  switch (step_) {
    case AxisStep::disconnect:
    case AxisStep::connect: return go(AxisStep::release, t);  // not connected (yet): DISCONNECT is all
    case AxisStep::running:
    case AxisStep::sv_off:
    case AxisStep::release:
    case AxisStep::released: return;  // running: one zero-speed command answered first
    default: return go(AxisStep::sv_off, t);  // start-up, a recovery, a failed start-up
  }
}

// A slave back in phase 1 is connected again; a servo that went off while running, or a
// communication alarm during start-up (SV_ON is refused until ALM_CLR), is cleared and
// switched on again. True when a recovery began (the response is not used).
bool ServoAxis::recover(std::span<const std::uint8_t> rsp, SimTime t) {
  const bool started = step_ >= AxisStep::sync_set && step_ <= AxisStep::running;
  if (!started || stopping_) return false;
  if (stat_.cmd_alm == CmdAlarm::phase_error) {
    why_ = fmt::format("{} answered with a phase error: the slave lost power, its connection or phase 3",
                       to_string(static_cast<Command>(rsp[0])));
  } else if (step_ == AxisStep::running && (get_u32(rsp, kSvcmdStat) & kSvOn) == 0) {
    why_ = fmt::format("the servo went off (COMM_ALM {:X}h, D_ALM {})", static_cast<int>(stat_.comm_alm), stat_.d_alm);
  } else if (step_ < AxisStep::running && is_alarm(stat_.comm_alm)) {
    // During start-up: the slave refuses SV_ON until the alarm is cleared. (While running, an
    // alarm that leaves the servo on needs no recovery: a recovery takes the axis out of
    // running, and the platform loop stops for a lost axis.)
    why_ = fmt::format("a communication alarm (COMM_ALM {:X}h) during start-up", static_cast<int>(stat_.comm_alm));
  } else {
    return false;
  }
  ++recoveries_;
  recovering_ = true;
  if (log_) log_(t, fmt::format("{}: {}; recovering", name_, why_));
  // DISCONNECT works in every phase, so the start-up begins again from wherever the slave is.
  go(stat_.cmd_alm == CmdAlarm::phase_error ? AxisStep::disconnect : AxisStep::alm_clr, t);
  return true;
}

void ServoAxis::write(std::span<std::uint8_t> cmd) const {
  std::fill(cmd.begin(), cmd.end(), std::uint8_t{0});
  const Command c = command_of(step_, cfg_.position_mode);
  write_header(cmd, CommandHeader{static_cast<std::uint8_t>(c), 0, 0});
  switch (step_) {
    case AxisStep::connect:
      cmd[4] = 0x30;  // VER: standard servo profile
      cmd[5] = cfg_.synchronous ? 0x02 : 0x00;  // COM_MOD: (a)synchronous, single transfer, no subcommands
      cmd[6] = cfg_.com_tim;
      cmd[7] = 0x10;  // PROFILE_TYPE: standard servo
      return;
    case AxisStep::id_rd:
      put_u16(cmd, kIdSize, kIdSizeRead);  // ID_CODE 0 from OFFSET 0: the device name
      return;
    case AxisStep::params:
      if (param_ >= cfg_.params.size()) return;
      put_u16(cmd, kPrmNo, cfg_.params[param_].first);
      cmd[kPrmSize] = 4;
      put_i32(cmd, kPrmData, cfg_.params[param_].second);
      return;
    case AxisStep::running:
      put_u32(cmd, kSvcmdCtrl, kSelMon);
      if (cfg_.position_mode) {
        put_i32(cmd, kIpTpos, position_);
        put_i32(cmd, kIpVff, vff_);
      } else {
        put_i32(cmd, kVelVref, velocity_);
      }
      return;
    case AxisStep::alm_clr:
      put_u16(cmd, 2, pack(CmdCtrl{.alm_clr = true, .cmd_id = 0}));  // the communication alarm too
      return;
    case AxisStep::sens_on:
    case AxisStep::sv_on:
    case AxisStep::sv_off: put_u32(cmd, kSvcmdCtrl, kSelMon); return;
    default: return;
  }
}

}  // namespace omnitwin::m3
