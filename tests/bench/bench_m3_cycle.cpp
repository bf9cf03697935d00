// Benchmarks one MECHATROLINK-III transmission cycle of the emulated segment in process: our
// C1 master core (controller/mechatrolink3/m3_master) polling N servo slaves (m3_link +
// m3_servo on the shared drive core, each closed over an axis model) through the line model
// (m3_line), against a baseline measured in the same run: the same N drives and axes stepped
// once per cycle with no bus at all. The difference is what the M-III emulation costs.
//
//   BM_M3Cycle/<N>      master + line + N slaves: SYNC, N commands and responses, the
//                       interrupt with N ServoAxis applications (VELCTRL), N drive steps
//   BM_DrivesOnly/<N>   the N drive steps alone (the baseline)
// Both run cycles of simulated time after the start-up (the servos are on and turning): 1 ms,
// or the shortest whole number of ms the segment's plan fits (62 slaves: counter cycle_ms);
// items_per_second = cycles per wall second; the counter ns_per_slave = wall time per cycle
// divided by N. In process, not a CLI figure (`omnitwin run --bus m3` is timed by
// tests/bench/bench_cli.sh); run with `build/tests/bench/bench_m3_cycle` (scripts/bench does).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <memory>
#include <vector>

#include "bus_emulators/drive/axis_model.hpp"
#include "bus_emulators/mechatrolink3/m3_stations.hpp"
#include "controller/mechatrolink3/m3_master.hpp"
#include "controller/mechatrolink3/m3_servo_axis.hpp"

namespace {

using namespace omnitwin;
using namespace omnitwin::m3;

// The transmission cycle for n slaves: 1 ms, or the shortest whole number of ms that fits
// (62 slaves in a 10 m cascade need more than 1 ms with polling: docs/results/m3-cycle).
SimTime cycle_for(int n) {
  CycleInputs in;
  in.topology = Topology::cascade_of(n, 10.0);
  in.stations.assign(static_cast<std::size_t>(n), StationTiming{});
  const SimTime need = plan_cycle(in).min_cycle_ns;
  return std::max<SimTime>(1'000'000, (need + 999'999) / 1'000'000 * 1'000'000);
}

ServoConfig servo_config() {
  ServoConfig c;
  c.drive.counts_per_rev = 10000;
  c.drive.max_speed_rad_s = 200;
  return c;
}

// The segment: a C1 master, the line and n slaves with axes, on one simulated timeline.
struct Segment {
  M3Stations stations;
  std::vector<drive::AxisModel> axes;
  std::vector<ServoAxis> apps;
  std::unique_ptr<C1Master> master;
  SimTime next_drive = 0;
  SimTime cycle;

  explicit Segment(int n)
      : stations(StationsConfig{.topology = Topology::cascade_of(n, 10.0), .servo = servo_config(), .response_ns = 2'000}),
        cycle(cycle_for(n)) {
    MasterConfig cfg;
    cfg.cycle_ns = cycle;
    for (int k = 0; k < n; ++k) {
      cfg.slaves.push_back(MasterSlave{.address = static_cast<std::uint8_t>(kFirstSlave + k)});
      axes.emplace_back();
      apps.emplace_back("axis", ServoAxisConfig{});
      apps.back().set_velocity(5000);
    }
    master = std::make_unique<C1Master>(
        cfg, [this](std::span<const std::uint8_t> f, SimTime t) { stations.line().from_master(f, t); },
        [this](std::uint64_t, SimTime t) {
          for (int k = 0; k < master->slaves(); ++k)
            apps[static_cast<std::size_t>(k)].on_interrupt(master->response(k), master->fresh(k), master->command(k), t);
        });
    stations.line().attach_master([this](std::span<const std::uint8_t> f, SimTime t) { master->on_frame(f, t); });
    master->start(0);
  }
  // Runs the timeline to `end`: line deliveries, master wake-ups, drive periods in time order.
  void run_until(SimTime end) {
    for (;;) {
      SimTime t = end + 1;
      for (SimTime c : {master->next_wakeup(), stations.line().next_due(), next_drive})
        if (c >= 0 && c < t) t = c;
      if (t > end) return;
      stations.line().advance(t);
      master->advance(t);
      stations.advance(t);
      if (t == next_drive) {
        for (std::size_t k = 0; k < axes.size(); ++k) {
          const int i = static_cast<int>(k);
          axes[k].step(stations.servo(i).step(t, axes[k].feedback()), cycle * 1e-9);
        }
        next_drive += cycle;
      }
    }
  }
};

void BM_M3Cycle(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  Segment seg(n);
  SimTime t = 200 * seg.cycle;
  seg.run_until(t);  // start-up: every servo on and turning
  if (seg.master->state() != DriverState::cyclic || seg.apps[0].step() != AxisStep::running) {
    state.SkipWithError("the segment did not start");
    return;
  }
  for (auto _ : state) {
    t += seg.cycle;
    seg.run_until(t);
  }
  state.counters["cycle_ms"] = static_cast<double>(seg.cycle) * 1e-6;
  state.SetItemsProcessed(state.iterations());
  state.counters["ns_per_slave"] =
      benchmark::Counter(static_cast<double>(n), benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  std::uint64_t missed = 0;
  for (int k = 0; k < n; ++k) missed += seg.master->counters(k).missed;
  state.counters["missed"] = static_cast<double>(missed);
}

void BM_DrivesOnly(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  std::vector<std::unique_ptr<ServoProfile>> servos;
  std::vector<drive::AxisModel> axes(static_cast<std::size_t>(n));
  for (int k = 0; k < n; ++k) servos.push_back(std::make_unique<ServoProfile>(servo_config()));
  SimTime t = 0;
  for (auto _ : state) {
    for (std::size_t k = 0; k < axes.size(); ++k) axes[k].step(servos[k]->step(t, axes[k].feedback()), 1e-3);
    t += 1'000'000;
  }
  state.SetItemsProcessed(state.iterations());
  state.counters["ns_per_slave"] =
      benchmark::Counter(static_cast<double>(n), benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

}  // namespace

BENCHMARK(BM_DrivesOnly)->Arg(1)->Arg(4)->Arg(16)->Arg(62);
BENCHMARK(BM_M3Cycle)->Arg(1)->Arg(4)->Arg(16)->Arg(62);

BENCHMARK_MAIN();
