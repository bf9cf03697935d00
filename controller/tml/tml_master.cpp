// controller/tml — our TML master (see tml_master.hpp).
#include "controller/tml/tml_master.hpp"

#include <fmt/format.h>

#include <cmath>

#include "bus_emulators/tml/tml_can.hpp"
#include "bus_emulators/tml/tml_drive.hpp"

namespace omnitwin::controller::tml {

namespace t = omnitwin::tml;

const char* to_string(TmlPhase p) {
  switch (p) {
    case TmlPhase::detecting: return "detecting";
    case TmlPhase::starting: return "starting";
    case TmlPhase::running: return "running";
    case TmlPhase::stopped: return "stopped";
    case TmlPhase::finished: return "finished";
    case TmlPhase::failed: return "failed";
  }
  return "?";
}

TmlMaster::TmlMaster(const TmlProgramConfig& config, SendFn send) : cfg_(config), send_(std::move(send)) {}

std::int32_t TmlMaster::speed_iu(double counts_per_s) const {
  return static_cast<std::int32_t>(std::llround(counts_per_s * cfg_.sample_period * 65536.0));
}

std::uint16_t TmlMaster::group() const { return t::group_id_code(t::group_mask(1)); }

int TmlMaster::wheel_of(std::uint8_t axis) const {
  for (int i = 0; i < 4; ++i)
    if (cfg_.axes[static_cast<std::size_t>(i)] == axis) return i;
  return -1;
}

bool TmlMaster::send(const t::Message& m, SimTime at) {
  can::Frame f;
  const t::CanStatus s = cfg_.techcan ? t::encode_techcan(m, f) : t::encode_tmlcan(m, f);
  if (s != t::CanStatus::ok) return false;  // a message we build is always encodable: counted below
  const bool ok = send_(f, at);
  ++(ok ? stats_.frames_tx : stats_.tx_refused);
  return ok;
}

void TmlMaster::event(SimTime t, const std::string& text, bool warning) {
  if (event_) event_(t, text, warning);
}

void TmlMaster::enter(TmlPhase p, SimTime t) {
  if (p == phase_) return;
  event(t, fmt::format("phase {} -> {}", to_string(phase_), to_string(p)));
  phase_ = p;
}

void TmlMaster::stop(simclock::StopReason r, std::uint8_t axis, SimTime t, const std::string& why) {
  reason_ = r;
  reason_node_ = axis;
  event(t, why, true);
  enter(phase_ == TmlPhase::running ? TmlPhase::stopped : TmlPhase::failed, t);
  if (phase_ == TmlPhase::stopped) speeds(t, true);
}

simclock::MasterState TmlMaster::report_state() const {
  switch (phase_) {
    case TmlPhase::running: return simclock::MasterState::running;
    case TmlPhase::stopped:
    case TmlPhase::failed: return simclock::MasterState::stopped;
    case TmlPhase::finished: return simclock::MasterState::finished;
    default: return simclock::MasterState::detecting;
  }
}

// ---------------------------------------------------------------------------------------
// Receiving: TakeData2 answers of SRL (or SR32: SRL, SRH), CACC and APOS.

void TmlMaster::on_frame(const can::Frame& f, SimTime) {
  ++stats_.frames_rx;
  t::Message m;
  if (cfg_.techcan) {
    t::TechCanMessage tm;
    if (t::decode_techcan(f, tm) != t::CanStatus::ok) return void(++stats_.not_tml);
    m = tm.message;
  } else if (t::decode_tmlcan(f, m) != t::CanStatus::ok) {
    return void(++stats_.not_tml);
  }
  const t::Classified c = t::classify(m);
  if (c.kind != t::Kind::take_data2 || !c.complete) return;
  const int w = wheel_of(static_cast<std::uint8_t>(c.sender));
  if (w < 0) return;
  Axis& a = axes_[static_cast<std::size_t>(w)];
  ++stats_.answers;
  a.found = true;
  a.last_answer_tick = stats_.ticks;
  if (c.address == t::reg::srl) a.srl = static_cast<std::uint16_t>(c.value);
  if (c.address == t::reg::srl && c.wide) a.srh = static_cast<std::uint16_t>(c.value >> 16);
  if (c.address == t::reg::cacc) a.cacc = c.value;
  if (c.address == t::reg::apos) a.apos = static_cast<std::int32_t>(c.value);
}

// ---------------------------------------------------------------------------------------
// The tick

void TmlMaster::query(std::uint16_t address, bool wide, SimTime t) {
  send(t::give_me_data2(group(), t::axis_id_code(cfg_.host_axis), address, wide), t);
}

std::uint32_t TmlMaster::cacc_iu() const {
  return static_cast<std::uint32_t>(std::llround(cfg_.acceleration * cfg_.sample_period * cfg_.sample_period * 65536.0));
}

// Axis i: speed mode with the acceleration, command speed 0, applied; then the power stage on.
void TmlMaster::set_up(std::size_t i, SimTime t) {
  const std::uint16_t dest = t::axis_id_code(cfg_.axes[i]);
  send(t::bitset_instruction(dest, t::bitset_data::mode_sp), t);
  send(*t::assign32(dest, t::reg::cacc, cacc_iu()), t);
  send(*t::assign32(dest, t::reg::cspd, 0), t);
  send(t::instruction(dest, t::instr::upd), t);
  send(t::instruction(dest, t::instr::axison), t);
  axes_[i].setup_tick = stats_.ticks;
  ++axes_[i].setup_sends;
}

// What start-up can read back: on, no fault, CACC as sent. (MODE SP has no readable trace: the
// facts define no mode bit; CSPD 0 is also the power-on value.)
bool TmlMaster::confirmed(const Axis& a) const {
  return (a.srl & t::bits::srl_axis_on) && !(a.srh & t::bits::srh_fault) && a.cacc == cacc_iu();
}

// An axis not confirmed within kConfirmTicks of its set-up gets it again; after kSetupSends
// sends the start-up fails (false).
bool TmlMaster::confirm_set_up(SimTime t) {
  for (std::size_t i = 0; i < 4; ++i) {
    const Axis& a = axes_[i];
    if (confirmed(a) || stats_.ticks - a.setup_tick <= kConfirmTicks) continue;
    const std::string seen = fmt::format("SRL {:04X}, SRH {:04X}, CACC {:08X} (sent {:08X})", a.srl, a.srh, a.cacc, cacc_iu());
    if (a.setup_sends >= kSetupSends) {
      stop(simclock::StopReason::config_failed, cfg_.axes[i], t,
           fmt::format("axis {}: set-up not confirmed after {} sends ({}): start-up failed", cfg_.axes[i], a.setup_sends, seen));
      return false;
    }
    event(t, fmt::format("axis {}: set-up not confirmed ({}): sent again", cfg_.axes[i], seen), true);
    ++stats_.setup_resends;
    set_up(i, t);
  }
  return true;
}

void TmlMaster::speeds(SimTime t, bool zero) {
  for (std::size_t i = 0; i < 4; ++i)
    send(*t::assign32(t::axis_id_code(cfg_.axes[i]), t::reg::cspd,
                      static_cast<std::uint32_t>(zero ? 0 : speed_iu(speed_[i]))),
         t);
  send(t::instruction(group(), t::instr::upd), t);
}

// An axis that did not answer the last lost_ticks queries is lost.
void TmlMaster::check_answers(SimTime t) {
  for (std::size_t i = 0; i < 4; ++i) {
    const Axis& a = axes_[i];
    if (stats_.ticks - a.last_answer_tick <= static_cast<std::uint64_t>(cfg_.lost_ticks)) continue;
    ++stats_.axes_lost;
    stop(simclock::StopReason::node_missing, cfg_.axes[i], t,
         fmt::format("axis {} stopped answering: platform stopped (CSPD 0 to every axis)", cfg_.axes[i]));
    return;
  }
}

// An axis whose last SR32 says off (SRL.15 = 0) or in fault (SRH.15) no longer follows its CSPD:
// the platform stops as for a lost axis.
void TmlMaster::check_status(SimTime t) {
  for (std::size_t i = 0; i < 4; ++i) {
    const Axis& a = axes_[i];
    const bool off = !(a.srl & t::bits::srl_axis_on), fault = (a.srh & t::bits::srh_fault) != 0;
    if (!off && !fault) continue;
    ++stats_.axes_lost;
    stop(simclock::StopReason::drive_fault, cfg_.axes[i], t,
         fmt::format("axis {} is {} (SRL {:04X}, SRH {:04X}): platform stopped (CSPD 0 to every axis)", cfg_.axes[i],
                     fault ? "in fault" : "off", a.srl, a.srh));
    return;
  }
}

void TmlMaster::on_tick(SimTime t) {
  ++stats_.ticks;
  if (start_ < 0) start_ = t;
  const bool late = t - start_ > std::llround(cfg_.startup_timeout * 1e9);
  switch (phase_) {
    case TmlPhase::detecting: {
      bool all = true;
      for (const Axis& a : axes_) all = all && a.found;
      if (all) {
        event(t, "all four axes answered: speed mode, AXISON");
        for (std::size_t i = 0; i < 4; ++i) set_up(i, t);
        enter(TmlPhase::starting, t);
      } else if (late) {
        stop(simclock::StopReason::startup_timeout, 0, t, "not every axis answered in time");
        return;
      }
      query(t::reg::srl, false, t);
      return;
    }
    case TmlPhase::starting: {
      if (!confirm_set_up(t)) return;
      bool all = true;
      for (const Axis& a : axes_) all = all && confirmed(a);
      if (all) {
        enter(TmlPhase::running, t);
        for (Axis& a : axes_) a.last_answer_tick = stats_.ticks;
      } else if (late) {
        stop(simclock::StopReason::startup_timeout, 0, t, "not every axis switched on in time");
        return;
      }
      // Until every axis is confirmed, SR32 and CACC are read back in turn.
      query(all ? t::reg::apos : stats_.ticks % 2 ? t::reg::srl : t::reg::cacc, true, t);
      return;
    }
    case TmlPhase::running:
      check_answers(t);
      if (phase_ == TmlPhase::running) check_status(t);
      if (phase_ != TmlPhase::running) return;
      speeds(t, false);
      query(t::reg::apos, true, t);
      if (stats_.ticks % kStatusTicks == 0) query(t::reg::srl, true, t);  // SR32: SRL and SRH
      return;
    case TmlPhase::stopped:
    case TmlPhase::finished:
      // Holding still, the axes stay watched: a master on the wall clock that fell silent here
      // read as lost to the twin's supervision (exit 3 after a path that ended early, or after
      // the stop of a lost axis; found in review).
      query(t::reg::apos, true, t);
      if (stats_.ticks % kStatusTicks == 0) query(t::reg::srl, true, t);
      return;
    default:
      return;
  }
}

void TmlMaster::finish(SimTime t) {
  if (phase_ != TmlPhase::running) return;
  speed_ = {};
  speeds(t, true);
  enter(TmlPhase::finished, t);
}

void TmlMaster::shutdown(SimTime t) {
  speed_ = {};
  if (phase_ == TmlPhase::running) enter(TmlPhase::finished, t);
  if (phase_ != TmlPhase::detecting) speeds(t, true);
  send(t::instruction(group(), t::instr::axisoff), t);
  shut_down_ = true;
}

}  // namespace omnitwin::controller::tml
