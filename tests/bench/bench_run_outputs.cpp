// Benchmarks what a lockstep thesis run costs with its outputs on (DESIGN §8, §11: ratios
// against a baseline measured in the same benchmark):
//
//   BM_ThesisOutputs/B   per iteration, the thesis line (22 s simulated, lockstep) on bus B
//                        (0 direct, 1 can: omni-master as its own process over UDP):
//                          run_s       the run alone: no DDS, no video, no report (baseline)
//                          run_dds_s   the same run publishing on DDS (loopback, 100 Hz)
//                          render_s    its video afterwards (640x480, 30 fps, OSMesa, H.264)
//                          report_s    its report afterwards (matplotlib)
//                        and the ratios dds_slowdown = run_dds/run (stepping with DDS on) and
//                        video_total = (run + render)/run (the whole wall time with a video).
//                        The stepping loop never renders, so stepping with video on is the
//                        baseline itself (ratio 1 by construction; DESIGN §8 "afterwards").
#include <benchmark/benchmark.h>

#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

#include "twin/dds_observer.hpp"
#include "twin/run.hpp"
#include "twin/run_outputs.hpp"
#include "twin/scenario.hpp"

namespace {

using namespace omnitwin;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

const std::string kScenario = std::string(OMNITWIN_SOURCE_DIR) + "/models/scenarios/thesis_line.yaml";

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

twin::Scenario thesis(bool can) {
  std::vector<twin::Override> o{{"bus", can ? "can" : "direct"}};
  if (can) o.push_back({"bus.transport", "udp:239.74.163.2:47950"});
  return twin::load_scenario(kScenario, o);
}

// One run into `dir`, with `observer` (may be null); returns its wall time [s].
double timed_run(const twin::Scenario& s, const std::string& dir, twin::RunObserver* observer) {
  twin::RunOptions o;
  o.out_dir = dir;
  o.observer = observer;
  const auto t0 = Clock::now();
  twin::run_scenario(s, o);
  return seconds_since(t0);
}

void BM_ThesisOutputs(benchmark::State& state) {
  const twin::Scenario s = thesis(state.range(0) == 1);
  const std::string dir = (fs::temp_directory_path() / ("omnitwin-bench-outputs-" + std::to_string(::getpid()))).string();
  double run = 0, run_dds = 0, render = 0, report = 0;
  for (auto _ : state) {
    run += timed_run(s, dir, nullptr);
    {
      twin::DdsSettings d;
      d.domain = 1 + ::getpid() % 200;
      d.interface = "lo";
      twin::DdsRunObserver dds(d);
      run_dds += timed_run(s, dir, &dds);
    }
    twin::OutputPlan video;
    video.video = true;
    const twin::OutputsResult v = twin::make_run_outputs(dir, video, nullptr);
    if (!v.errors.empty()) state.SkipWithError(v.errors.front().c_str());
    render += v.render_wall_s;
    twin::OutputPlan rep;
    rep.report = true;
    const twin::OutputsResult r = twin::make_run_outputs(dir, rep, nullptr);
    if (!r.errors.empty()) state.SkipWithError(r.errors.front().c_str());
    report += r.report_wall_s;
  }
  const double n = static_cast<double>(state.iterations());
  state.counters["run_s"] = run / n;
  state.counters["run_dds_s"] = run_dds / n;
  state.counters["render_s"] = render / n;
  state.counters["report_s"] = report / n;
  state.counters["dds_slowdown"] = run_dds / run;
  state.counters["video_total"] = (run + render) / run;
  fs::remove_all(dir);
}

BENCHMARK(BM_ThesisOutputs)->Arg(0)->Arg(1)->Unit(benchmark::kSecond)->Iterations(2);

}  // namespace
BENCHMARK_MAIN();
