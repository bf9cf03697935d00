// Benchmarks one EtherCAT cycle of the emulated segment in process against the number of
// slaves (issue 17, item 4): our master core (controller/ethercat/ec_master) with its LRW over
// N single-axis CiA 402 drives (DriveSlave behind its Esc, on an EscChain), each drive on an
// axis model, against a baseline measured in the same run: the same N drives stepped with no
// bus at all. The difference is what the EtherCAT emulation costs per slave and cycle.
//
//   BM_EcCycle/<N>       master tick + the frame through N ESCs + N firmware cycles + N drive steps
//   BM_EcDrivesOnly/<N>  the N drive steps alone (the baseline)
// Both run 1 ms cycles of simulated time in OP after the start-up. items_per_second = cycles per
// wall second; ns_per_slave = wall time per cycle / N; the counter max_slaves_1ms = how many
// such slaves one core could cycle in 1 ms at this cost (1 ms / ns_per_slave). In process, not
// a CLI figure: it is the bus model's share of a run (docs/benchmarks.md explains the split).
// 35 or more drives would not fit one LRW image (our master's one frame per cycle). This
// benchmark found that 22 or more did not even start (fixed: EcMaster::fill_slaves).
// Run with `build/tests/bench/bench_ec_scaling` (scripts/bench does).
#include <benchmark/benchmark.h>

#include "tests/controller/ethercat/ec_bench.hpp"

namespace {

using ecbench::Bench;

std::unique_ptr<Bench> operational(int n, benchmark::State& state) {
  auto b = std::make_unique<Bench>(n);
  if (!b->to_op(200000)) {
    state.SkipWithError(("the segment did not reach OP: " + b->master->error()).c_str());
    return nullptr;
  }
  for (int k = 0; k < 100; ++k) b->step();
  return b;
}

// ns_per_slave = wall seconds / (iterations · n) in ns; max_slaves_1ms = 1 ms / that.
void counters(benchmark::State& state, int n) {
  using C = benchmark::Counter;
  state.SetItemsProcessed(state.iterations());
  state.counters["ns_per_slave"] = C(n * 1e-9, C::kIsIterationInvariantRate | C::kInvert);
  state.counters["max_slaves_1ms"] = C(n * 1e-3, C::kIsIterationInvariantRate);
}

void BM_EcCycle(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  auto b = operational(n, state);
  if (!b) return;
  for (auto _ : state) b->step();
  if (b->master->stats().last_wkc != 3 * n) state.SkipWithError("wrong WKC in OP");
  counters(state, n);
}

void BM_EcDrivesOnly(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  auto b = operational(n, state);
  if (!b) return;
  for (auto _ : state) {
    for (std::size_t i = 0; i < b->slaves.size(); ++i) {
      auto& ax = b->slaves[i]->axis(0);
      const auto cmd = ax.step(b->t, b->models[i].feedback());
      b->models[i].step(cmd, 1e-3);
    }
    b->t += b->cycle;
  }
  counters(state, n);
}

BENCHMARK(BM_EcDrivesOnly)->Arg(1)->Arg(4)->Arg(8)->Arg(16)->Arg(32);
BENCHMARK(BM_EcCycle)->Arg(1)->Arg(4)->Arg(8)->Arg(16)->Arg(32);

}  // namespace

BENCHMARK_MAIN();
