// Benchmarks the twin's lockstep stepping against raw mj_step of the same model, in the
// same run (DESIGN §11: figures are ratios against a baseline measured alongside).
//
//   BM_RawMjStep     mj_step of the same model fed the very setpoint sequence the twin's
//                    slaves produced (replayed from a twin run's trajectory.csv, where the
//                    setpoints change only at the 10 ms slave ticks), so MuJoCo does the same
//                    contact work and the difference is the twin alone.
//   BM_TwinLockstep  the whole thesis scenario through run_scenario (scheduler, drive
//                    chains, master loop, metrics, trajectory.csv) in lockstep.
//   BM_Overhead      both of the above alternated inside every iteration, so machine drift
//                    hits them alike; reports twin_over_raw = Σ twin time / Σ raw time.
// All simulate the same 22 s; rtf counters are simulated seconds per wall second.
#include <benchmark/benchmark.h>
#include <mujoco/mujoco.h>

#include <algorithm>
#include <chrono>
#include <array>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "physics/platform_sim.hpp"
#include "twin/run.hpp"
#include "twin/scenario.hpp"

namespace {

using namespace omnitwin;

const std::string kScenario = std::string(OMNITWIN_SOURCE_DIR) + "/models/scenarios/thesis_line.yaml";

twin::Scenario load(physics::ModelVariant v) {
  const char* variant = v == physics::ModelVariant::rollers ? "rollers" : "capsule";
  return twin::load_scenario(kScenario, {{"platform.variant", variant}});
}

// Setpoint columns w1..w4_setpoint_rad_s of every row of a twin run's trajectory.csv.
std::vector<std::array<double, 4>> recorded_setpoints(const twin::Scenario& s) {
  const std::string out = (std::filesystem::temp_directory_path() / "omnitwin-bench-replay").string();
  twin::RunOptions o;
  o.out_dir = out;
  twin::run_scenario(s, o);
  std::ifstream f(out + "/trajectory.csv");
  std::string line;
  std::getline(f, line);
  std::vector<int> cols;
  std::vector<std::string> names;
  for (std::stringstream hs(line); std::getline(hs, line, ',');) names.push_back(line);
  for (int i = 1; i <= 4; ++i)
    cols.push_back(static_cast<int>(std::find(names.begin(), names.end(), "w" + std::to_string(i) + "_setpoint_rad_s") - names.begin()));
  std::vector<std::array<double, 4>> rows;
  while (std::getline(f, line)) {
    std::vector<double> v;
    for (std::stringstream ls(line); std::getline(ls, line, ',');) v.push_back(std::stod(line));
    rows.push_back({v[cols[0]], v[cols[1]], v[cols[2]], v[cols[3]]});
  }
  std::filesystem::remove_all(out);
  return rows;
}

// One replay of the recorded setpoints through bare mj_step (model built beforehand).
void replay(physics::PlatformSim& sim, const twin::Scenario& s, const std::vector<std::array<double, 4>>& setpoints) {
  const int per_row = static_cast<int>(std::lround(s.controller.period / s.platform.sim.timestep));
  const mjModel* m = sim.model();
  mjData* d = sim.data();
  const int steps = static_cast<int>(s.duration / s.platform.sim.timestep) + 1;
  for (int k = 0; k < steps; ++k) {
    if (k % per_row == 0 && k / per_row < static_cast<int>(setpoints.size()))
      for (int i = 0; i < 4; ++i) d->ctrl[i] = setpoints[k / per_row][i];
    mj_step(m, d);
  }
  benchmark::DoNotOptimize(d->qpos[0]);
}

void raw_mj_step(benchmark::State& state, physics::ModelVariant v) {
  const twin::Scenario s = load(v);
  const auto setpoints = recorded_setpoints(s);
  for (auto _ : state) {
    state.PauseTiming();
    physics::PlatformSim sim(s.platform);
    sim.reset(0, 0, 0);
    state.ResumeTiming();
    replay(sim, s, setpoints);
  }
  state.counters["rtf"] = benchmark::Counter(s.duration * state.iterations(), benchmark::Counter::kIsRate);
}

void twin_lockstep(benchmark::State& state, physics::ModelVariant v) {
  const twin::Scenario s = load(v);
  const std::string out = (std::filesystem::temp_directory_path() / "omnitwin-bench-lockstep").string();
  twin::RunOptions o;
  o.out_dir = out;
  double final_error = 0;
  for (auto _ : state) {
    const twin::RunResult r = twin::run_scenario(s, o);
    final_error = r.metrics["platform"]["final_error_cm"].get<double>();
  }
  std::filesystem::remove_all(out);
  state.counters["rtf"] = benchmark::Counter(s.duration * state.iterations(), benchmark::Counter::kIsRate);
  state.counters["final_error_cm"] = final_error;
}

void overhead(benchmark::State& state, physics::ModelVariant v) {
  const twin::Scenario s = load(v);
  const auto setpoints = recorded_setpoints(s);
  const std::string out = (std::filesystem::temp_directory_path() / "omnitwin-bench-overhead").string();
  twin::RunOptions o;
  o.out_dir = out;
  double raw_s = 0, twin_s = 0;
  for (auto _ : state) {
    // Raw first; both sides build their model inside the timing (generate + compile MJCF).
    auto t0 = std::chrono::steady_clock::now();
    {
      physics::PlatformSim sim(s.platform);
      sim.reset(0, 0, 0);
      replay(sim, s, setpoints);
    }
    auto t1 = std::chrono::steady_clock::now();
    twin::run_scenario(s, o);
    auto t2 = std::chrono::steady_clock::now();
    raw_s += std::chrono::duration<double>(t1 - t0).count();
    twin_s += std::chrono::duration<double>(t2 - t1).count();
  }
  std::filesystem::remove_all(out);
  state.counters["twin_over_raw"] = twin_s / raw_s;
  state.counters["twin_rtf"] = s.duration * state.iterations() / twin_s;
}

BENCHMARK_CAPTURE(overhead, rollers, physics::ModelVariant::rollers)->Unit(benchmark::kMillisecond)->Iterations(10);
BENCHMARK_CAPTURE(overhead, capsule, physics::ModelVariant::capsule)->Unit(benchmark::kMillisecond)->Iterations(10);
BENCHMARK_CAPTURE(raw_mj_step, rollers, physics::ModelVariant::rollers)->Unit(benchmark::kMillisecond)->MinTime(5);
BENCHMARK_CAPTURE(twin_lockstep, rollers, physics::ModelVariant::rollers)->Unit(benchmark::kMillisecond)->MinTime(5);
BENCHMARK_CAPTURE(raw_mj_step, capsule, physics::ModelVariant::capsule)->Unit(benchmark::kMillisecond)->MinTime(5);
BENCHMARK_CAPTURE(twin_lockstep, capsule, physics::ModelVariant::capsule)->Unit(benchmark::kMillisecond)->MinTime(5);

}  // namespace

BENCHMARK_MAIN();
