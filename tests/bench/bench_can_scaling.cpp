// Benchmarks one cycle of an emulated CANopen segment in process against the number of drive
// nodes (issue 17, item 4): N CiA 402 drive nodes (bus_emulators/canopen/co_drive, built from
// the shipped EDS, their default PDO mapping: RPDO1 controlword + target velocity, TPDO1
// statusword + position, both on SYNC) on the simulated CAN wire (can_bus, 1 Mbit/s), fed by a
// minimal cyclic master on node 0 (SYNC and one RPDO per node each cycle), against a baseline
// measured in the same run: the same N drive nodes stepped with no frame on any wire. The
// difference is what the CAN emulation costs per node and cycle.
//
//   BM_CanCycle/<N>       SYNC + N RPDOs + N TPDOs through the wire model, N nodes' protocol
//                         stacks and N drive steps
//   BM_CanDrivesOnly/<N>  the N drive steps alone (the baseline)
// The cycle is the shortest whole number of ms whose frames (and the nodes' heartbeats) fill
// at most 80 % of the wire, measured (counter cycle_ms; counter load = the wire's busy
// fraction while timed): a CAN segment is
// limited by its bit rate long before by this CPU. items_per_second = cycles per wall second;
// ns_per_node = wall time per cycle / N. In process, not a CLI figure: it is the bus model's
// share of a run (docs/benchmarks.md). At most 63 drives: the wire model holds 64 nodes.
// Run with `build/tests/bench/bench_can_scaling`.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include "bus_emulators/can/can_bits.hpp"
#include "bus_emulators/can/can_bus.hpp"
#include "bus_emulators/canopen/co_drive.hpp"
#include "bus_emulators/canopen/co_eds.hpp"
#include "tests/bus_emulators/canopen/co_drive_on_bus.hpp"

namespace {

using namespace omnitwin;
namespace co = omnitwin::canopen;
using co::SimTime;

constexpr SimTime kMs = 1'000'000;
constexpr std::int64_t kBitRate = 1'000'000;


can::Frame frame(std::uint32_t id, std::initializer_list<std::uint8_t> data) {
  can::Frame f;
  f.id = id;
  f.dlc = static_cast<std::uint8_t>(data.size());
  std::copy(data.begin(), data.end(), f.data.begin());
  return f;
}

can::Frame rpdo(int node, std::uint16_t controlword, std::int32_t velocity) {
  const auto v = static_cast<std::uint32_t>(velocity);
  return frame(0x200 + static_cast<std::uint32_t>(node),
               {static_cast<std::uint8_t>(controlword), static_cast<std::uint8_t>(controlword >> 8),
                static_cast<std::uint8_t>(v), static_cast<std::uint8_t>(v >> 8), static_cast<std::uint8_t>(v >> 16),
                static_cast<std::uint8_t>(v >> 24)});
}

// A first guess at the whole-ms cycle whose SYNC, N RPDOs and N TPDOs fill at most 80 % of
// the wire (the nodes' heartbeats come on top: choose_cycle() measures).
SimTime cycle_guess(int n) {
  const int bits = can::frame_bits_with_intermission(frame(0x080, {})) +
                   2 * n * can::worst_case_frame_bits(false, 6);
  const SimTime need = static_cast<SimTime>(bits) * 1'000'000'000 / kBitRate * 5 / 4;
  return std::max<SimTime>(kMs, (need + kMs - 1) / kMs * kMs);
}

// Node 0 the master, nodes 1..n the drives (node IDs 1..n), all operational and enabled.
struct Segment {
  can::CanBus bus;
  std::vector<std::unique_ptr<co::DriveNode>> drives;
  SimTime cycle;
  SimTime now = 0;
  std::uint64_t tpdos = 0;
  int k = 0, started = -1;  // cycle count; the cycle of NMT start (-1: not yet)

  Segment(int n, SimTime cycle_ns)
      : bus(can::BusConfig{.bit_rate_bps = kBitRate, .queue_capacity = 256, .max_nodes = n + 1}), cycle(cycle_ns) {
    for (int i = 0; i <= n; ++i) bus.attach();
    for (int i = 0; i < n; ++i) drives.push_back(co::testing::drive_on_bus(bus, i + 1));
    bus.on_deliver([this](can::BusNode r, const can::Frame& f, const can::FrameTiming& t) {
      if (r == 0) {
        if ((f.id & 0x780) == 0x180) ++tpdos;
        return;
      }
      drives[static_cast<std::size_t>(r - 1)]->on_frame(f, t.end_ns);
    });
    for (auto& d : drives) d->power_on(0);
    run(20);  // boot-up messages out
    bus.submit(0, frame(0x000, {0x01, 0x00}), now);  // NMT start all
    started = k;
    run(20);
  }
  // One cycle: SYNC and the RPDOs at its start (after NMT start controlword 6, 7, then 15:
  // enable operation), the wire and the nodes to mid-cycle, the drives' steps there, the rest.
  void step() {
    const int since = started < 0 ? -1 : k - started;
    const std::uint16_t cw = since < 0 ? 0x00 : since == 0 ? 0x06 : since == 1 ? 0x07 : 0x0F;
    bus.advance(now);
    bus.submit(0, frame(0x080, {}), now);
    for (std::size_t i = 0; i < drives.size(); ++i) bus.submit(0, rpdo(static_cast<int>(i) + 1, cw, 1000), now);
    bus.advance(now + cycle / 2);
    for (auto& d : drives) d->step(now + cycle / 2, drive::Feedback{});
    now += cycle;
    ++k;
  }
  void run(int cycles) {
    for (int i = 0; i < cycles; ++i) step();
  }
};

// The wire's busy fraction over the next `cycles` cycles.
double load_over(Segment& s, int cycles) {
  const std::int64_t busy0 = s.bus.stats().busy_ns;
  s.run(cycles);
  return static_cast<double>(s.bus.stats().busy_ns - busy0) / static_cast<double>(cycles * s.cycle);
}

// A running segment of n nodes on the shortest whole-ms cycle that keeps the wire at most
// 80 % busy, measured.
std::unique_ptr<Segment> running_segment(int n) {
  for (SimTime cycle = cycle_guess(n);; cycle += kMs) {
    auto s = std::make_unique<Segment>(n, cycle);
    s->run(50);
    if (load_over(*s, 50) <= 0.8) return s;
  }
}

void counters(benchmark::State& state, int n, const Segment& s) {
  using C = benchmark::Counter;
  state.SetItemsProcessed(state.iterations());
  state.counters["ns_per_node"] = C(n * 1e-9, C::kIsIterationInvariantRate | C::kInvert);
  state.counters["cycle_ms"] = static_cast<double>(s.cycle) / kMs;
}

void BM_CanCycle(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  const auto seg = running_segment(n);
  Segment& s = *seg;
  const std::uint64_t before = s.tpdos;
  const std::int64_t busy0 = s.bus.stats().busy_ns;
  const SimTime t0 = s.now;
  for (auto _ : state) s.step();
  // Every node answers every SYNC once the segment runs.
  if (s.tpdos - before < static_cast<std::uint64_t>(n) * (state.iterations() - 1))
    state.SkipWithError("not every node answered every SYNC");
  if (s.drives.back()->drive().state() != drive::State::operation_enabled) state.SkipWithError("drives not enabled");
  counters(state, n, s);
  state.counters["load"] = static_cast<double>(s.bus.stats().busy_ns - busy0) / static_cast<double>(s.now - t0);
}

void BM_CanDrivesOnly(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  const auto seg = running_segment(n);
  Segment& s = *seg;
  for (auto _ : state) {
    for (auto& d : s.drives) d->step(s.now, drive::Feedback{});
    s.now += s.cycle;
  }
  counters(state, n, s);
}

BENCHMARK(BM_CanDrivesOnly)->Arg(1)->Arg(2)->Arg(4)->Arg(8)->Arg(16)->Arg(32)->Arg(63);
BENCHMARK(BM_CanCycle)->Arg(1)->Arg(2)->Arg(4)->Arg(8)->Arg(16)->Arg(32)->Arg(63);

}  // namespace

BENCHMARK_MAIN();
