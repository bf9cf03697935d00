// bus_emulators/canopen — NMT and error control (see co_nmt.hpp).
#include "bus_emulators/canopen/co_nmt.hpp"

#include <algorithm>

namespace omnitwin::canopen {

namespace {
constexpr SimTime kMs = 1'000'000;
}  // namespace

const char* to_string(NmtState s) {
  switch (s) {
    case NmtState::initialising: return "initialising";
    case NmtState::stopped: return "stopped";
    case NmtState::operational: return "operational";
    case NmtState::pre_operational: return "pre_operational";
  }
  return "?";
}

const char* to_string(NmtCommand c) {
  switch (c) {
    case NmtCommand::start: return "start";
    case NmtCommand::stop: return "stop";
    case NmtCommand::enter_pre_operational: return "enter_pre_operational";
    case NmtCommand::reset_node: return "reset_node";
    case NmtCommand::reset_communication: return "reset_communication";
  }
  return "?";
}

const char* to_string(NmtTransition t) {
  switch (t) {
    case NmtTransition::boot_up: return "boot_up";
    case NmtTransition::start: return "start";
    case NmtTransition::stop: return "stop";
    case NmtTransition::enter_pre_operational: return "enter_pre_operational";
    case NmtTransition::reset_node: return "reset_node";
    case NmtTransition::reset_communication: return "reset_communication";
  }
  return "?";
}

NmtTransition transition_of(NmtCommand c) {
  switch (c) {
    case NmtCommand::start: return NmtTransition::start;
    case NmtCommand::stop: return NmtTransition::stop;
    case NmtCommand::enter_pre_operational: return NmtTransition::enter_pre_operational;
    case NmtCommand::reset_node: return NmtTransition::reset_node;
    case NmtCommand::reset_communication: return NmtTransition::reset_communication;
  }
  return NmtTransition::reset_communication;
}

// ---------------------------------------------------------------------------------------
// NMT slave

bool NmtSlave::decode(const can::Frame& f, NmtTransition& out) const {
  if (f.id != cob::nmt || f.extended || f.kind != can::FrameKind::data || f.dlc != 2) return false;
  if (f.data[1] != 0 && f.data[1] != node_id_) return false;
  switch (f.data[0]) {
    case 0x01: case 0x02: case 0x80: case 0x81: case 0x82:
      out = transition_of(static_cast<NmtCommand>(f.data[0]));
      return true;
    default: return false;
  }
}

bool NmtSlave::apply(NmtTransition t, SimTime now, const SendFn& send) {
  const NmtState s = state_;
  switch (t) {
    case NmtTransition::boot_up: {
      if (s != NmtState::initialising) return false;
      can::Frame f = frame11(cob::heartbeat + node_id_, 1);  // boot-up: [00]
      send(f, now);
      state_ = NmtState::pre_operational;
      return true;
    }
    case NmtTransition::start:
      if (s != NmtState::pre_operational && s != NmtState::stopped && s != NmtState::operational) return false;
      state_ = NmtState::operational;
      return true;
    case NmtTransition::stop:
      if (s == NmtState::initialising) return false;
      state_ = NmtState::stopped;
      return true;
    case NmtTransition::enter_pre_operational:
      if (s == NmtState::initialising) return false;
      state_ = NmtState::pre_operational;
      return true;
    case NmtTransition::reset_node:
    case NmtTransition::reset_communication:
      state_ = NmtState::initialising;
      return true;
  }
  return false;
}

// ---------------------------------------------------------------------------------------
// Error control producer

void ErrorControlProducer::restart(SimTime now) {
  period_ms_ = 0;  // re-armed from the parameters at the next on_time
  next_heartbeat_ = now;
  from_restart_ = true;
}

void ErrorControlProducer::reset(SimTime now) {
  toggle_ = false;
  lost_ = false;
  last_guard_ = -1;
  restart(now);
}

LifeGuardEvent ErrorControlProducer::on_time(SimTime now, const ErrorControlParams& p, NmtState s, const SendFn& send) {
  if (s == NmtState::initialising) return LifeGuardEvent::none;
  if (p.heartbeat_ms != 0) {
    const SimTime period = p.heartbeat_ms * kMs;
    // The first period counts from the restart (boot-up); a new 0x1017 (also after 0) from now.
    if (p.heartbeat_ms != period_ms_) {
      next_heartbeat_ = (from_restart_ ? next_heartbeat_ : now) + period;
      period_ms_ = p.heartbeat_ms;
      from_restart_ = false;
    }
    if (next_heartbeat_ <= now) {
      can::Frame f = frame11(cob::heartbeat + node_id_, 1);
      f.data[0] = static_cast<std::uint8_t>(s);
      send(f, now);
      ++heartbeats_;
      next_heartbeat_ += period;
      if (next_heartbeat_ <= now) next_heartbeat_ = now + period;  // a late caller: no catch-up burst
    }
    return LifeGuardEvent::none;
  }
  period_ms_ = 0;
  from_restart_ = false;
  // Life guarding: active once the master has guarded us and both parameters are set.
  const SimTime life = static_cast<SimTime>(p.guard_time_ms) * p.life_factor * kMs;
  if (life == 0 || last_guard_ < 0 || lost_) return LifeGuardEvent::none;
  if (now - last_guard_ > life) {
    lost_ = true;
    return LifeGuardEvent::lost;
  }
  return LifeGuardEvent::none;
}

LifeGuardEvent ErrorControlProducer::on_guard_request(SimTime now, const ErrorControlParams& p, NmtState s,
                                                      const SendFn& send) {
  if (p.heartbeat_ms != 0 || s == NmtState::initialising) return LifeGuardEvent::none;
  can::Frame f = frame11(cob::heartbeat + node_id_, 1);
  f.data[0] = static_cast<std::uint8_t>((toggle_ ? 0x80 : 0x00) | static_cast<std::uint8_t>(s));
  send(f, now);
  toggle_ = !toggle_;
  ++guard_answers_;
  last_guard_ = now;
  if (lost_) {
    lost_ = false;
    return LifeGuardEvent::resumed;
  }
  return LifeGuardEvent::none;
}

// ---------------------------------------------------------------------------------------
// Heartbeat consumer

void HeartbeatConsumer::set(std::uint8_t node, std::uint16_t time_ms) {
  if (!valid_node_id(node)) return;
  // The list on_time walks: configured producers only.
  auto* end = watched_.begin() + watched_n_;
  auto* it = std::find(watched_.begin(), end, node);
  if (time_ms != 0 && it == end) watched_[static_cast<std::size_t>(watched_n_++)] = node;
  if (time_ms == 0 && it != end) std::copy(it + 1, end, it), --watched_n_;
  Slot& s = slots_[node];
  s.time_ms = time_ms;
  s.active = time_ms != 0 && s.heard;
  s.timed_out = false;
}

bool HeartbeatConsumer::set_from_entry(std::uint32_t entry) {
  const auto node = static_cast<std::uint8_t>((entry >> 16) & 0xFF);
  const auto ms = static_cast<std::uint16_t>(entry & 0xFFFF);
  if (node == 0 || ms == 0) return true;  // an unused entry
  if (!valid_node_id(node)) return false;
  set(node, ms);
  return true;
}

void HeartbeatConsumer::clear() {
  for (Slot& s : slots_) s = Slot{};
  watched_n_ = 0;
}

void HeartbeatConsumer::on_frame(const can::Frame& f, SimTime now) {
  if (f.extended || f.kind != can::FrameKind::data || f.dlc != 1) return;
  if (f.id <= cob::heartbeat || f.id > cob::heartbeat + 127) return;
  const auto node = static_cast<std::uint8_t>(f.id - cob::heartbeat);
  Slot& s = slots_[node];
  const auto st = static_cast<NmtState>(f.data[0] & 0x7F);
  const NmtState before = s.state;
  const bool was_out = s.timed_out;
  s.last = now;
  s.state = st;
  s.heard = true;
  s.active = s.time_ms != 0;
  s.timed_out = false;
  if (st == NmtState::initialising) {
    if (on_event_) on_event_({HeartbeatEvent::boot_up, node, st, now});
  } else if (was_out) {
    if (on_event_) on_event_({HeartbeatEvent::resumed, node, st, now});
  } else if (before != st && on_event_) {
    on_event_({HeartbeatEvent::state_changed, node, st, now});
  }
}

void HeartbeatConsumer::on_time(SimTime now) {
  for (int k = 0; k < watched_n_; ++k) {
    const std::uint8_t n = watched_[static_cast<std::size_t>(k)];
    Slot& s = slots_[n];
    if (!s.active || s.timed_out) continue;
    if (now - s.last <= static_cast<SimTime>(s.time_ms) * kMs) continue;
    s.timed_out = true;
    ++timeouts_;
    if (on_event_) on_event_({HeartbeatEvent::timeout, n, s.state, now});
  }
}

}  // namespace omnitwin::canopen
