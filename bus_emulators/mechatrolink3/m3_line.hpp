// bus_emulators/mechatrolink3 — the line between the C1 master and its slaves, in process:
// frames in flight on the simulated timeline. A frame that starts leaving a station at
// t_start reaches the other end at t_start + the one-way delay of m3_wire (cables, stations
// or hub passed) + its own frame time, i.e. when its last bit has arrived (cut-through).
// Broadcast frames reach every slave; a unicast frame only the slave it names (the others
// pass it on without reading it); a slave's frame reaches the master.
//
// No sockets, no clock: the owner calls advance(t) up to the next due time (next_due()) and
// the line calls the stations' receive callbacks in time order (ties in sending order).
// Frames are copied into a queue sized at construction, so the cyclic path does not
// allocate; a full queue drops the frame and counts it. Slave k has address kFirstSlave + k.
// A fault hook may drop or corrupt a frame on its way (a frame's fate is decided when sent).
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "bus_emulators/mechatrolink3/m3_wire.hpp"

namespace omnitwin::m3 {

// What happens to one frame on the line.
enum class Fate : std::uint8_t { deliver, drop, corrupt };

class Line {
 public:
  using Receive = std::function<void(std::span<const std::uint8_t>, SimTime)>;
  // (from_master, slave index or -1 for the master's side, bytes) → its fate.
  using FaultHook = std::function<Fate(bool from_master, int slave, std::span<const std::uint8_t>)>;

  // Throws std::invalid_argument for a topology check() refuses (programmer error).
  explicit Line(const Topology& topology, std::size_t queue_capacity = 0);

  void attach_master(Receive r) { master_ = std::move(r); }
  void attach_slave(int k, Receive r) { slaves_.at(static_cast<std::size_t>(k)) = std::move(r); }
  void set_fault_hook(FaultHook h) { fault_ = std::move(h); }
  // A slave off the line (power lost, cable cut): frames to it and from it vanish. Real-time safe.
  void set_reachable(int k, bool reachable) { reachable_.at(static_cast<std::size_t>(k)) = reachable; }
  // Cascade: the cable after slave `after` (0-based; -1: between the master and slave 0) is
  // cut, so every slave behind it is off the line; mend_cable() puts them back. Star: only
  // that slave's own cable. Real-time safe.
  void cut_cable(int after);
  void mend_cable();
  // Fault injection: frames from slave k reach the master `extra_ns` later (a slow station or
  // repeater: a response later than T_RSP). 0 restores the wire's own delay. Real-time safe.
  void set_extra_delay(int k, SimTime extra_ns) { extra_.at(static_cast<std::size_t>(k)) = extra_ns; }

  // Frames entering the line at t_start [ns] (first bit). Real-time safe.
  void from_master(std::span<const std::uint8_t> frame, SimTime t_start);
  void from_slave(int k, std::span<const std::uint8_t> frame, SimTime t_start);
  // Delivers every frame due at or before t. Real-time safe (the callbacks must be too).
  void advance(SimTime t);
  // The earliest due time in flight, or -1 if nothing is. Real-time safe.
  SimTime next_due() const;

  const Topology& topology() const { return topology_; }
  std::uint64_t dropped() const { return dropped_; }         // by the fault hook or unreachable
  std::uint64_t corrupted() const { return corrupted_; }
  std::uint64_t overflow() const { return overflow_; }       // queue full

 private:
  struct InFlight {
    SimTime due = 0;
    std::uint64_t order = 0;
    int to = -1;  // slave index, -1: the master
    std::uint8_t size = 0;
    std::array<std::uint8_t, kMaxFrame> bytes{};
  };
  void put(int to, std::span<const std::uint8_t> frame, SimTime due, Fate fate);
  static bool later(const InFlight& a, const InFlight& b);

  Topology topology_;
  std::vector<SimTime> one_way_;
  Receive master_;
  std::vector<Receive> slaves_;
  std::vector<bool> reachable_;
  std::vector<SimTime> extra_;  // per slave, fault injection (set_extra_delay)
  FaultHook fault_;
  std::vector<InFlight> heap_;
  std::size_t capacity_;
  std::uint64_t order_ = 0, dropped_ = 0, corrupted_ = 0, overflow_ = 0;
};

}  // namespace omnitwin::m3
