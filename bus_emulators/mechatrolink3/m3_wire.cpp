// bus_emulators/mechatrolink3 — the wire model's arithmetic; see m3_wire.hpp.
#include "bus_emulators/mechatrolink3/m3_wire.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace omnitwin::m3 {

namespace {

// Seed 000 table 1: 100 m between stations; its 6300 m in all is 63 links of 100 m, so it
// follows from the per-link limit and needs no check of its own.
constexpr double kMaxCableM = 100.0;
constexpr SimTime kGapNs = kInterFrameGapNs;

SimTime cable_ns(const Topology& t, double metres) { return std::llround(metres * t.cable_ns_per_m); }

// The longest exchange a retry may need: the slowest slave's T_RSP and a gap.
SimTime slowest_exchange_ns(const std::vector<SimTime>& t_rsp) {
  return t_rsp.empty() ? 0 : *std::max_element(t_rsp.begin(), t_rsp.end()) + kGapNs;
}

}  // namespace

Topology Topology::cascade_of(int n, double metres) {
  Topology t;
  t.kind = TopologyKind::cascade;
  t.cable_m.assign(static_cast<std::size_t>(std::max(n, 0)), metres);
  return t;
}

Topology Topology::star_of(int n, double metres) {
  Topology t = cascade_of(n, metres);
  t.kind = TopologyKind::star;
  t.master_cable_m = metres;
  return t;
}

std::string check(const Topology& t) {
  if (t.slaves() < 1 || t.slaves() > kMaxSlaves) return fmt::format("{} slaves (1 … {})", t.slaves(), kMaxSlaves);
  for (int k = 0; k < t.slaves(); ++k) {
    const double m = t.cable_m[static_cast<std::size_t>(k)];
    if (!(m >= 0 && m <= kMaxCableM)) return fmt::format("cable before slave {}: {} m (0 … 100 m)", k + 1, m);
  }
  if (t.kind == TopologyKind::star && !(t.master_cable_m >= 0 && t.master_cable_m <= kMaxCableM))
    return fmt::format("master-to-hub cable: {} m (0 … 100 m)", t.master_cable_m);
  if (t.forward_delay_ns < 0 || t.hub_delay_ns < 0 || !(t.cable_ns_per_m >= 0)) return "negative delay";
  return "";
}

SimTime one_way_delay_ns(const Topology& t, int k) {
  if (t.kind == TopologyKind::star) {
    return cable_ns(t, t.master_cable_m) + t.hub_delay_ns + cable_ns(t, t.cable_m[static_cast<std::size_t>(k)]);
  }
  // Cascade: every cable up to slave k, and every station before it passing the frame on.
  SimTime d = static_cast<SimTime>(k) * t.forward_delay_ns;
  for (int i = 0; i <= k; ++i) d += cable_ns(t, t.cable_m[static_cast<std::size_t>(i)]);
  return d;
}

SimTime tr_dly_ns(const Topology& t, int k) { return 2 * one_way_delay_ns(t, k); }

SimTime t_rsp_ns(const CycleInputs& in, int k) {
  const StationTiming& s = in.stations[static_cast<std::size_t>(k)];
  return tr_dly_ns(in.topology, k) + 2 * frame_time_ns(s.data_bytes) + s.response_ns + in.margin_ns;
}

CyclePlan plan_cycle(const std::vector<SimTime>& tr_dly, const std::vector<StationTiming>& stations,
                     int retry_slots, SimTime margin_ns, SimTime software_ns) {
  CyclePlan p;
  p.exchange_ns = frame_slot_ns(8);  // the sync frame
  for (std::size_t k = 0; k < stations.size(); ++k) {
    const StationTiming& s = stations[k];
    p.t_rsp_ns.push_back(tr_dly[k] + 2 * frame_time_ns(s.data_bytes) + s.response_ns + margin_ns);
    p.exchange_ns += p.t_rsp_ns.back() + kGapNs;
  }
  p.retry_ns = retry_slots * slowest_exchange_ns(p.t_rsp_ns);
  p.int_offset_ns = p.exchange_ns + p.retry_ns;
  p.min_cycle_ns = p.int_offset_ns + software_ns;
  return p;
}

CyclePlan plan_cycle(const CycleInputs& in) {
  std::vector<SimTime> tr_dly;
  for (int k = 0; k < in.topology.slaves(); ++k) tr_dly.push_back(tr_dly_ns(in.topology, k));
  return plan_cycle(tr_dly, in.stations, in.retry_slots, in.margin_ns, in.software_ns);
}

std::string check_inputs(const CycleInputs& in) {
  if (std::string why = check(in.topology); !why.empty()) return why;
  if (in.stations.size() != in.topology.cable_m.size())
    return fmt::format("{} station timings for {} slaves", in.stations.size(), in.topology.cable_m.size());
  for (std::size_t k = 0; k < in.stations.size(); ++k) {
    if (!is_cyclic_length(in.stations[k].data_bytes))
      return fmt::format("slave {}: data length {} (8, 16, 32, 48 or 64 bytes)", k + 1, in.stations[k].data_bytes);
    if (in.stations[k].response_ns < 0) return fmt::format("slave {}: negative response time", k + 1);
  }
  if (in.retry_slots < 0 || in.retry_slots > 7) return fmt::format("{} retry slots (0 … 7)", in.retry_slots);
  if (in.margin_ns < 0 || in.software_ns < 0) return "negative margin or software time";
  return "";
}

std::string check_cycle(const CyclePlan& plan, SimTime cycle_ns) {
  if (cycle_ns >= plan.min_cycle_ns) return "";
  const SimTime us = (plan.min_cycle_ns + 999) / 1000;
  return fmt::format("a {:.3f} ms transmission cycle is too short: the slaves, data lengths and retry slots "
                     "need {:.3f} ms (INT_OFFSET {:.3f} ms + software); the shortest cycle that fits is {} µs",
                     cycle_ns * 1e-6, plan.min_cycle_ns * 1e-6, plan.int_offset_ns * 1e-6, us);
}

}  // namespace omnitwin::m3
