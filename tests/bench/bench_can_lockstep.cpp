// Benchmarks whole lockstep runs of the thesis scenario over the CAN bus (DESIGN §11: a
// ratio against a baseline measured in the same run).
//
//   BM_CanLockstep/P     the thesis line (22 s simulated) with --bus can: omni-master as its own
//                        process, UDP multicast on loopback, the sim-clock handshake every
//                        master tick, the twin with four Omni slaves; sampling period P ms for
//                        the master and the slaves (10, 5, 1).
//   BM_CanLockstepLocal/P  as BM_CanLockstep with the transport option ttl=0: the datagrams
//                        stay on this host (local receivers, python-can included, hear them
//                        all; the network does not), so no network-device transmission per send.
//   BM_DirectLockstep/P  the same scenario and period with bus direct (no frames, no second
//                        process): the baseline.
// Counters: rtf = simulated seconds per wall second; us_per_tick = wall time per master tick.
// Each benchmark uses its own UDP port; the master binary must be built (scripts/bench does).
#include <benchmark/benchmark.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

#include "twin/run.hpp"
#include "twin/scenario.hpp"

namespace {

using namespace omnitwin;

const std::string kScenario = std::string(OMNITWIN_SOURCE_DIR) + "/models/scenarios/thesis_line.yaml";

void run_thesis(benchmark::State& state, const char* bus, const char* options = "") {
  const std::string period = std::to_string(state.range(0) / 1000.0);
  std::vector<twin::Override> o_set{{"bus", bus}, {"controller.period", period}, {"platform.velocity_loop.period", period}};
  if (std::string(bus) == "can")
    o_set.push_back({"bus.transport", "udp:239.74.163.2:" + std::to_string(47900 + state.range(0)) + options});
  const twin::Scenario s = twin::load_scenario(kScenario, o_set);
  twin::RunOptions o;
  o.out_dir = (std::filesystem::temp_directory_path() / ("omnitwin-bench-can-" + std::string(bus))).string();
  double sim = 0, wall = 0;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    const twin::RunResult r = twin::run_scenario(s, o);
    wall += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    sim += r.metrics.at("sim_time_s").get<double>();
    if (r.exit_code == 3) state.SkipWithError(r.error.c_str());
  }
  state.counters["rtf"] = sim / wall;
  state.counters["us_per_tick"] = 1e6 * wall / (sim / (state.range(0) / 1000.0));
  std::filesystem::remove_all(o.out_dir);
}

void BM_CanLockstep(benchmark::State& state) { run_thesis(state, "can"); }
void BM_CanLockstepLocal(benchmark::State& state) { run_thesis(state, "can", "?ttl=0"); }
void BM_DirectLockstep(benchmark::State& state) { run_thesis(state, "direct"); }

BENCHMARK(BM_CanLockstep)->Arg(10)->Arg(5)->Arg(1)->Unit(benchmark::kSecond)->Iterations(3);
BENCHMARK(BM_CanLockstepLocal)->Arg(10)->Arg(5)->Arg(1)->Unit(benchmark::kSecond)->Iterations(3);
BENCHMARK(BM_DirectLockstep)->Arg(10)->Arg(5)->Arg(1)->Unit(benchmark::kSecond)->Iterations(3);

}  // namespace

BENCHMARK_MAIN();
