// bus_emulators/canopen — NMT and error control (CiA 301 §7.2.8, §7.3.2): the NMT slave state
// machine, the boot-up message, the heartbeat producer, node guarding with life guarding, and
// the heartbeat consumer (used by slaves for 0x1016 and by our master for every node).
//
// Protocol cores: frames and time [ns] in, frames out through SendFn, no clock. The node
// (co_node) owns them and reads their parameters from its dictionary on every call (0x1017,
// 0x100C, 0x100D, 0x1016), so an SDO write takes effect at once, as on a real device.
// Nothing here allocates after construction; every call is real-time safe.
#pragma once

#include <array>
#include <cstdint>
#include <functional>

#include "bus_emulators/canopen/co_types.hpp"

namespace omnitwin::canopen {

// The named transitions of the NMT slave (states: NmtState). Legal in each state:
//  initialising    — transient (power-on, reset): only boot_up, which sends the boot-up
//                    message 0x700+id [00] and enters pre_operational.
//  pre_operational — SDO, SYNC, TIME, EMCY, NMT, error control; no PDOs. Legal: start, stop,
//                    reset_node, reset_communication (enter_pre_operational: no change).
//  operational     — every service. Legal: stop, enter_pre_operational, reset_*
//                    (start: no change).
//  stopped         — NMT and error control only. Legal: start, enter_pre_operational, reset_*
//                    (stop: no change).
// reset_node and reset_communication lead to initialising; the owner resets the application
// and/or the communication objects and then applies boot_up.
enum class NmtTransition : std::uint8_t {
  boot_up,                // initialising → pre_operational (boot-up message)
  start,                  // pre_operational|stopped → operational
  stop,                   // pre_operational|operational → stopped
  enter_pre_operational,  // operational|stopped → pre_operational
  reset_node,             // any → initialising (application and communication reset)
  reset_communication,    // any → initialising (communication reset)
};
const char* to_string(NmtTransition t);

// The transition an NMT command asks for.
NmtTransition transition_of(NmtCommand c);

class NmtSlave {
 public:
  explicit NmtSlave(std::uint8_t node_id) : node_id_(node_id) {}

  NmtState state() const { return state_; }
  std::uint8_t node_id() const { return node_id_; }

  // An NMT frame (COB-ID 0, 2 bytes): the command if it addresses this node (or all), else
  // nullopt-like false. A malformed NMT frame (DLC != 2, unknown specifier) is ignored.
  bool decode(const can::Frame& f, NmtTransition& out) const;
  // Applies t; false when it is not legal in the current state (state unchanged). boot_up
  // sends the boot-up message through `send`. Real-time safe.
  bool apply(NmtTransition t, SimTime now, const SendFn& send);

 private:
  std::uint8_t node_id_;
  NmtState state_ = NmtState::initialising;
};

// Error control of one node as producer: heartbeat (0x1017 > 0) or, when it is 0, node guarding
// answers with life guarding (0x100C guard time [ms] × 0x100D life time factor).
struct ErrorControlParams {
  std::uint16_t heartbeat_ms = 0;  // 0x1017
  std::uint16_t guard_time_ms = 0; // 0x100C
  std::uint8_t life_factor = 0;    // 0x100D
};

enum class LifeGuardEvent : std::uint8_t { none, lost, resumed };

class ErrorControlProducer {
 public:
  explicit ErrorControlProducer(std::uint8_t node_id) : node_id_(node_id) {}

  // Restarts the heartbeat timer (boot-up): the first heartbeat follows one period after `now`.
  void restart(SimTime now);
  // Sends the heartbeat due by `now` (one at most: a caller more than a period late gets one,
  // and the next a period later) and checks life guarding. A changed 0x1017 (also 0 → n) takes
  // effect from `now`: the next heartbeat one new period later. Returns lost when the master's
  // guarding stopped for guard time × life factor (once), resumed when it came back.
  LifeGuardEvent on_time(SimTime now, const ErrorControlParams& p, NmtState s, const SendFn& send);
  // A remote frame on 0x700+id: the guarding answer [toggle | state] (node guarding only;
  // ignored while the heartbeat runs). Returns resumed if life guarding had been lost.
  LifeGuardEvent on_guard_request(SimTime now, const ErrorControlParams& p, NmtState s, const SendFn& send);
  // NMT reset communication: toggle back to 0, guarding inactive until the first request.
  void reset(SimTime now);

  std::uint64_t heartbeats_sent() const { return heartbeats_; }
  std::uint64_t guard_answers() const { return guard_answers_; }
  bool life_guarding_lost() const { return lost_; }

 private:
  std::uint8_t node_id_;
  SimTime next_heartbeat_ = 0;
  std::uint16_t period_ms_ = 0;  // the period the timer was armed with
  bool from_restart_ = false;    // armed from the restart time, not from the first on_time
  SimTime last_guard_ = -1;      // -1: guarding not started
  bool toggle_ = false, lost_ = false;
  std::uint64_t heartbeats_ = 0, guard_answers_ = 0;
};

// Heartbeat consumer: up to kMaxConsumed monitored producers, each with its time [ms]. A
// producer is monitored from its first heartbeat on (CiA 301); its absence for longer than
// its time is one `timeout` event; its next heartbeat a `resumed` event (with its state), a
// boot-up message a `boot_up` event (the node was reset or powered up).
struct HeartbeatEvent {
  enum Kind : std::uint8_t { timeout, resumed, boot_up, state_changed } kind = timeout;
  std::uint8_t node = 0;
  NmtState state = NmtState::initialising;
  SimTime t = 0;
};

class HeartbeatConsumer {
 public:
  static constexpr int kMaxConsumed = 127;
  using EventFn = std::function<void(const HeartbeatEvent&)>;

  explicit HeartbeatConsumer(EventFn on_event) : on_event_(std::move(on_event)) {}

  // (Re)configures producer `node` with a time [ms] (0 = not monitored). Keeps its last state.
  void set(std::uint8_t node, std::uint16_t time_ms);
  // Configures from a 0x1016 entry value (node << 16 | time ms); false for a bad node ID.
  bool set_from_entry(std::uint32_t entry);
  void clear();
  // A heartbeat/boot-up frame (0x701..0x77F, 1 byte). Ignored otherwise. Real-time safe.
  void on_frame(const can::Frame& f, SimTime now);
  // Timeouts due by now. Real-time safe.
  void on_time(SimTime now);

  // The last state heard from `node` (initialising when never heard); whether it is alive.
  NmtState state(std::uint8_t node) const { return slots_[node].state; }
  bool alive(std::uint8_t node) const { return slots_[node].active && !slots_[node].timed_out; }
  bool heard(std::uint8_t node) const { return slots_[node].heard; }
  std::uint64_t timeouts() const { return timeouts_; }

 private:
  struct Slot {
    std::uint16_t time_ms = 0;
    SimTime last = 0;
    NmtState state = NmtState::initialising;
    bool active = false;     // monitored: configured and heard at least once
    bool heard = false;
    bool timed_out = false;
  };
  EventFn on_event_;
  std::array<Slot, 128> slots_{};
  std::array<std::uint8_t, kMaxConsumed> watched_{};  // the configured producers, for on_time
  int watched_n_ = 0;
  std::uint64_t timeouts_ = 0;
};

}  // namespace omnitwin::canopen
