// Benchmarks the CAN bus core (bus_emulators/can/can_bus): how many simulated frames it
// completes per wall second when the bus is saturated, i.e. the worst case a twin meets.
//
//   BM_CanBusSaturated/<bit rate>  six acknowledging nodes, each keeping two frames queued (a
//                    transmit-done callback queues the sender's next frame), so every idle
//                    bus starts an arbitration among six contenders. Frames are standard
//                    data frames of 0–8 bytes with varied identifiers and data (so stuffing
//                    varies). Time advances event by event, as the twin's scheduler drives it:
//                    advance(next_event_ns()). Every delivery runs a counting callback.
// items_per_second = frames completed per wall second; sim_rtf = simulated seconds per wall
// second; deliveries_per_frame must read 5 (every other node receives every frame).
#include <benchmark/benchmark.h>

#include <array>
#include <cstdint>

#include "bus_emulators/can/can_bus.hpp"

namespace {

using namespace omnitwin;

constexpr int kNodes = 6;
constexpr int kQueued = 2;             // frames each node keeps queued
constexpr std::uint64_t kBatch = 100;  // frames completed per benchmark iteration
constexpr std::size_t kPattern = 9;    // DLCs 0..8 in turn

// Frame `i` of node `n`: identifier 0x100 + 16·n + i (unique per node), DLC i mod 9, data
// bytes from a small mixing of n and i.
can::Frame frame_of(int n, std::size_t i) {
  can::Frame f;
  f.id = 0x100u + 16u * static_cast<std::uint32_t>(n) + static_cast<std::uint32_t>(i % 16);
  f.dlc = static_cast<std::uint8_t>(i % kPattern);
  for (std::size_t b = 0; b < 8; ++b)
    f.data[b] = static_cast<std::uint8_t>((n * 37 + i * 11 + b * 73) & 0xff);
  return f;
}

void BM_CanBusSaturated(benchmark::State& state) {
  // The bus, its nodes and their frame tables (set-up, outside the timing).
  can::BusConfig cfg;
  cfg.bit_rate_bps = state.range(0);
  can::CanBus bus(cfg);
  std::array<std::array<can::Frame, 16 * kPattern>, kNodes> frames;
  std::array<std::size_t, kNodes> next{};
  for (int n = 0; n < kNodes; ++n) {
    bus.attach();
    for (std::size_t i = 0; i < frames[n].size(); ++i) frames[n][i] = frame_of(n, i);
  }
  // Deliveries are counted; each completed transmission queues the sender's next frame.
  std::uint64_t deliveries = 0;
  bus.on_deliver([&](can::BusNode, const can::Frame&, const can::FrameTiming&) { ++deliveries; });
  auto submit_next = [&](can::BusNode n, std::int64_t t) {
    const auto k = static_cast<std::size_t>(n);
    bus.submit(n, frames[k][next[k]++ % frames[k].size()], t);
  };
  bus.on_tx_done([&](can::BusNode n, const can::Frame&, const can::FrameTiming& t) {
    submit_next(n, t.end_ns);
  });
  for (int n = 0; n < kNodes; ++n)
    for (int q = 0; q < kQueued; ++q) submit_next(n, 0);
  // The timed loop: run events until kBatch more frames have completed.
  std::int64_t now = 0;
  for (auto _ : state) {
    const std::uint64_t target = bus.stats().frames + kBatch;
    while (bus.stats().frames < target) {
      now = bus.next_event_ns();
      bus.advance(now);
    }
  }
  const auto done = static_cast<double>(bus.stats().frames);
  state.SetItemsProcessed(static_cast<std::int64_t>(bus.stats().frames));
  state.counters["sim_rtf"] = benchmark::Counter(static_cast<double>(now) * 1e-9,
                                                 benchmark::Counter::kIsRate);
  state.counters["deliveries_per_frame"] = done > 0 ? static_cast<double>(deliveries) / done : 0;
  state.counters["bus_load"] = bus.bus_load(now);
  state.counters["sim_frames_per_s"] = done > 0 ? done / (static_cast<double>(now) * 1e-9) : 0;
}

}  // namespace

BENCHMARK(BM_CanBusSaturated)->Arg(1'000'000)->Arg(125'000)->UseRealTime();
BENCHMARK_MAIN();
