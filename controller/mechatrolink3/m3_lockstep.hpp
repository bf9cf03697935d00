// controller/mechatrolink3 — our C1 master in exchange-level lockstep with the twin: the
// master's frames travel over a real M-III transport, its time and frame counts over the
// sim-clock channel (docs/protocols/sim-clock.md, "Inside a tick"). This is the adapter
// between the protocol core (C1Master: frames and simulated time in, frames out) and the two
// channels; the core itself never sees a socket or a clock.
//
// Per frame the core emits: send it on the transport, report it with Sent{tick, t_send,
// count} (a SYNC, which nothing answers, is reported together with the frame that follows it
// back to back: one exchange fewer per cycle), and take the twin's Horizon (what reached the master and when; nothing else before
// quiet_until), draining the transport up to the Horizon's count into an inbox. The frames in
// the inbox are handed to the core at their arrival times after the core's call returns (so
// the core is never re-entered); frames the Grant counts beyond those (another station's,
// sent outside any exchange) are handed over at the grant's instant; the core's own deadlines run in simulated time in between,
// and the tick ends when the core's next event lies beyond it. Our master polls: every Sent
// is answered by at most one frame (the response to it).
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "bus_emulators/mechatrolink3/m3_frame.hpp"
#include "bus_emulators/mechatrolink3/transport/m3_transport.hpp"
#include "controller/mechatrolink3/m3_master.hpp"
#include "controller/sim_clock.hpp"

namespace omnitwin::m3 {

class MasterLockstep {
 public:
  // The sim-clock bus slot the M-III counts travel in (Grant/Done/Sent/Horizon frames[bus]).
  MasterLockstep(M3Transport& transport, simclock::Client& clock, std::size_t bus = 0);

  // Give this to C1Master as its Emit: sends the frame and exchanges Sent/Horizon for it.
  void emit(std::span<const std::uint8_t> frame, SimTime t);
  // Runs the master's events of tick g (from g.t_ns up to g.t_ns + period, exclusive) and
  // hands it every frame the twin delivered. ok, or why the twin stopped answering.
  simclock::WaitStatus run_tick(C1Master& master, const simclock::Grant& g, SimTime period);
  // Tick g begins: what the master sends from now on (before run_tick, e.g. event-driven
  // requests at the tick's start) is reported in it.
  void begin_tick(const simclock::Grant& g) { tick_ = g.tick; }

  simclock::Client& clock() { return clock_; }
  std::uint64_t frames_sent() const { return sent_; }
  std::uint64_t frames_received() const { return received_; }

 private:
  struct Arrived {
    SimTime at = 0;
    std::uint8_t size = 0;
    std::array<std::uint8_t, kMaxFrame> bytes{};
  };
  simclock::WaitStatus drain_to(std::uint64_t count, SimTime arrival);
  void report(SimTime t);
  void deliver_inbox(C1Master& master);

  M3Transport& transport_;
  simclock::Client& clock_;
  std::size_t bus_;
  std::uint64_t tick_ = 0, sent_ = 0, received_ = 0;
  SimTime unreported_at_ = -1, unreported_slot_ = 0;  // a SYNC sent, not yet reported
  simclock::WaitStatus status_ = simclock::WaitStatus::ok;
  std::vector<Arrived> inbox_;  // reserved once; frames the twin delivered, not yet handed over
  std::array<std::uint8_t, 2 * kMaxFrame> rx_{};
};

}  // namespace omnitwin::m3
