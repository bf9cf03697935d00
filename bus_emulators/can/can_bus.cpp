// bus_emulators/can — the discrete-event CAN bus core; see can_bus.hpp for the state machines.
#include "bus_emulators/can/can_bus.hpp"

#include <algorithm>
#include <stdexcept>

#include "bus_emulators/can/can_timing.hpp"

namespace omnitwin::can {

namespace {

constexpr int kErrorFrameBits = kErrorFlagBits + kErrorDelimiterBits;  // overlapping flags
constexpr int kTxLostDetectBits = 6;  // recessive bits until receivers see a stuff error
constexpr int kIntegrationBits = 11;  // a powered-up node waits for 11 recessive bits

std::uint64_t bit_of(BusNode n) { return std::uint64_t{1} << static_cast<unsigned>(n); }

// The arbitration field as a number, most significant bit first; lower wins (0 = dominant).
// Standard: base(11) RTR IDE=0; extended: base(11) SRR=1 IDE=1 ext(18) RTR.
std::uint32_t arbitration_key(const Frame& f) {
  const std::uint32_t rtr = f.kind == FrameKind::remote ? 1u : 0u;
  if (f.extended) {
    const std::uint32_t base = (f.id >> 18) & 0x7FFu;
    return (base << 21) | (1u << 20) | (1u << 19) | ((f.id & 0x3FFFFu) << 1) | rtr;
  }
  return ((f.id & 0x7FFu) << 21) | (rtr << 20);
}

}  // namespace

CanBus::CanBus(const BusConfig& config) : config_(config) {
  if (!valid_bit_rate(config.bit_rate_bps))
    throw std::invalid_argument("CanBus: bit rate must be 10 kbit/s … 1 Mbit/s");
  if (config.queue_capacity < 1) throw std::invalid_argument("CanBus: queue_capacity < 1");
  if (config.max_nodes < 1 || config.max_nodes > 64)
    throw std::invalid_argument("CanBus: max_nodes must be 1..64");
  nodes_.reserve(static_cast<std::size_t>(config.max_nodes));
  now_ = config.start_ns;
  idle_since_ = config.start_ns;
}

std::int64_t CanBus::bit_ns(int bits) const { return bits_to_ns(bits, config_.bit_rate_bps); }

BusNode CanBus::attach(const NodeConfig& config) {
  if (static_cast<int>(nodes_.size()) >= config_.max_nodes)
    throw std::length_error("CanBus::attach: more than max_nodes nodes");
  Node n;
  n.config = config;
  n.queue.resize(static_cast<std::size_t>(config_.queue_capacity));
  n.ready_ns = now_;
  n.joined_ns = now_;
  nodes_.push_back(std::move(n));
  return static_cast<BusNode>(nodes_.size() - 1);
}

const CanBus::Node& CanBus::node(BusNode n) const {
  if (n < 0 || n >= static_cast<int>(nodes_.size()))
    throw std::out_of_range("CanBus: unknown node");
  return nodes_[static_cast<std::size_t>(n)];
}
CanBus::Node& CanBus::node(BusNode n) {
  return const_cast<Node&>(static_cast<const CanBus*>(this)->node(n));
}

ErrorState CanBus::error_state(BusNode n) const { return node(n).state; }
int CanBus::tec(BusNode n) const { return node(n).tec; }
int CanBus::rec(BusNode n) const { return node(n).rec; }
bool CanBus::powered(BusNode n) const { return node(n).powered; }
int CanBus::pending(BusNode n) const { return node(n).count; }
const NodeStats& CanBus::node_stats(BusNode n) const { return node(n).stats; }

double CanBus::bus_load(std::int64_t now_ns) const {
  const std::int64_t elapsed = now_ns - config_.start_ns;
  if (elapsed <= 0) return 0.0;
  return static_cast<double>(stats_.busy_ns) / static_cast<double>(elapsed);
}

bool CanBus::eligible(const Node& n) const {
  return n.powered && n.state != ErrorState::bus_off && n.count > 0;
}

std::int64_t CanBus::ready_time(const Node& n) const {
  return std::max(head(n).submit_ns, n.ready_ns);
}

bool CanBus::can_acknowledge(BusNode receiver, BusNode sender) const {
  const Node& r = nodes_[static_cast<std::size_t>(receiver)];
  return receiver != sender && r.powered && r.state != ErrorState::bus_off && r.config.acknowledges &&
         r.joined_ns <= frame_start_;
}

SubmitStatus CanBus::submit(BusNode id, const Frame& f, std::int64_t now_ns) {
  if (id < 0 || id >= static_cast<int>(nodes_.size())) return SubmitStatus::unknown_node;
  Node& n = nodes_[static_cast<std::size_t>(id)];
  if (f.kind == FrameKind::error || !f.valid()) {
    ++n.stats.invalid_submits;
    return SubmitStatus::invalid_frame;
  }
  if (!n.powered) return SubmitStatus::node_off;
  if (n.count == config_.queue_capacity) {
    ++n.stats.queue_overflows;
    return SubmitStatus::queue_full;
  }
  TxEntry e;
  e.frame = f;
  e.submit_ns = std::max(now_ns, now_);
  e.arbitration_key = arbitration_key(f);
  e.region_bits = stuffed_region_bits(f);
  e.frame_bits = frame_bits(f);
  const int slot = (n.head + n.count) % config_.queue_capacity;
  n.queue[static_cast<std::size_t>(slot)] = e;
  ++n.count;

  // A node that becomes ready during the SOF bit synchronises on it and joins the arbitration.
  if (n.count == 1 && phase_ == BusPhase::frame && id != tx_node_ && outcome_ != Outcome::transmitter_lost &&
      eligible(n) && ready_time(n) < frame_start_ + bit_ns(1)) {
    contenders_ |= bit_of(id);
    const bool wins = e.arbitration_key < current_.arbitration_key ||
                      (e.arbitration_key == current_.arbitration_key && id < tx_node_);
    if (wins) {
      --head(nodes_[static_cast<std::size_t>(tx_node_)]).attempts;
      tx_node_ = id;
      ++head(n).attempts;
      current_ = head(n);
      plan_frame();
    }
  }
  return SubmitStatus::queued;
}

std::int64_t CanBus::next_start_ns() const {
  if (phase_ != BusPhase::idle) return kNoEvent;
  std::int64_t earliest = kNoEvent;
  for (const Node& n : nodes_)
    if (eligible(n)) earliest = std::min(earliest, ready_time(n));
  return earliest == kNoEvent ? kNoEvent : std::max(idle_since_, earliest);
}

std::int64_t CanBus::next_recovery_ns() const {
  if (phase_ != BusPhase::idle) return kNoEvent;
  std::int64_t earliest = kNoEvent;
  for (const Node& n : nodes_) {
    if (!n.recovering || !n.recovery_started) continue;
    const std::int64_t from = std::max(idle_since_, n.recovery_begin_ns);
    const int left = kBusOffRecoverySequences - n.recovery_count;
    const std::int64_t t = from + bit_ns(kRecoverySequenceBits * std::max(left, 0));
    earliest = std::min(earliest, t);
  }
  return earliest;
}

std::int64_t CanBus::next_event_ns() const {
  switch (phase_) {
    case BusPhase::idle:
      return std::min(next_start_ns(), next_recovery_ns());
    case BusPhase::frame:
    case BusPhase::error_frame:
    case BusPhase::intermission:
      return phase_end_;
  }
  return kNoEvent;
}

void CanBus::advance(std::int64_t now_ns) {
  if (in_advance_) return;  // nested call from a callback: events up to its instant are running
  in_advance_ = true;
  struct Guard {
    bool& flag;
    ~Guard() { flag = false; }
  } guard{in_advance_};
  for (;;) {
    const std::int64_t t = next_event_ns();
    if (t == kNoEvent || t > now_ns) break;
    step(t);
  }
  now_ = std::max(now_, now_ns);
}

void CanBus::step(std::int64_t t) {
  now_ = std::max(now_, t);
  switch (phase_) {
    case BusPhase::idle:
      // A recovery that completes at the same instant as a SOF completes first.
      if (next_recovery_ns() <= next_start_ns())
        apply(Transition::recovery_complete, t);
      else
        apply(Transition::start_of_frame, t);
      return;
    case BusPhase::frame:
      apply(outcome_ == Outcome::success ? Transition::end_of_frame : Transition::error_detected, t);
      return;
    case BusPhase::error_frame:
      apply(Transition::error_frame_end, t);
      return;
    case BusPhase::intermission:
      apply(Transition::intermission_end, t);
      return;
  }
}

void CanBus::plan_frame() {
  std::uint64_t ackers = 0;
  for (std::size_t i = 0; i < nodes_.size(); ++i)
    if (can_acknowledge(static_cast<BusNode>(i), tx_node_)) ackers |= bit_of(static_cast<BusNode>(i));
  ack_set_ = ackers;
  phase_start_ = frame_start_;
  if (corrupt_remaining_ > 0 || node(tx_node_).corrupt_tx > 0) {
    // The last CRC bit is flipped: the transmitter flags from the next bit on.
    outcome_ = Outcome::bit_error;
    phase_end_ = frame_start_ + bit_ns(current_.region_bits);
  } else if (ackers == 0) {
    // Nobody drives the ACK slot dominant: the error flag starts at the ACK delimiter.
    outcome_ = Outcome::ack_error;
    phase_end_ = frame_start_ + bit_ns(current_.region_bits + 2);
  } else {
    outcome_ = Outcome::success;
    phase_end_ = frame_start_ + bit_ns(current_.frame_bits);
  }
}

void CanBus::count_arbitration_losses() {
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    const BusNode id = static_cast<BusNode>(i);
    if (id != tx_node_ && (contenders_ & bit_of(id)) && nodes_[i].powered) ++nodes_[i].stats.arbitration_lost;
  }
  contenders_ = 0;
}

void CanBus::count_idle_recovery(std::int64_t t) {
  // A SOF ends the idle stretch: every complete 11 recessive bits of it counted.
  const std::int64_t seq_ns = bit_ns(kRecoverySequenceBits);
  for (Node& n : nodes_) {
    if (!n.recovering || !n.recovery_started) continue;
    const std::int64_t from = std::max(idle_since_, n.recovery_begin_ns);
    if (t <= from) continue;
    const std::int64_t k = (t - from) / seq_ns;
    const int left = kBusOffRecoverySequences - n.recovery_count;
    n.recovery_count += static_cast<int>(std::min<std::int64_t>(k, left));
  }
}

void CanBus::emit(BusEventKind kind, BusNode n, std::int64_t t, ErrorCause cause) {
  if (!event_) return;
  BusEvent e;
  e.kind = kind;
  e.node = n;
  e.t_ns = t;
  e.state = nodes_[static_cast<std::size_t>(n)].state;
  e.cause = cause;
  if (kind == BusEventKind::error_frame) e.frame = current_.frame;
  event_(e);
}

void CanBus::apply(Transition tr, std::int64_t t) {
  switch (tr) {
    case Transition::start_of_frame: {  // idle → frame
      count_idle_recovery(t);
      frame_start_ = t;
      phase_ = BusPhase::frame;
      contenders_ = 0;
      const std::int64_t window_end = t + bit_ns(1);
      BusNode best = -1;
      for (std::size_t i = 0; i < nodes_.size(); ++i) {
        const Node& n = nodes_[i];
        if (!eligible(n) || ready_time(n) >= window_end) continue;
        const BusNode id = static_cast<BusNode>(i);
        contenders_ |= bit_of(id);
        if (best < 0 || head(n).arbitration_key < head(nodes_[static_cast<std::size_t>(best)]).arbitration_key)
          best = id;
      }
      tx_node_ = best;  // next_start_ns() guarantees at least one contender
      Node& w = nodes_[static_cast<std::size_t>(best)];
      ++head(w).attempts;
      current_ = head(w);
      plan_frame();
      return;
    }
    case Transition::end_of_frame: {  // frame → intermission, frame delivered
      count_arbitration_losses();
      Node& tx = nodes_[static_cast<std::size_t>(tx_node_)];
      tx.head = (tx.head + 1) % config_.queue_capacity;
      --tx.count;
      ++stats_.frames;
      stats_.busy_ns += t - phase_start_;
      ++tx.stats.tx_frames;
      apply_node(tx_node_, NodeTransition::tx_success, t);
      std::uint64_t receivers = 0;
      for (std::size_t i = 0; i < nodes_.size(); ++i) {
        Node& r = nodes_[i];
        const BusNode id = static_cast<BusNode>(i);
        if (id == tx_node_ || !r.powered || r.state == ErrorState::bus_off || r.joined_ns > frame_start_) continue;
        receivers |= bit_of(id);
        ++r.stats.rx_frames;
        if (r.config.acknowledges) apply_node(id, NodeTransition::rx_success, t);
      }
      if (tx.state == ErrorState::error_passive)
        tx.ready_ns = std::max(tx.ready_ns, t + bit_ns(kIntermissionBits + kSuspendTransmissionBits));
      phase_ = BusPhase::intermission;
      phase_start_ = t;
      phase_end_ = t + bit_ns(kIntermissionBits);
      const BusNode sender = tx_node_;
      const Frame frame = current_.frame;
      FrameTiming timing;
      timing.sender = sender;
      timing.submit_ns = current_.submit_ns;
      timing.sof_ns = frame_start_;
      timing.end_ns = t;
      timing.attempts = current_.attempts;
      if (deliver_)
        for (std::size_t i = 0; i < nodes_.size(); ++i)
          if (receivers & bit_of(static_cast<BusNode>(i))) deliver_(static_cast<BusNode>(i), frame, timing);
      if (tx_done_) tx_done_(sender, frame, timing);
      return;
    }
    case Transition::error_detected: {  // frame → error_frame
      count_arbitration_losses();
      ++stats_.error_frames;
      stats_.busy_ns += t - phase_start_;
      Node& tx = nodes_[static_cast<std::size_t>(tx_node_)];
      ErrorCause cause = ErrorCause::ack;
      bool receivers_flag = false;
      switch (outcome_) {
        case Outcome::ack_error:
          cause = ErrorCause::ack;
          ++tx.stats.tx_errors;
          ++tx.stats.ack_errors;
          apply_node(tx_node_, tx.state == ErrorState::error_passive ? NodeTransition::tx_ack_error_unanswered
                                                                     : NodeTransition::tx_error,
                     t);
          break;
        case Outcome::bit_error:
          cause = ErrorCause::bit;
          // A corruption aimed at this transmitter is used up before a bus-wide one.
          if (tx.corrupt_tx > 0) {
            --tx.corrupt_tx;
          } else if (corrupt_remaining_ > 0) {
            --corrupt_remaining_;
          }
          ++tx.stats.tx_errors;
          apply_node(tx_node_, NodeTransition::tx_error, t);
          receivers_flag = true;
          break;
        case Outcome::transmitter_lost:
          cause = ErrorCause::transmitter_lost;
          receivers_flag = true;
          break;
        case Outcome::success:
          break;  // not reached: success ends with end_of_frame
      }
      if (receivers_flag)
        for (std::size_t i = 0; i < nodes_.size(); ++i) {
          const BusNode id = static_cast<BusNode>(i);
          if (!can_acknowledge(id, tx_node_)) continue;
          ++nodes_[i].stats.rx_errors;
          apply_node(id, NodeTransition::rx_error, t);
        }
      if (outcome_ != Outcome::transmitter_lost && tx.powered && tx.state == ErrorState::error_passive)
        tx.ready_ns = std::max(tx.ready_ns,
                               t + bit_ns(kErrorFrameBits + kIntermissionBits + kSuspendTransmissionBits));
      phase_ = BusPhase::error_frame;
      phase_start_ = t;
      phase_end_ = t + bit_ns(kErrorFrameBits);
      emit(BusEventKind::error_frame, tx_node_, t, cause);
      return;
    }
    case Transition::error_frame_end:  // error_frame → intermission
      stats_.busy_ns += t - phase_start_;
      phase_ = BusPhase::intermission;
      phase_start_ = t;
      phase_end_ = t + bit_ns(kIntermissionBits);
      return;
    case Transition::intermission_end: {  // intermission → idle
      stats_.busy_ns += t - phase_start_;
      phase_ = BusPhase::idle;
      idle_since_ = t;
      tx_node_ = -1;
      // Every frame and error frame ends with 11 recessive bits: one recovery sequence.
      for (std::size_t i = 0; i < nodes_.size(); ++i) {
        Node& n = nodes_[i];
        if (!n.recovering) continue;
        if (!n.recovery_started) {
          n.recovery_started = true;
          n.recovery_begin_ns = t;
          continue;
        }
        ++n.recovery_count;
        if (n.recovery_count >= kBusOffRecoverySequences)
          apply_node(static_cast<BusNode>(i), NodeTransition::recovery_complete, t);
      }
      return;
    }
    case Transition::recovery_complete: {  // idle → idle, a bus-off node's sequence done
      for (std::size_t i = 0; i < nodes_.size(); ++i) {
        Node& n = nodes_[i];
        if (!n.recovering || !n.recovery_started) continue;
        const std::int64_t from = std::max(idle_since_, n.recovery_begin_ns);
        const int left = kBusOffRecoverySequences - n.recovery_count;
        if (from + bit_ns(kRecoverySequenceBits * left) > t) continue;
        apply_node(static_cast<BusNode>(i), NodeTransition::recovery_complete, t);
      }
      return;
    }
  }
}

void CanBus::apply_node(BusNode id, NodeTransition tr, std::int64_t t) {
  Node& n = nodes_[static_cast<std::size_t>(id)];
  const ErrorState before = n.state;
  bool leaves_bus_off = false;
  switch (tr) {
    case NodeTransition::tx_success:
      if (n.tec > 0) --n.tec;
      break;
    case NodeTransition::rx_success:
      if (n.rec > 127)
        n.rec = 119;
      else if (n.rec > 0)
        --n.rec;
      break;
    case NodeTransition::tx_error:
      n.tec += 8;
      break;
    case NodeTransition::tx_ack_error_unanswered:
      break;  // ISO 11898-1 exception: passive transmitter, ACK error, no dominant bit seen
    case NodeTransition::rx_error:
      ++n.rec;
      break;
    case NodeTransition::recovery_complete:
      n.clear_errors();
      n.ready_ns = std::max(n.ready_ns, t);
      ++n.stats.recoveries;
      leaves_bus_off = true;
      break;
    case NodeTransition::power_on:
      n.clear_errors();
      leaves_bus_off = true;
      break;
  }
  if (n.state == ErrorState::bus_off && !leaves_bus_off) {
    // bus-off is left only by recovery or a power cycle
  } else if (n.tec > 255) {
    n.state = ErrorState::bus_off;
    ++n.stats.bus_off_events;
    n.recovering = false;
  } else if (n.tec > 127 || n.rec > 127) {
    n.state = ErrorState::error_passive;
  } else {
    n.state = ErrorState::error_active;
  }
  if (tr == NodeTransition::recovery_complete) emit(BusEventKind::recovery_complete, id, t);
  if (n.state != before) emit(BusEventKind::state_changed, id, t);
}

bool CanBus::detach(BusNode id, std::int64_t now_ns) {
  if (id < 0 || id >= static_cast<int>(nodes_.size()) || !nodes_[static_cast<std::size_t>(id)].powered)
    return false;
  advance(now_ns);
  const std::int64_t t = std::max(now_ns, now_);
  Node& n = nodes_[static_cast<std::size_t>(id)];
  n.powered = false;
  n.head = 0;
  n.count = 0;
  n.corrupt_tx = 0;
  n.recovering = false;
  n.recovery_started = false;
  contenders_ &= ~bit_of(id);
  if (phase_ == BusPhase::frame && tx_node_ == id && outcome_ != Outcome::transmitter_lost) {
    // The wire goes recessive; receivers see a stuff error within six bits.
    const std::int64_t one = bit_ns(1);
    const std::int64_t bits_done = (t - frame_start_ + one - 1) / one;
    outcome_ = Outcome::transmitter_lost;
    phase_end_ = frame_start_ + bit_ns(static_cast<int>(bits_done) + kTxLostDetectBits);
  }
  return true;
}

bool CanBus::reattach(BusNode id, std::int64_t now_ns) {
  if (id < 0 || id >= static_cast<int>(nodes_.size()) || nodes_[static_cast<std::size_t>(id)].powered)
    return false;
  advance(now_ns);
  const std::int64_t t = std::max(now_ns, now_);
  Node& n = nodes_[static_cast<std::size_t>(id)];
  n.powered = true;
  n.joined_ns = t;
  n.ready_ns = t + bit_ns(kIntegrationBits);
  apply_node(id, NodeTransition::power_on, t);
  return true;
}

bool CanBus::corrupt_frames_of(BusNode id, int count) {
  if (id < 0 || id >= static_cast<int>(nodes_.size())) return false;
  nodes_[static_cast<std::size_t>(id)].corrupt_tx += count;
  return true;
}

bool CanBus::clear_corruptions_of(BusNode id) {
  if (id < 0 || id >= static_cast<int>(nodes_.size())) return false;
  nodes_[static_cast<std::size_t>(id)].corrupt_tx = 0;
  return true;
}

bool CanBus::request_recovery(BusNode id, std::int64_t now_ns) {
  if (id < 0 || id >= static_cast<int>(nodes_.size())) return false;
  if (nodes_[static_cast<std::size_t>(id)].state != ErrorState::bus_off ||
      !nodes_[static_cast<std::size_t>(id)].powered)
    return false;
  advance(now_ns);
  Node& n = nodes_[static_cast<std::size_t>(id)];
  if (n.recovering) return true;
  const std::int64_t t = std::max(now_ns, now_);
  n.recovering = true;
  n.recovery_count = 0;
  n.recovery_started = phase_ == BusPhase::idle;
  n.recovery_begin_ns = t;
  return true;
}

}  // namespace omnitwin::can
