// bus_emulators/ethercat — a line of ESCs: what one frame does on its way through the segment.
//
// Slaves are in wire order; the frame enters slave 0 on port 0, leaves on port 1 to the next,
// and the last reachable slave (port 1 closed) sends it back through every earlier slave to the
// master. Timing: the frame reaches slave i at a_i = t + Σ_{j<i} forward_delay_j (every datagram
// of the frame is processed at a_i); on the way back it reaches slave i's port 1 at r_i = x_{i+1}
// where x_k = (k last ? a_k : r_k) + forward_delay_k; it is back at the master at x_0. These are
// the times the DC receive-time latches (BWR 0x0900) record, so a master computes propagation
// delays from them as on a real segment.
//
// Faults: set_link_break(k) cuts the cable in front of slave k (slaves k… unreachable, the frame
// returns from k − 1; k = 0: nothing returns); set_powered(i, false) has the same effect at i and
// the slave restarts in its power-on state when powered again. DL status (0x0110) follows the
// links of every slave. No sockets, no clock.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "bus_emulators/ethercat/ec_esc.hpp"

namespace omnitwin::ethercat {

class EscChain {
 public:
  struct Stats {
    std::uint64_t frames = 0, returned = 0, malformed = 0, datagrams = 0;
  };

  void add(Esc* esc);  // in wire order; sets DL status of the line (set-up only: allocates)
  // Processes every datagram of the PDU as the frame passes slave i at a_i. Returns false when
  // the frame does not come back (malformed PDU, link broken before slave 0). RT-safe.
  bool process(std::span<std::uint8_t> pdu, SimTime t) noexcept;
  void advance(SimTime t) noexcept;
  SimTime next_event_time() const noexcept;  // earliest of the powered slaves' (kNoEscEvent: none)
  void set_link_break(int after);  // -1: intact; k: slaves k.. unreachable (frame returns from k-1)
  void set_powered(int i, bool on, SimTime t);
  bool powered(int i) const { return powered_[static_cast<std::size_t>(i)]; }
  int size() const { return static_cast<int>(escs_.size()); }
  int reachable() const;                              // slaves the frame reaches
  Esc& esc(int i) { return *escs_[static_cast<std::size_t>(i)]; }
  SimTime last_return_time() const { return last_return_; }  // frame back at the master
  // The working counter of the process data (logical datagrams: LRD, LWR, LRW, summed) in the
  // last returned frame that carried any, as a master checks it; -1 before the first.
  std::int32_t last_process_wkc() const { return last_process_wkc_; }
  const Stats& stats() const { return stats_; }

 private:
  void update_links();
  void note_process_wkc(const PduView& v) noexcept;
  bool cable_ok(int c) const;  // cable in front of slave c

  std::vector<Esc*> escs_;
  std::vector<bool> powered_;
  std::vector<SimTime> arrive_;
  int break_at_ = -1;
  SimTime last_return_ = 0;
  std::int32_t last_process_wkc_ = -1;
  Stats stats_;
};

}  // namespace omnitwin::ethercat
