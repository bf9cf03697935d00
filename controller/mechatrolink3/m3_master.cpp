// controller/mechatrolink3 — our C1 master's communication core; see m3_master.hpp.
#include "controller/mechatrolink3/m3_master.hpp"

#include <fmt/format.h>

#include <algorithm>

namespace omnitwin::m3 {

namespace {

constexpr SimTime kGapNs = kInterFrameGapNs;

}  // namespace

const char* to_string(DriverState s) {
  switch (s) {
    case DriverState::idle: return "idle";
    case DriverState::init: return "initialisation";
    case DriverState::detect: return "connected-station detection";
    case DriverState::delay: return "delay-time measurement";
    case DriverState::params: return "communication parameters";
    case DriverState::notify: return "transmission-cycle notification";
    case DriverState::start: return "communication start";
    case DriverState::cyclic: return "cyclic communication";
    case DriverState::event: return "event-driven communication";
    case DriverState::failed: return "failed";
  }
  return "?";
}

C1Master::C1Master(MasterConfig config, Emit emit, Interrupt interrupt, Log log)
    : cfg_(std::move(config)), emit_(std::move(emit)), interrupt_(std::move(interrupt)), log_(std::move(log)),
      slave_(cfg_.slaves.size()) {
  retry_.reserve(cfg_.slaves.size());
  queue_.assign(4 * cfg_.slaves.size() + 1, -1);
  requested_at_.assign(cfg_.slaves.size(), 0);
}

std::span<std::uint8_t> C1Master::command(int k) {
  return std::span(slave_[static_cast<std::size_t>(k)].cmd).first(cfg_.slaves[static_cast<std::size_t>(k)].data_bytes);
}

std::span<const std::uint8_t> C1Master::response(int k) const {
  return std::span(slave_[static_cast<std::size_t>(k)].rsp).first(cfg_.slaves[static_cast<std::size_t>(k)].data_bytes);
}

void C1Master::log(SimTime t, const std::string& line) const {
  if (log_) log_(t, line);
}

void C1Master::fail(SimTime t, std::string why) {
  state_ = DriverState::failed;
  why_ = std::move(why);
  wake_ = -1;
  log(t, "failed: " + why_);
}

void C1Master::send(FrameType type, std::uint8_t dst, std::span<const std::uint8_t> data, SimTime t, bool retry) {
  const std::size_t n = encode(FrameSpec{.dst = dst, .src = kC1Master, .type = type,
                                         .sequence = sequence_, .retry = retry, .data = data},
                               out_);
  if (n == 0) return;
  emit_(std::span<const std::uint8_t>(out_.data(), n), t);
}

void C1Master::start(SimTime t) {
  state_ = DriverState::init;
  log(t, "initialisation request: ASIC set up, normal operation checked");
  log(t, "SRAM test passed, parameters initialised");
  state_ = DriverState::detect;
  log(t, fmt::format("connected-station detection: {} stations configured", slaves()));
  station_ = 0;
  next_station(t);
}

// Setup: DETECT or DLY_REQ to the next station, or the next state when all were asked.
void C1Master::next_station(SimTime t) {
  const bool detecting = state_ == DriverState::detect;
  if (station_ < slaves()) {
    const std::uint8_t a = cfg_.slaves[static_cast<std::size_t>(station_)].address;
    send(detecting ? FrameType::detect : FrameType::delay_request, a, {}, t);
    pending_ = Pending{station_, detecting ? FrameType::detect_reply : FrameType::delay_reply, t,
                       t + cfg_.detect_timeout_ns};
    wake_ = pending_.deadline;
    return;
  }
  pending_ = Pending{};
  if (detecting) {
    state_ = DriverState::delay;
    log(t, "delay-time measurement request");
    station_ = 0;
    return next_station(t);
  }
  state_ = DriverState::params;
  if (cfg_.event_driven) {
    for (const MasterSlave& c : cfg_.slaves)
      if (c.data_bytes != kMaxData) {
        misfit_ = true;
        return fail(t, fmt::format("event-driven data is 64 bytes, slave {:02X}h has {}", c.address, c.data_bytes));
      }
    // Fig. 6: each slave answers within its own response time, 50 ms at most: T_RSP from its
    // measured TR_DLY, as in cyclic communication, capped at the limit. A silent slave then
    // holds the line for its three attempts of T_RSP, not of 50 ms.
    const CyclePlan p = plan();
    for (int k = 0; k < slaves(); ++k)
      slave_[static_cast<std::size_t>(k)].t_rsp = std::min(p.t_rsp_ns[static_cast<std::size_t>(k)], cfg_.event_timeout_ns);
    log(t, fmt::format("communication parameters: event-driven (no transmission cycle; each slave answers within its "
                       "T_RSP, at most {} ms)", cfg_.event_timeout_ns / 1'000'000));
    for (int k = 0; k < slaves(); ++k)
      log(t, fmt::format("  station {:02X}h T_RSP {} ns", address(k), slave_[static_cast<std::size_t>(k)].t_rsp));
    state_ = DriverState::start;
    send(FrameType::comm_start, kBroadcast, std::array<std::uint8_t, 8>{2}, t);
    log(t, "communication start: event-driven");
    state_ = DriverState::event;
    wake_ = -1;
    return;
  }
  if (!compute_params(t)) return;
  state_ = DriverState::notify;
  std::array<std::uint8_t, 16> n{};
  put_u32(n, 0, static_cast<std::uint32_t>(cfg_.cycle_ns));
  put_u32(n, 4, static_cast<std::uint32_t>(int_offset_));
  send(FrameType::cycle_notify, kBroadcast, n, t);
  log(t, fmt::format("transmission-cycle notification: {} µs", cfg_.cycle_ns / 1000));
  state_ = DriverState::start;
  const SimTime t_start = t + frame_slot_ns(16);
  send(FrameType::comm_start, kBroadcast, std::array<std::uint8_t, 8>{1}, t_start);
  log(t_start, "communication start: cyclic");
  state_ = DriverState::cyclic;
  interrupted_ = true;  // the first wake-up begins a cycle
  wake_ = t_start + frame_slot_ns(8);
}

void C1Master::finish_setup_exchange(SimTime t, bool answered) {
  Slave& s = slave_[static_cast<std::size_t>(station_)];
  const std::uint8_t a = cfg_.slaves[static_cast<std::size_t>(station_)].address;
  if (state_ == DriverState::detect) {
    s.detected = answered;
    if (!answered) return fail(t, fmt::format("no slave answers at address {:02X}h (connected-station detection)", a));
    log(t, fmt::format("  station {:02X}h detected", a));
  } else {
    if (!answered) return fail(t, fmt::format("slave {:02X}h does not answer the delay measurement", a));
    log(t, fmt::format("  station {:02X}h TR_DLY {} ns", a, s.tr_dly));
  }
  ++station_;
  next_station(t);
}

// Seed 000 fig. 10: T_RSP per station and INT_OFFSET from the measured delays.
CyclePlan C1Master::plan() const {
  std::vector<SimTime> tr;
  std::vector<StationTiming> st;
  for (int k = 0; k < slaves(); ++k) {
    tr.push_back(slave_[static_cast<std::size_t>(k)].tr_dly);
    const MasterSlave& c = cfg_.slaves[static_cast<std::size_t>(k)];
    st.push_back(StationTiming{.data_bytes = c.data_bytes, .response_ns = c.response_ns});
  }
  return plan_cycle(tr, st, cfg_.retry_slots, cfg_.margin_ns, cfg_.software_ns);
}

bool C1Master::compute_params(SimTime t) {
  const CyclePlan p = plan();
  for (int k = 0; k < slaves(); ++k) slave_[static_cast<std::size_t>(k)].t_rsp = p.t_rsp_ns[static_cast<std::size_t>(k)];
  int_offset_ = p.int_offset_ns;
  min_cycle_ = p.min_cycle_ns;
  log(t, fmt::format("communication parameters: INT_OFFSET {} ns, shortest cycle {} ns", int_offset_, min_cycle_));
  for (int k = 0; k < slaves(); ++k)
    log(t, fmt::format("  station {:02X}h T_RSP {} ns", cfg_.slaves[static_cast<std::size_t>(k)].address,
                       slave_[static_cast<std::size_t>(k)].t_rsp));
  if (std::string why = check_cycle(p, cfg_.cycle_ns); !why.empty()) {
    misfit_ = true;
    fail(t, why);
    return false;
  }
  return true;
}

void C1Master::begin_cycle(SimTime t) {
  cycle_start_ = t;
  sequence_ = static_cast<std::uint8_t>(cycle_ & 0xF);
  wdt_ = static_cast<std::uint8_t>((wdt_ + 1) & 0xF);
  for (auto& s : slave_) s.fresh = false;
  retry_.clear();
  retry_next_ = 0;
  poll_ = 0;
  interrupted_ = false;
  std::array<std::uint8_t, 8> sync{};
  put_u32(sync, 0, static_cast<std::uint32_t>(cycle_));
  send(FrameType::sync, kBroadcast, sync, t);
  poll_next(t + frame_slot_ns(8));
}

// The next command of this cycle (first attempts, then retries), or the wait for INT_OFFSET.
void C1Master::poll_next(SimTime t) {
  int k = -1;
  bool retry = false;
  if (poll_ < slaves()) {
    k = poll_++;
  } else if (retry_next_ < retry_.size() && static_cast<int>(retry_next_) < cfg_.retry_slots) {
    k = retry_[retry_next_++];
    retry = true;
  }
  if (k < 0) {
    pending_ = Pending{};
    wake_ = std::max(t, cycle_start_ + int_offset_);
    return;
  }
  Slave& s = slave_[static_cast<std::size_t>(k)];
  auto cmd = command(k);
  cmd[1] = static_cast<std::uint8_t>(wdt_ << 4);
  send(FrameType::cyclic_command, cfg_.slaves[static_cast<std::size_t>(k)].address, cmd, t, retry);
  if (retry) ++s.counters.retries;
  else ++s.counters.exchanges;
  pending_ = Pending{k, FrameType::cyclic_response, t, t + s.t_rsp};
  pending_retry_ = retry;
  wake_ = pending_.deadline;
}

void C1Master::close_exchange(SimTime t, bool good) {
  const int k = pending_.k;
  Slave& s = slave_[static_cast<std::size_t>(k)];
  if (good && pending_retry_) ++s.counters.retry_recovered;
  if (!good && !pending_retry_) retry_.push_back(k);
  pending_ = Pending{};
  poll_next(t + kGapNs);
}

bool C1Master::request(int k, SimTime t) {
  if (state_ != DriverState::event || k < 0 || k >= slaves() || queue_count_ == queue_.size()) return false;
  queue_[(queue_head_ + queue_count_++) % queue_.size()] = k;
  requested_at_[static_cast<std::size_t>(k)] = t;
  if (pending_.k < 0) event_next(t);
  return true;
}

// Event-driven: the next queued request goes out, one exchange on the line at a time.
void C1Master::event_next(SimTime t) {
  if (queue_count_ == 0) {
    wake_ = -1;
    return;
  }
  const int k = queue_[queue_head_];
  queue_head_ = (queue_head_ + 1) % queue_.size();
  --queue_count_;
  attempts_ = 0;
  // A sequence number of the slave's own, one on from its last request: with one count for
  // all, 16 slaves in turn would each see the same number every time, and a slave would take
  // the retry of a lost new command for a retry of its previous one.
  Slave& s = slave_[static_cast<std::size_t>(k)];
  s.sequence = static_cast<std::uint8_t>((s.sequence + 1) & 0xF);
  sequence_ = s.sequence;
  event_send(k, t, false);
}

void C1Master::event_send(int k, SimTime t, bool retry) {
  Slave& s = slave_[static_cast<std::size_t>(k)];
  s.fresh = false;
  send(FrameType::event_command, cfg_.slaves[static_cast<std::size_t>(k)].address, command(k), t, retry);
  if (retry) ++s.counters.retries;
  else ++s.counters.exchanges;
  pending_ = Pending{k, FrameType::event_response, t, t + s.t_rsp};
  pending_retry_ = retry;
  wake_ = pending_.deadline;
}

// Event-driven: the exchange in progress ended (a response, or its time limit with no retry left).
void C1Master::event_end(SimTime t, bool ok) {
  const int k = pending_.k;
  Slave& s = slave_[static_cast<std::size_t>(k)];
  if (!ok && attempts_ < cfg_.event_retries) {
    ++attempts_;
    return event_send(k, t + kGapNs, true);
  }
  if (ok && pending_retry_) ++s.counters.retry_recovered;
  if (!ok) ++s.counters.missed;
  pending_ = Pending{};
  if (event_done_) event_done_(k, ok, t - requested_at_[static_cast<std::size_t>(k)]);
  if (pending_.k < 0) event_next(t + kGapNs);
}

void C1Master::on_frame(std::span<const std::uint8_t> bytes, SimTime t) {
  FrameView v;
  const FrameStatus st = decode(bytes, v);
  const bool waiting = pending_.k >= 0 && t <= pending_.deadline;
  if (st != FrameStatus::ok) {
    // A corrupted frame while a response is awaited is that response, bad: retry it.
    if (waiting && (state_ == DriverState::cyclic || state_ == DriverState::event)) {
      ++slave_[static_cast<std::size_t>(pending_.k)].counters.bad;
      if (state_ == DriverState::event) event_end(t, false);
      else close_exchange(t, false);
    }
    return;
  }
  if (v.src == kC1Master) {  // we never hear our own frames: another C1 master sent this
    if (foreign_master_++ == 0) log(t, "another C1 master is on the line (a frame from address 01h): counted, ignored");
    return;
  }
  if (v.dst != kC1Master) return;
  const bool expected = waiting && v.type == pending_.expect &&
                        v.src == cfg_.slaves[static_cast<std::size_t>(pending_.k)].address &&
                        (state_ == DriverState::detect || state_ == DriverState::delay || v.sequence() == sequence_);
  if (!expected) {
    // A response after its T_RSP (or to an earlier cycle) is late: counted, not used.
    for (int k = 0; k < slaves(); ++k)
      if ((v.type == FrameType::cyclic_response || v.type == FrameType::event_response) &&
          cfg_.slaves[static_cast<std::size_t>(k)].address == v.src)
        ++slave_[static_cast<std::size_t>(k)].counters.late;
    return;
  }
  Slave& s = slave_[static_cast<std::size_t>(pending_.k)];
  if (state_ == DriverState::delay) s.tr_dly = t - pending_.sent - 2 * frame_time_ns(0) - kDelayEchoNs;
  if (state_ == DriverState::detect || state_ == DriverState::delay) return finish_setup_exchange(t, true);
  std::copy(v.data.begin(), v.data.end(), s.rsp.begin());
  s.fresh = true;
  if (state_ == DriverState::event) return event_end(t, true);
  close_exchange(t, true);
}

void C1Master::step(SimTime t) {
  switch (state_) {
    case DriverState::detect:
    case DriverState::delay:
      if (pending_.k >= 0) finish_setup_exchange(t, false);  // its deadline passed unanswered
      return;
    case DriverState::cyclic:
      if (pending_.k >= 0) return close_exchange(t, false);  // T_RSP over: a retry target
      if (!interrupted_) {
        interrupted_ = true;
        for (auto& s : slave_) s.counters.missed += s.fresh ? 0 : 1;
        if (interrupt_) interrupt_(cycle_, t);
        ++cycle_;
        wake_ = cycle_start_ + cfg_.cycle_ns;
        return;
      }
      return begin_cycle(t);  // wake_ was the next cycle's start
    case DriverState::event:
      if (pending_.k >= 0) return event_end(t, false);  // its time limit passed
      wake_ = -1;
      return;
    default: wake_ = -1; return;
  }
}

void C1Master::advance(SimTime t) {
  while (wake_ >= 0 && wake_ <= t) step(wake_);
}

}  // namespace omnitwin::m3
