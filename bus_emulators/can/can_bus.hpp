// bus_emulators/can — the discrete-event CAN bus core: arbitration, frame timing, ACK, error
// confinement and fault injection for one classic-CAN bus. No sockets, no clock: time comes
// in as integer nanoseconds (the twin's timeline), frames go out through callbacks.
//
// Use: attach nodes at set-up; submit(node, frame, now) queues a frame in that node's FIFO
// transmit queue; the owner (the twin's scheduler) calls advance(now) whenever now reaches
// next_event_ns(). advance() runs every bus event with time <= now in time order and calls
// the delivery / transmit-done / event callbacks with each event's own time.
//
// Bus state machine (one per bus; transitions applied in CanBus::apply, one flat switch):
//   idle          no bits on the wire since idle_since. Legal: start_of_frame (at
//                 max(idle_since, earliest ready head); arbitration among every eligible
//                 node whose head is ready before the end of the SOF bit: lower arbitration
//                 field wins bitwise, i.e. lower identifier, a standard frame before an
//                 extended one with the same base id, data before remote), recovery_complete
//                 (a bus-off node that has seen 128 × 11 recessive bits).
//   frame         SOF … the winner's frame. Legal: end_of_frame (EOF done, acknowledged:
//                 delivered to every other powered, not-bus-off node), error_detected
//                 (ACK error: no other node able to acknowledge; bit error: injected
//                 corruption; transmitter lost power). A submit during the SOF bit may still
//                 join (and win) the arbitration.
//   error_frame   error flag (6) + error delimiter (8). Legal: error_frame_end.
//   intermission  3 recessive bits. Legal: intermission_end (→ idle).
// The winner's frame stays at the head of its queue until it is sent without error; losers
// and failed frames retry at the next idle.
//
// Node error confinement (one per node; CanBus::apply_node, one flat switch):
//   error_active   TEC <= 127 and REC <= 127: sends active error flags.
//   error_passive  TEC > 127 or REC > 127: after every frame it transmitted it waits 8 more
//                  recessive bits (suspend transmission) after the intermission before it
//                  may start again; it still receives and acknowledges.
//   bus_off        TEC > 255: does not transmit, receive or acknowledge; its queue is kept.
//                  Leaves only by request_recovery() followed by 128 occurrences of 11
//                  consecutive recessive bits (each frame or error frame ends with exactly
//                  11: ACK delimiter + EOF + intermission, or error delimiter + intermission;
//                  idle time counts 11 bits at a time; counting starts at the first idle
//                  instant after the request), or by a power cycle (detach + reattach).
//   Counters: transmit error +8 (exception: an error-passive transmitter's ACK error on a
//   bus where nobody answers with a dominant bit leaves TEC unchanged, so a lone node stays
//   error passive at TEC 128 and keeps retrying), receive error +1, successful transmission
//   TEC −1, successful reception REC −1 (a REC above 127 drops to 119).
//
// Simplifications (documented model choices): the ACK decision is taken at SOF from the set
// of nodes attached then; an injected corruption flips the last CRC bit: the transmitter
// sees a bit error, every receiver a CRC error, and all error flags overlap (6 + 8 bits);
// a transmitter that loses power mid-frame is noticed 6 bits later (stuff error); two nodes
// sending identical arbitration fields are resolved by attach order (a real bus would see a
// bit error later if their data differed); a reattached node may transmit after 11 bits.
//
// Fixed configuration (BusConfig, NodeConfig) is set at construction/attach; everything else
// is changing state. attach() allocates (set-up only); submit(), advance(), next_event_ns()
// and the fault hooks are allocation-free and real-time safe (callbacks excepted).
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <vector>

#include "bus_emulators/can/can_bits.hpp"
#include "bus_emulators/can/can_frame.hpp"

namespace omnitwin::can {

using BusNode = int;  // 0, 1, 2 … in attach order

inline constexpr std::int64_t kNoEvent = std::numeric_limits<std::int64_t>::max();  // [ns]

enum class ErrorState : std::uint8_t { error_active, error_passive, bus_off };

enum class SubmitStatus : std::uint8_t {
  queued,
  queue_full,     // the node's transmit queue is full: frame dropped, counted
  invalid_frame,  // !Frame::valid() or an error frame: rejected, counted
  node_off,       // the node is detached (powered off)
  unknown_node,
};

enum class BusPhase : std::uint8_t { idle, frame, error_frame, intermission };

enum class ErrorCause : std::uint8_t { ack, bit, transmitter_lost };

struct BusConfig {
  std::int64_t bit_rate_bps = 1'000'000;  // 10 kbit/s … 1 Mbit/s
  int queue_capacity = 32;                // frames per node transmit queue
  int max_nodes = 16;                     // at most 64
  std::int64_t start_ns = 0;              // the bus's time origin (for bus load)
};

struct NodeConfig {
  bool acknowledges = true;  // false: listen-only (receives; never ACKs, never flags errors)
};

struct NodeStats {
  std::uint64_t tx_frames = 0;         // frames sent without error
  std::uint64_t rx_frames = 0;         // frames received
  std::uint64_t arbitration_lost = 0;  // arbitrations taken part in and lost
  std::uint64_t tx_errors = 0;         // transmissions ended by an error frame (any cause)
  std::uint64_t ack_errors = 0;        // of which ACK errors
  std::uint64_t rx_errors = 0;         // error frames seen as a receiver
  std::uint64_t queue_overflows = 0;   // submits refused: queue full
  std::uint64_t invalid_submits = 0;   // submits refused: invalid frame
  std::uint64_t bus_off_events = 0;
  std::uint64_t recoveries = 0;        // bus-off recoveries completed
};

struct BusStats {
  std::uint64_t frames = 0;        // frames completed without error
  std::uint64_t error_frames = 0;  // error frames on the bus
  std::int64_t busy_ns = 0;        // frames, error frames and intermissions [ns]
};

// Timing of one transmitted frame [ns, absolute]: T_wait of eq. 2-1 is sof_ns − submit_ns.
struct FrameTiming {
  BusNode sender = -1;
  std::int64_t submit_ns = 0;  // when it was queued
  std::int64_t sof_ns = 0;     // start of the successful attempt
  std::int64_t end_ns = 0;     // end of EOF: delivery time
  int attempts = 0;            // arbitrations won (1 = sent at the first try)
};

enum class BusEventKind : std::uint8_t {
  error_frame,        // node = the transmitter, cause set, frame = the failed frame
  state_changed,      // node's error state is now `state`
  recovery_complete,  // node left bus-off after its recovery sequence
};

struct BusEvent {
  BusEventKind kind = BusEventKind::error_frame;
  BusNode node = -1;
  std::int64_t t_ns = 0;
  ErrorState state = ErrorState::error_active;
  ErrorCause cause = ErrorCause::ack;
  Frame frame{};
};

class CanBus {
 public:
  using DeliverFn = std::function<void(BusNode receiver, const Frame&, const FrameTiming&)>;
  using TxDoneFn = std::function<void(BusNode sender, const Frame&, const FrameTiming&)>;
  using EventFn = std::function<void(const BusEvent&)>;

  // Throws std::invalid_argument for a bit rate outside 10 kbit/s … 1 Mbit/s, a queue
  // capacity < 1 or max_nodes outside 1..64 (set-up).
  explicit CanBus(const BusConfig& config = {});

  // Callbacks, set at set-up. Deliver: once per receiving node at end of EOF; tx done: to the
  // sender at the same instant (after the deliveries); event: errors and state changes.
  // Callbacks may call submit(); they must not call advance() (ignored when nested).
  void on_deliver(DeliverFn fn) { deliver_ = std::move(fn); }
  void on_tx_done(TxDoneFn fn) { tx_done_ = std::move(fn); }
  void on_event(EventFn fn) { event_ = std::move(fn); }

  // Attaches (powers) a new node, error active with empty queue. Allocates its queue: not
  // real-time safe. Throws std::length_error past max_nodes.
  BusNode attach(const NodeConfig& config = {});

  // Queues `f` at the end of `node`'s transmit queue at `now_ns` (clamped to the bus's own
  // time). Does not run events. Real-time safe.
  SubmitStatus submit(BusNode node, const Frame& f, std::int64_t now_ns);

  // Runs every bus event with time <= now_ns in time order [ns]. Real-time safe apart from
  // what the callbacks do.
  void advance(std::int64_t now_ns);
  // Time of the next bus event [ns], or kNoEvent when nothing is pending. Real-time safe.
  std::int64_t next_event_ns() const;

  // --- fault injection (scenario faults and tests) ---
  // The next `count` transmissions that start are corrupted (a bit error seen by all →
  // error frame, retransmission). Real-time safe.
  void corrupt_next_frames(int count) { corrupt_remaining_ += count; }
  int corruptions_pending() const { return corrupt_remaining_; }
  // The next `count` transmissions of `node` are corrupted (a faulty transceiver or wiring at
  // that node): 32 in a row take an error-active node to bus-off. Returns false for an
  // unknown node. Real-time safe.
  bool corrupt_frames_of(BusNode node, int count);
  // Drops the node's corruptions still pending (the end of a bus_off fault whose node did not
  // use them all, e.g. it was off the bus). Returns false for an unknown node. Real-time safe.
  bool clear_corruptions_of(BusNode node);
  // Power loss: runs events up to now_ns, then the node stops: its queue is emptied, it no
  // longer receives or acknowledges; a frame it was sending is cut off (receivers see an
  // error frame). Returns false if it was already off or is unknown. Real-time safe.
  bool detach(BusNode node, std::int64_t now_ns);
  // Power return: runs events up to now_ns, then a power-on reset (error active, counters 0,
  // empty queue); it receives frames that start from now and may transmit 11 bits later.
  bool reattach(BusNode node, std::int64_t now_ns);
  // Bus-off recovery request (ISO 11898-1: recovery needs a request and 128 × 11 recessive
  // bits). Runs events up to now_ns. Returns false unless the node is bus-off.
  bool request_recovery(BusNode node, std::int64_t now_ns);

  // --- state and statistics (real-time safe; an unknown node throws std::out_of_range) ---
  ErrorState error_state(BusNode node) const;
  int tec(BusNode node) const;
  int rec(BusNode node) const;
  bool powered(BusNode node) const;
  int pending(BusNode node) const;  // frames in the node's transmit queue
  const NodeStats& node_stats(BusNode node) const;
  const BusStats& stats() const { return stats_; }
  // Busy time over elapsed time since config.start_ns, 0…1 (completed bus activity only).
  double bus_load(std::int64_t now_ns) const;
  BusPhase phase() const { return phase_; }
  int node_count() const { return static_cast<int>(nodes_.size()); }
  const BusConfig& config() const { return config_; }
  std::int64_t bit_ns(int bits) const;  // duration of `bits` bit times [ns]

 private:
  struct TxEntry {
    Frame frame{};
    std::int64_t submit_ns = 0;
    std::uint32_t arbitration_key = 0;  // lower wins
    int region_bits = 0;                // stuffed SOF … CRC
    int frame_bits = 0;                 // SOF … EOF
    int attempts = 0;
  };
  struct Node {
    NodeConfig config{};
    bool powered = true;
    std::vector<TxEntry> queue;  // ring buffer, fixed capacity
    int head = 0;
    int count = 0;
    int tec = 0;
    int rec = 0;
    ErrorState state = ErrorState::error_active;
    std::int64_t ready_ns = 0;       // earliest SOF (suspend transmission, integration)
    std::int64_t joined_ns = 0;      // receives frames starting at or after this
    bool recovering = false;
    bool recovery_started = false;   // counting began (at an idle instant)
    std::int64_t recovery_begin_ns = 0;
    int recovery_count = 0;          // occurrences of 11 recessive bits seen
    int corrupt_tx = 0;              // own transmissions still to corrupt (fault injection)
    NodeStats stats{};

    // Back to a fresh controller's error state (recovery done, or power returning).
    void clear_errors() {
      tec = 0;
      rec = 0;
      recovering = false;
      recovery_started = false;
      recovery_count = 0;
    }
  };
  enum class Transition : std::uint8_t {
    start_of_frame,
    end_of_frame,
    error_detected,
    error_frame_end,
    intermission_end,
    recovery_complete,
  };
  enum class NodeTransition : std::uint8_t {
    tx_success,
    rx_success,
    tx_error,
    tx_ack_error_unanswered,
    rx_error,
    recovery_complete,
    power_on,
  };
  enum class Outcome : std::uint8_t { success, ack_error, bit_error, transmitter_lost };

  void apply(Transition tr, std::int64_t t);
  void apply_node(BusNode n, NodeTransition tr, std::int64_t t);
  void step(std::int64_t t);
  void run_until(std::int64_t now_ns);
  void plan_frame();
  void start_frame(std::int64_t t);
  void count_arbitration_losses();
  void count_idle_recovery(std::int64_t t);
  bool eligible(const Node& n) const;
  std::int64_t ready_time(const Node& n) const;
  std::int64_t next_start_ns() const;
  std::int64_t next_recovery_ns() const;
  bool can_acknowledge(BusNode receiver, BusNode sender) const;
  const Node& node(BusNode n) const;
  Node& node(BusNode n);
  TxEntry& head(Node& n) { return n.queue[static_cast<std::size_t>(n.head)]; }
  const TxEntry& head(const Node& n) const { return n.queue[static_cast<std::size_t>(n.head)]; }
  void emit(BusEventKind kind, BusNode n, std::int64_t t, ErrorCause cause = ErrorCause::ack);

  BusConfig config_;
  std::vector<Node> nodes_;
  DeliverFn deliver_;
  TxDoneFn tx_done_;
  EventFn event_;

  BusPhase phase_ = BusPhase::idle;
  std::int64_t now_ = 0;            // time of the last event run [ns]
  std::int64_t idle_since_ = 0;     // valid in idle
  std::int64_t phase_start_ = 0;    // start of the current non-idle phase
  std::int64_t phase_end_ = 0;      // end of the current non-idle phase
  std::int64_t frame_start_ = 0;    // SOF of the current / last frame
  BusNode tx_node_ = -1;
  TxEntry current_{};               // copy of the frame on the wire
  Outcome outcome_ = Outcome::success;
  std::uint64_t contenders_ = 0;    // bit per node that took part in this arbitration
  std::uint64_t ack_set_ = 0;       // nodes able to acknowledge at SOF
  int corrupt_remaining_ = 0;
  bool in_advance_ = false;
  BusStats stats_{};
};

}  // namespace omnitwin::can
