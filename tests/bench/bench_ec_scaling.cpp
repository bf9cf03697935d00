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
// From 35 drives on the image no longer fits one LRW laid out separately; the master then
// overlaps it (EcMasterConfig::image_layout), which holds up to 59 of these drives
// (24 bytes each) per frame; beyond that it sends several LRW frames per cycle. This benchmark
// found that 22 or more did not even start (fixed: EcMaster::fill_slaves).
// BM_SegmentLockstep / BM_SegmentRealtime: seed 001's 100 axes at 100 µs, and segments of
// 200 … 1,600 axes at 1 ms (several frames per cycle).
// Run with `build/tests/bench/bench_ec_scaling` (scripts/bench does).
#include <benchmark/benchmark.h>

#include <pthread.h>
#include <sched.h>
#include <time.h>

#include <algorithm>
#include <chrono>
#include <vector>

#include "bus_emulators/ethercat/transport/ec_transport.hpp"
#include "tests/bench/ec_chain_thread.hpp"
#include "tests/controller/ethercat/ec_bench.hpp"
#include "tests/support/veth.hpp"

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

BENCHMARK(BM_EcDrivesOnly)->Arg(1)->Arg(4)->Arg(8)->Arg(16)->Arg(32)->Arg(48)->Arg(96)->Arg(192);
BENCHMARK(BM_EcCycle)->Arg(1)->Arg(4)->Arg(8)->Arg(16)->Arg(32)->Arg(48)->Arg(96)->Arg(192);

// ---- segments of seed 001's multi-axis slaves (8 axis cards each, the rest on the last) ----
// 100 axes: 13 slaves (12 × 8 + 4), one overlapped LRW of 1,200 bytes. From 119 axes on the
// image takes more than one frame (EcMaster cuts it into several LRW frames per cycle).

std::unique_ptr<ecbench::MultiAxisSegment> segment(benchmark::State& state, int axes, ecbench::me::SimTime cycle) {
  auto seg = std::make_unique<ecbench::MultiAxisSegment>(axes, cycle);
  if (!seg->to_op(400000)) {
    state.SkipWithError(("the segment did not reach OP: " + seg->master->error()).c_str());
    return nullptr;
  }
  return seg;
}

// Lockstep, in process: state.range(1) cycles of state.range(2) µs of simulated time over a
// segment of state.range(0) axes — the master's tick, its frames through the ESCs and back,
// every card's firmware cycle on SYNC0 — timed; beside it, in the same iteration, the baseline:
// the same drives stepped as often with no bus. rtf = simulated / wall; bus_share =
// (segment − drives) / segment; us_per_cycle: what one cycle costs one core.
void BM_SegmentLockstep(benchmark::State& state) {
  const auto cycle = static_cast<ecbench::me::SimTime>(state.range(2)) * 1000;
  auto seg = segment(state, static_cast<int>(state.range(0)), cycle);
  if (!seg) return;
  const auto cycles = static_cast<int>(state.range(1));
  double seg_s = 0, drives_s = 0;
  for (auto _ : state) {
    auto t0 = std::chrono::steady_clock::now();
    for (int k = 0; k < cycles; ++k) seg->step();
    seg_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    t0 = std::chrono::steady_clock::now();
    for (int k = 0; k < cycles; ++k)
      for (auto& sl : seg->slaves)
        for (int a = 0; a < sl->axes(); ++a) sl->axis(a).step(seg->t + k * cycle, omnitwin::drive::Feedback{});
    drives_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  const double sim_s = static_cast<double>(cycles) * static_cast<double>(cycle) * 1e-9 * static_cast<double>(state.iterations());
  state.counters["rtf"] = sim_s / seg_s;
  state.counters["rtf_drives_only"] = sim_s / drives_s;
  state.counters["us_per_cycle"] = seg_s / (sim_s / (static_cast<double>(cycle) * 1e-9)) * 1e6;
  state.counters["bus_share"] = (seg_s - drives_s) / seg_s;
  state.counters["wkc_errors"] = static_cast<double>(seg->master->stats().wkc_errors);
  state.counters["lost_frames"] = static_cast<double>(seg->master->stats().lost_frames);
  state.counters["last_wkc"] = seg->master->stats().last_wkc;
  state.counters["lrw_bytes"] = seg->master->lrw_bytes();
  state.counters["frames_per_cycle"] = seg->master->cyclic_frames();
}

// Realtime: a segment of state.range(2) axes served on its own SCHED_FIFO thread on end b of a
// veth pair (what the twin's segment does per frame), our master core on this thread
// (SCHED_FIFO) on end a, paced by clock_nanosleep to absolute deadlines every state.range(1) µs
// for state.range(0) seconds. Per cycle: tick → send its frames → wait until the cycle is
// complete (every frame back) or the next deadline → on_frame. Counters: frames sent, lost
// (the master's own count: not back by the next tick), wkc_errors, turnaround p50/p99/max
// (first frame out → last frame back), late_starts (a cycle that began half a period or more
// after its deadline), the worst start lateness and segment_losses (the master left OP on a
// silent segment); fifo = 1 when both threads got SCHED_FIFO.
// The chain thread answers each frame when it arrives: 100 Mbit/s wire time is not modelled
// here (docs/benchmarks.md does that arithmetic).
void BM_SegmentRealtime(benchmark::State& state) {
  if (const auto why = omnitwin::testing::VethPair::unavailable_reason()) {
    state.SkipWithError(why->c_str());
    return;
  }
  const ecbench::me::SimTime cycle = state.range(1) * 1000;
  auto seg = segment(state, static_cast<int>(state.range(2)), cycle);
  if (!seg) return;
  sched_param sp{};
  sp.sched_priority = 40;
  const bool fifo = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp) == 0;
  omnitwin::testing::VethPair veth;
  const std::int64_t seconds = state.range(0);
  std::vector<double> turn_us;
  std::uint64_t late_starts = 0, sent = 0;
  double worst_late_us = 0;
  bool chain_fifo = false;
  for (auto _ : state) {
    ecbench::ChainThread chain(seg->chain, seg->t, "raw:" + veth.b(), 40);
    auto master = omnitwin::ethercat::open_transport("raw:" + veth.a(), omnitwin::ethercat::Role::master);
    std::vector<std::uint8_t> buf(omnitwin::ethercat::kMaxPdu);
    const std::int64_t cycles = seconds * 1'000'000'000 / cycle;
    turn_us.reserve(static_cast<std::size_t>(cycles));
    timespec next{};
    clock_gettime(CLOCK_MONOTONIC, &next);
    const auto start = std::chrono::steady_clock::now();
    for (std::int64_t k = 0; k < cycles; ++k) {
      next.tv_nsec += cycle;
      if (next.tv_nsec >= 1'000'000'000) next.tv_nsec -= 1'000'000'000, ++next.tv_sec;
      clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
      timespec now{};
      clock_gettime(CLOCK_MONOTONIC, &now);
      const double late_us = static_cast<double>((now.tv_sec - next.tv_sec) * 1'000'000'000 + now.tv_nsec - next.tv_nsec) / 1e3;
      worst_late_us = std::max(worst_late_us, late_us);
      late_starts += late_us * 1e3 >= static_cast<double>(cycle) / 2;
      const auto t = seg->t + std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - start).count();
      seg->new_tick();
      seg->master->tick(t);
      if (!seg->sent) continue;
      const auto t0 = std::chrono::steady_clock::now();
      master->send(seg->frame);
      for (std::size_t i = 0; i < seg->n_more; ++i) master->send(seg->more[i]);
      sent += 1 + seg->n_more;
      // Wait for the cycle's frames until the next deadline at most. An answer that came after
      // its deadline is still queued: handed to the master (which counts it stray), and the
      // wait goes on for this cycle's.
      const auto deadline = std::chrono::steady_clock::now() + std::chrono::nanoseconds(cycle) -
                            std::chrono::nanoseconds(static_cast<std::int64_t>(late_us * 1e3));
      const std::uint64_t before = seg->master->stats().cycles;
      while (seg->master->stats().cycles == before) {
        const auto left = deadline - std::chrono::steady_clock::now();
        if (left <= std::chrono::nanoseconds(0)) break;
        const int n = master->receive(buf, left);
        if (n <= 0) break;
        const auto t1 = std::chrono::steady_clock::now();
        seg->master->on_frame(std::span<std::uint8_t>(buf.data(), static_cast<std::size_t>(n)),
                              seg->t + std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - start).count());
        if (seg->master->stats().cycles != before)
          turn_us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
      }
    }
    chain_fifo = chain.fifo();
  }
  std::sort(turn_us.begin(), turn_us.end());
  const auto pct = [&](int p) { return turn_us.empty() ? -1.0 : turn_us[std::min(turn_us.size() - 1, turn_us.size() * p / 100)]; };
  const auto& st = seg->master->stats();
  state.counters["frames_sent"] = static_cast<double>(sent);
  state.counters["frames_per_cycle"] = seg->master->cyclic_frames();
  state.counters["lost_frames"] = static_cast<double>(st.lost_frames);
  state.counters["stray_frames"] = static_cast<double>(st.stray_frames);
  state.counters["wkc_errors"] = static_cast<double>(st.wkc_errors);
  state.counters["segment_losses"] = static_cast<double>(st.segment_losses);
  state.counters["turnaround_p50_us"] = pct(50);
  state.counters["turnaround_p99_us"] = pct(99);
  state.counters["turnaround_max_us"] = turn_us.empty() ? -1.0 : turn_us.back();
  state.counters["late_starts"] = static_cast<double>(late_starts);
  state.counters["worst_late_us"] = worst_late_us;
  state.counters["operational"] = seg->master->operational();
  state.counters["fifo"] = fifo && chain_fifo;
}

// Seed 001's 100 axes at its 100 µs (60 s of simulated time), then segments beyond one frame
// at 1 ms: what one core holds.
BENCHMARK(BM_SegmentLockstep)
    ->Args({100, 600000, 100})
    ->Args({100, 20000, 1000})
    ->Args({200, 20000, 1000})
    ->Args({400, 20000, 1000})
    ->Args({800, 10000, 1000})
    ->Args({1600, 5000, 1000})
    ->Iterations(1)
    ->Unit(benchmark::kSecond);
// Realtime: the seed's 100 axes at 100 µs for 60 s and at 250 µs … 1 ms for 20 s; then larger
// segments at 1 ms for 20 s.
BENCHMARK(BM_SegmentRealtime)
    ->Args({60, 100, 100})
    ->Args({20, 250, 100})
    ->Args({20, 500, 100})
    ->Args({20, 1000, 100})
    ->Args({20, 1000, 200})
    ->Args({20, 1000, 400})
    ->Args({20, 1000, 800})
    ->Args({20, 1000, 1600})
    ->Iterations(1)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
