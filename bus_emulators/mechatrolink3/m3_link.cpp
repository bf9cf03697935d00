// bus_emulators/mechatrolink3 — a slave station's communication core; see m3_link.hpp.
#include "bus_emulators/mechatrolink3/m3_link.hpp"

#include <algorithm>

namespace omnitwin::m3 {

namespace {

// 0 normal, 1 a warning, 2 an alarm.
int severity(CommAlarm a) { return a == CommAlarm::normal ? 0 : is_alarm(a) ? 2 : 1; }

}  // namespace

SlaveLink::SlaveLink(const LinkConfig& config, Profile& profile, Emit emit)
    : cfg_(config), profile_(profile), emit_(std::move(emit)) {}

void SlaveLink::transition(Transition tr, SimTime t) {
  switch (tr) {
    case Transition::power_on:
      if (s_.phase != Phase::p5) return;
      s_ = State{};  // power-on: nothing remembered
      s_.phase = Phase::p1;
      return;
    case Transition::connect:
      if (s_.phase == Phase::p1) s_.phase = Phase::p2;
      return;
    case Transition::sync_set:
      if (s_.phase != Phase::p2) return;
      s_.phase = Phase::p3;
      // Without a SYNC, the first check comes one and a half transmission cycles from now.
      s_.next_check = t + 3 * s_.cycle_ns / 2;
      s_.last_sync = s_.last_command = t;
      s_.sync_misses = s_.command_misses = 0;
      s_.cycle_open = false;
      s_.syncs = 0;
      s_.wdt_seen = false;
      return;
    case Transition::disconnect:
      if (s_.phase == Phase::p5) return;
      if (s_.phase != Phase::p1) profile_.disconnect(t);
      s_.phase = Phase::p1;
      return;
    case Transition::comm_alarm:
      profile_.stop(t);
      if (s_.phase == Phase::p3) s_.phase = Phase::p2;
      return;
    case Transition::power_off:
      s_.phase = Phase::p5;
      return;
  }
}

void SlaveLink::power_on(SimTime t) { transition(Transition::power_on, t); }
void SlaveLink::power_off(SimTime t) { transition(Transition::power_off, t); }

void SlaveLink::on_frame(std::span<const std::uint8_t> bytes, SimTime t) {
  if (s_.phase == Phase::p5) return;  // no power: the line passes frames on, nobody reads them
  FrameView f;
  const FrameStatus s = decode(bytes, f);
  if (s == FrameStatus::bad_fcs) {
    // Only a frame that (by its unchecked destination byte) was ours or everybody's counts.
    // Before CONNECT there is no communication to supervise: counted, not raised.
    if (!bytes.empty() && (bytes[0] == cfg_.address || bytes[0] == kBroadcast)) {
      ++s_.stats.fcs_errors;
      if (s_.phase != Phase::p1) raise(++s_.fcs_in_row >= 2 ? CommAlarm::fcs : CommAlarm::fcs_warning, t);
    }
    return;
  }
  if (s != FrameStatus::ok) return void(++s_.stats.bad_frames);
  if (f.dst != cfg_.address && f.dst != kBroadcast) return void(++s_.stats.not_for_me);
  if (f.src != kC1Master) return void(++s_.stats.bad_frames);  // a C2 master is not served here
  if (f.type == FrameType::cyclic_command || f.type == FrameType::event_command) return on_command(f, t);
  on_link_service(f, t);
}

void SlaveLink::on_link_service(const FrameView& f, SimTime t) {
  switch (f.type) {
    case FrameType::sync:
      // A slave that was not told the cycle (it came back after the notification) takes it
      // from the interval of two sync frames, as its ASIC locks onto them.
      if (s_.cycle_ns <= 0 && s_.last_sync >= 0 && t > s_.last_sync) s_.cycle_ns = t - s_.last_sync;
      if (s_.phase == Phase::p3) on_sync(t);
      s_.last_sync = t;
      return;
    case FrameType::detect: {
      std::array<std::uint8_t, 8> d{};
      put_u32(d, 0, cfg_.vendor_id);
      put_u16(d, 4, cfg_.device_code);
      d[6] = profile_.profile_type();
      d[7] = static_cast<std::uint8_t>(s_.phase);
      return reply(FrameType::detect_reply, d, f.sequence(), t + cfg_.response_ns);
    }
    case FrameType::delay_request: return reply(FrameType::delay_reply, {}, f.sequence(), t + kDelayEchoNs);
    case FrameType::cycle_notify: s_.cycle_ns = get_u32(f.data, 0); return;
    case FrameType::comm_start: s_.started = true; return;
    default: ++s_.stats.bad_frames; return;  // responses and replies are for masters
  }
}

void SlaveLink::on_command(const FrameView& f, SimTime t) {
  ++s_.stats.commands;
  s_.fcs_in_row = 0;
  const FrameType type = f.type == FrameType::cyclic_command ? FrameType::cyclic_response : FrameType::event_response;
  // A retry of the command just executed (its response was lost or late): answered with the
  // stored response, not executed again — CONNECT or a POSING must not run twice (ours). Only
  // the very same command is a retry: a new one may come with the same sequence number.
  const auto last = std::span(cmd_).first(s_.last_length);
  if (f.retry() && f.sequence() == s_.last_sequence && std::equal(f.data.begin(), f.data.end(), last.begin(), last.end())) {
    ++s_.stats.repeated;
    s_.last_command = t;
    return reply(type, std::span(rsp_).first(s_.last_length), f.sequence(), t + cfg_.response_ns);
  }
  CommandHeader h;
  read_header(f.data, h);  // every command length is at least 8 bytes
  const CmdCtrl ctrl = unpack_ctrl(h.ctrl);
  if (s_.phase == Phase::p3 && !f.retry()) check_watchdog(h.wdt, t);
  s_.last_command = t;
  if (s_.phase == Phase::p3) s_.command_misses = 0, s_.commanded = true;
  // ALM_CLR (the command or CMD_CTRL.ALM_CLR) clears COMM_ALM, only in a phase it is allowed in;
  // CMD_CTRL.ALM_CLR rising also resets the device's alarm (the command does that itself).
  const bool clear = allowed_in(Command::alm_clr, s_.phase);
  if (clear && (ctrl.alm_clr || h.code == static_cast<std::uint8_t>(Command::alm_clr))) s_.comm_alm = CommAlarm::normal;
  if (clear && ctrl.alm_clr && !s_.alm_clr_bit) profile_.clear_alarms();
  s_.alm_clr_bit = ctrl.alm_clr;
  const auto rsp = std::span(rsp_).first(f.data.size());
  std::fill(rsp.begin(), rsp.end(), std::uint8_t{0});
  write_header(rsp, CommandHeader{h.code, static_cast<std::uint8_t>((h.wdt & 0xF0) | (s_.own_count++ & 0x0F)), 0});
  s_.cmd_alm = run_link_command(static_cast<Command>(h.code), f.data, rsp, t);
  if (s_.conn.subcommand && f.data.size() == 48 && s_.phase != Phase::p1)
    run_subcommand(static_cast<Command>(h.code), f.data, rsp);
  if (s_.cmd_alm == CmdAlarm::phase_error) ++s_.stats.phase_errors;
  if (s_.cmd_alm == CmdAlarm::unsupported) ++s_.stats.unsupported;
  // ALM_CLR_CMP: the clear is complete, COMM_ALM at once, a device alarm once the device has
  // reset it (a drive period later; never while its cause persists).
  CmdStat st{profile_.device_alarm(), profile_.device_warning(), profile_.ready(),
             clear && ctrl.alm_clr && !profile_.device_alarm(), ctrl.cmd_id, s_.cmd_alm, s_.comm_alm};
  put_u16(rsp, 2, pack(st));
  s_.last_sequence = f.sequence();
  s_.last_length = f.data.size();
  std::copy(f.data.begin(), f.data.end(), cmd_.begin());
  reply(type, rsp, f.sequence(), t + cfg_.response_ns);
}

CmdAlarm SlaveLink::run_link_command(Command c, std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp,
                                     SimTime t) {
  if (!is_known(c)) return CmdAlarm::unsupported;
  if (!allowed_in(c, s_.phase)) return CmdAlarm::phase_error;
  if (s_.phase != Phase::p3 && profile_.synchronous_only(c)) return CmdAlarm::phase_error;
  if (is_alarm(s_.comm_alm) && profile_.needs_alarm_cleared(c)) return CmdAlarm::condition_error;
  switch (c) {
    case Command::nop: return CmdAlarm::normal;
    case Command::connect: return connect(cmd, rsp, t);
    case Command::disconnect: transition(Transition::disconnect, t); return CmdAlarm::normal;
    case Command::sync_set:
      if (!s_.conn.synchronous || s_.cycle_ns <= 0) return CmdAlarm::condition_error;  // event-driven: never P3
      transition(Transition::sync_set, t);
      return CmdAlarm::normal;
    default: break;
  }
  // The profile reads its fields at fixed offsets: a command of another length than the
  // connection's (before CONNECT: one the profile does not take) is not executed.
  const bool length_ok = s_.phase == Phase::p1 ? profile_.accepts_length(cmd.size()) || cmd.size() == kMaxData
                                               : cmd.size() == s_.conn.data_bytes;
  if (!length_ok) {
    ++s_.stats.length_errors;
    return CmdAlarm::invalid_data;
  }
  return profile_.execute(c, cmd, rsp, t);
}

// The subcommand region of the 48-byte mode, after the main command: SUB_RCMD, SUB_STAT and
// the profile's answer; a subcommand that cannot go with the main command is SUBCMD_ALM Bh
// (the main command is executed all the same).
void SlaveLink::run_subcommand(Command main, std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp) {
  const auto sub_cmd = cmd.subspan(kSubcommandOffset, 16);
  const auto sub_rsp = rsp.subspan(kSubcommandOffset, 16);
  const auto sub = static_cast<Command>(sub_cmd[0]);
  sub_rsp[0] = sub_cmd[0];
  CmdAlarm a = CmdAlarm::normal;
  if (!is_known(sub) || !is_subcommand(sub)) a = CmdAlarm::unsupported;
  else if (!combines(main, sub)) a = CmdAlarm::subcommand_combination;
  else if (sub != Command::nop) a = profile_.execute_sub(sub, sub_cmd, sub_rsp);
  const std::uint32_t st = pack_sub_stat(true, a);
  for (std::size_t i = 0; i < 3; ++i) sub_rsp[1 + i] = static_cast<std::uint8_t>(st >> (8 * i));
}

CmdAlarm SlaveLink::connect(std::span<const std::uint8_t> cmd, std::span<std::uint8_t> rsp, SimTime t) {
  const std::uint8_t ver = cmd[4], mod = cmd[5], com_tim = cmd[6], profile = cmd[7];
  std::copy_n(cmd.begin() + 4, 4, rsp.begin() + 4);  // the response echoes the parameters
  const bool sub = (mod & kComModSubcommand) != 0;
  if (ver != kServoProfileVersion || com_tim == 0 || profile != profile_.profile_type()) return CmdAlarm::invalid_data;
  if ((mod & (kComModDtMode | kComModReserved)) != 0) return CmdAlarm::invalid_data;
  // The communication cycle is checked when the transmission cycle is known (not event-driven).
  const SimTime comm_cycle = s_.cycle_ns * com_tim;
  if (s_.cycle_ns > 0 && (comm_cycle < kMinCommCycleNs || comm_cycle > kMaxCommCycleNs)) return CmdAlarm::invalid_data;
  // Event-driven data is 64 bytes whatever the profile (seed 000); cyclic lengths are the profile's.
  const bool event = cmd.size() == kMaxData && (mod & kComModSync) == 0;
  if (!(event || profile_.accepts_length(cmd.size())) || (sub && cmd.size() != 48)) return CmdAlarm::invalid_data;
  s_.conn = Connection{(mod & kComModSync) != 0, sub, com_tim, profile, cmd.size()};
  transition(Transition::connect, t);
  return CmdAlarm::normal;
}

void SlaveLink::check_watchdog(std::uint8_t wdt, SimTime t) {
  const std::uint8_t count = wdt >> 4;
  if (s_.wdt_seen && count == s_.last_wdt) {
    ++s_.stats.wdt_errors;
    raise(CommAlarm::wdt, t);  // the master's count did not advance: at once
  }
  s_.last_wdt = count;
  s_.wdt_seen = true;
}

// A SYNC in phase 3: the slave's cycle follows the master's. The SYNC that opens a new
// communication cycle (every COM_TIM transmission cycles) closes the previous one, which must
// have brought a command; and the next SYNC is due within one and a half transmission cycles
// of this one. Anchored on the SYNC, not on a fixed grid, so jitter of up to half a cycle in
// when frames arrive is no miss.
void SlaveLink::on_sync(SimTime t) {
  s_.sync_misses = 0;
  s_.next_check = t + 3 * s_.cycle_ns / 2;
  if (s_.syncs++ % s_.conn.com_tim != 0) return;
  if (s_.cycle_open && !s_.commanded) count_miss(false, t);
  s_.cycle_open = true;
  s_.commanded = false;
}

void SlaveLink::advance(SimTime t) {
  if (s_.phase != Phase::p3 || s_.cycle_ns <= 0) return;
  // No SYNC: each transmission cycle without one is a miss (the master stopped or lost it).
  while (t >= s_.next_check && s_.phase == Phase::p3) {
    s_.next_check += s_.cycle_ns;
    count_miss(true, s_.next_check - s_.cycle_ns);
  }
}

void SlaveLink::count_miss(bool sync, SimTime t) {
  int& misses = sync ? s_.sync_misses : s_.command_misses;
  ++(sync ? s_.stats.missed_syncs : s_.stats.missed_commands);
  ++misses;
  if (sync) raise(misses >= 2 ? CommAlarm::no_sync : CommAlarm::no_sync_warning, t);
  else raise(misses >= 2 ? CommAlarm::no_command : CommAlarm::no_command_warning, t);
}

void SlaveLink::raise(CommAlarm a, SimTime t) {
  if (severity(a) >= severity(s_.comm_alm)) s_.comm_alm = a;  // an alarm is never hidden by a warning
  if (!is_alarm(a)) return;
  ++s_.stats.comm_alarms;
  transition(Transition::comm_alarm, t);
}

void SlaveLink::reply(FrameType type, std::span<const std::uint8_t> data, std::uint8_t sequence, SimTime t) {
  const std::size_t n = encode(FrameSpec{.dst = kC1Master, .src = cfg_.address, .type = type,
                                         .sequence = sequence, .retry = false, .data = data},
                               out_);
  if (n == 0) return;
  ++s_.stats.responses;
  emit_(std::span<const std::uint8_t>(out_.data(), n), t);
}

}  // namespace omnitwin::m3
