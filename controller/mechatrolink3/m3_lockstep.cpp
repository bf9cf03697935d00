// controller/mechatrolink3 — our C1 master in exchange-level lockstep; see m3_lockstep.hpp.
#include "controller/mechatrolink3/m3_lockstep.hpp"

#include "bus_emulators/mechatrolink3/m3_wire.hpp"

#include <algorithm>
#include <chrono>

namespace omnitwin::m3 {

namespace {

constexpr auto kWait = std::chrono::milliseconds(10'000);  // the twin answers each exchange within

}  // namespace

MasterLockstep::MasterLockstep(M3Transport& transport, simclock::Client& clock, std::size_t bus)
    : transport_(transport), clock_(clock), bus_(bus) {
  inbox_.reserve(8);
}

void MasterLockstep::emit(std::span<const std::uint8_t> frame, SimTime t) {
  if (status_ != simclock::WaitStatus::ok) return;  // the twin is gone: nothing more to say
  // A SYNC waiting to be reported goes alone unless this frame follows it back to back.
  if (unreported_at_ >= 0 && t != unreported_at_ + unreported_slot_) report(unreported_at_);
  if (transport_.send(frame)) ++sent_;
  // A SYNC has no answer: it is reported with the frame that follows it back to back (the
  // first command), one exchange fewer per cycle, or on its own at the end of the tick.
  if (frame.size() > kHeaderSize + kFcsSize && frame[3] == static_cast<std::uint8_t>(FrameType::sync)) {
    unreported_at_ = t;
    unreported_slot_ = frame_slot_ns(frame.size() - kHeaderSize - kFcsSize);
    return;
  }
  report(t);
}

// Sent for every frame so far, the last starting at t; the Horizon's frames into the inbox.
void MasterLockstep::report(SimTime t) {
  unreported_at_ = -1;
  simclock::Sent s;
  s.tick = tick_;
  s.t_ns = t;
  s.frames[bus_] = sent_;
  simclock::Horizon h;
  status_ = clock_.exchange(s, h, kWait);
  if (status_ == simclock::WaitStatus::ok) status_ = drain_to(h.frames[bus_], h.arrival_ns);
}

// Receives from the transport until `count` frames have arrived since the start, each put in
// the inbox at `arrival` (our master polls: one frame per exchange at most).
simclock::WaitStatus MasterLockstep::drain_to(std::uint64_t count, SimTime arrival) {
  while (received_ < count) {
    const int n = transport_.receive(rx_, std::chrono::duration_cast<std::chrono::nanoseconds>(kWait));
    if (n <= 0) return simclock::WaitStatus::timeout;
    ++received_;
    Arrived a;
    a.at = arrival;
    a.size = static_cast<std::uint8_t>(std::min<int>(n, static_cast<int>(kMaxFrame)));
    std::copy_n(rx_.begin(), a.size, a.bytes.begin());
    inbox_.push_back(a);
  }
  return simclock::WaitStatus::ok;
}

// Hands the inbox to the master in order, its clock first run to each frame's arrival.
void MasterLockstep::deliver_inbox(C1Master& master) {
  while (!inbox_.empty()) {
    const Arrived a = inbox_.front();
    inbox_.erase(inbox_.begin());
    master.advance(a.at);  // a deadline at or before the arrival comes first
    master.on_frame(std::span<const std::uint8_t>(a.bytes.data(), a.size), a.at);
  }
}

simclock::WaitStatus MasterLockstep::run_tick(C1Master& master, const simclock::Grant& g, SimTime period) {
  tick_ = g.tick;
  const SimTime end = g.t_ns + period;
  // Frames the twin sent outside an exchange (another station on the line) arrive at the grant.
  if (status_ == simclock::WaitStatus::ok && received_ < g.frames[bus_]) status_ = drain_to(g.frames[bus_], g.t_ns);
  master.advance(g.t_ns);
  for (;;) {
    deliver_inbox(master);
    if (status_ != simclock::WaitStatus::ok) return status_;
    if (!inbox_.empty()) continue;  // delivering made the master send again
    const SimTime next = master.next_wakeup();
    if (next < 0 || next >= end) {
      if (unreported_at_ < 0 || status_ != simclock::WaitStatus::ok) return status_;
      report(unreported_at_);  // a SYNC nothing followed within the tick
      continue;
    }
    master.advance(next);  // a deadline or the next frame to send, in simulated time
  }
}

}  // namespace omnitwin::m3
