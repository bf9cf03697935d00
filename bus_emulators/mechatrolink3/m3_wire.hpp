// bus_emulators/mechatrolink3 — the M-III wire model: how long frames take at 100 Mbit/s,
// how far each station is from the C1 master in a cascade or a star, and what that implies
// for one transmission cycle (T_RSP, INT_OFFSET, the shortest cycle that fits).
//
// Seed 000 fixes 100 Mbit/s (4B/5B MLT-3: 80 ns per data byte), at most 62 slaves, 100 m
// between stations, cascade and star topologies, and the shape of a cyclic transmission
// cycle (fig. 5): the C1 master's sync, then one command and one response per slave, then
// retries of the slaves whose response was missing or bad, all before the cyclic interrupt
// at INT_OFFSET; the software then prepares the next commands in what is left of the cycle.
// Everything else here is our documented choice (docs/protocols/mechatrolink3.md):
//   - a frame on the wire: preamble + SFD (8 bytes) + the carried frame (m3_frame: header,
//     data, FCS), then an inter-frame gap of 12 bytes;
//   - cut-through stations: a frame reaches station k after the cables and the forwarding
//     delays of the stations before it; a star has one hub between master and every slave;
//   - the C1 master polls: after each command it waits for that slave's response for at most
//     T_RSP(k) = TR_DLY(k) + the command's and response's frame times + the slave's response
//     time + a margin, then goes on with the next slave.
// Pure arithmetic on integers (ns): no sockets, no clock. Real-time safe unless noted.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "bus_emulators/mechatrolink3/m3_frame.hpp"

namespace omnitwin::m3 {

inline constexpr SimTime kByteNs = 80;              // 100 Mbit/s
inline constexpr std::size_t kPreambleSfd = 8, kInterFrameGap = 12;
inline constexpr SimTime kInterFrameGapNs = static_cast<SimTime>(kInterFrameGap) * kByteNs;  // 960 ns
// DLY_REQ to DLY_RPL turnaround of every slave's ASIC (ours; fixed and known, so the C1
// master subtracts it from the round trip it measures).
inline constexpr SimTime kDelayEchoNs = 1'000;

// Time the frame with an information field of n bytes occupies a link, first preamble bit
// to last FCS bit [ns].
constexpr SimTime frame_time_ns(std::size_t data_bytes) {
  return static_cast<SimTime>(kPreambleSfd + kHeaderSize + data_bytes + kFcsSize) * kByteNs;
}
// The same plus the inter-frame gap: the least spacing of two frames' starts on one link [ns].
constexpr SimTime frame_slot_ns(std::size_t data_bytes) {
  return frame_time_ns(data_bytes) + static_cast<SimTime>(kInterFrameGap) * kByteNs;
}

enum class TopologyKind : std::uint8_t { cascade, star };

// Where the slaves sit. Slave k (0-based) has station address kFirstSlave + k.
struct Topology {
  TopologyKind kind = TopologyKind::cascade;
  // cascade: cable before slave k (from the master for k = 0, else from slave k-1) [m];
  // star: cable from the hub to slave k [m]. One entry per slave; at most 100 m each.
  std::vector<double> cable_m;
  double master_cable_m = 1.0;        // star only: master to hub [m]
  SimTime forward_delay_ns = 500;     // cascade: a station passing a frame on (cut-through)
  SimTime hub_delay_ns = 500;         // star: the hub passing a frame on
  double cable_ns_per_m = 5.0;        // CAT5e, about 0.66 c

  int slaves() const { return static_cast<int>(cable_m.size()); }
  // A line of n slaves with `metres` of cable before each.
  static Topology cascade_of(int n, double metres = 1.0);
  static Topology star_of(int n, double metres = 1.0);
};

// "" if the topology can exist (1 … 62 slaves, cables 0 … 100 m, delays ≥ 0),
// else why not. Not real-time safe (builds a string).
std::string check(const Topology& t);

// Time from the master starting to send until slave k starts to receive (one way, the same
// both ways) [ns]: cables and the stations or hub in between.
SimTime one_way_delay_ns(const Topology& t, int k);
// TR_DLY(k): the round trip the master's delay measurement finds for slave k [ns]: both ways
// of one_way_delay_ns, without frame times and without the slave's own response time.
SimTime tr_dly_ns(const Topology& t, int k);

// One slave's part of a cyclic exchange.
struct StationTiming {
  std::size_t data_bytes = 32;     // command and response information field (8/16/32/48/64)
  SimTime response_ns = 2'000;     // from the command's last bit to the response's first [ns]
};

// The inputs of a cycle plan.
struct CycleInputs {
  Topology topology;
  std::vector<StationTiming> stations;  // one per slave, in topology order
  int retry_slots = 1;                  // retries the cycle keeps room for (0 … 7)
  SimTime margin_ns = 1'000;            // added to every T_RSP
  SimTime software_ns = 100'000;        // after INT_OFFSET: read responses, prepare commands
};

// The result: what the C1 master sets before communication starts (seed 000 fig. 10).
struct CyclePlan {
  std::vector<SimTime> t_rsp_ns;  // per slave: response monitoring time, from the command's start
  SimTime exchange_ns = 0;        // sync + every command/response exchange
  SimTime retry_ns = 0;           // room for retry_slots exchanges with the slowest slave
  SimTime int_offset_ns = 0;      // cyclic interrupt INT1: exchange + retries
  SimTime min_cycle_ns = 0;       // int_offset + software time
};

// T_RSP of slave k: TR_DLY + command and response frame times + response time + margin.
SimTime t_rsp_ns(const CycleInputs& in, int k);
// Plans one transmission cycle. The inputs must be consistent (check_inputs() == "").
CyclePlan plan_cycle(const CycleInputs& in);
// The same from TR_DLY values the master measured (one per station) instead of a topology:
// what the C1 master computes at seed 000 fig. 10. Sizes must match.
CyclePlan plan_cycle(const std::vector<SimTime>& tr_dly, const std::vector<StationTiming>& stations,
                     int retry_slots, SimTime margin_ns, SimTime software_ns);
// "" if plan_cycle() may be called: a valid topology, one StationTiming per slave with a
// cyclic data length and a response time ≥ 0, 0 … 7 retry slots, margins ≥ 0. Not real-time safe.
std::string check_inputs(const CycleInputs& in);
// "" if a transmission cycle of cycle_ns fits the plan, else a message naming the shortest
// cycle that does (rounded up to whole µs). Not real-time safe.
std::string check_cycle(const CyclePlan& plan, SimTime cycle_ns);

}  // namespace omnitwin::m3
