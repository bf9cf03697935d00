// twin layer — `omnitwin experiment fast-model`: the fast physics model (variant capsule)
// against the reference (variant rollers) on the thesis line, the circle and the rotation
// (issue 17, item 3): how far its platform twist departs from the reference's, and how much
// faster a whole run is, both measured here, in one invocation.
//
// Each scenario runs on both models in lockstep over bus direct, reference then fast, `reps`
// times (interleaved, so a busy machine slows both alike); the real-time factor of a model is
// the median of sim seconds / wall seconds of run_scenario (model compile, physics, drive
// chains, master, records). The twist agreement compares the last pair's trajectory.csv
// (lockstep runs are deterministic, every pair is the same). Only the accuracy bound decides
// the exit code: speed depends on the machine and is reported, not judged.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include "twin/csv_columns.hpp"
#include "twin/experiment.hpp"
#include "twin/run.hpp"
#include "twin/scenario.hpp"

namespace omnitwin::twin {

namespace fs = std::filesystem;

TwistAgreement twist_agreement(const CsvColumns& ref, const CsvColumns& fast, double wheel_distance_m,
                               double window_s) {
  const std::size_t n = std::min(ref.rows(), fast.rows());
  if (n < 2) throw std::runtime_error("twist_agreement: fewer than two samples in " + ref.file);
  const auto& t = ref.column("t");
  const double period = t[1] - t[0];
  const std::size_t w = std::max<std::size_t>(1, static_cast<std::size_t>(std::llround(window_s / period)));
  const double L = wheel_distance_m;
  // The columns both files need, looked up once (a file without one is refused whatever its
  // length).
  struct Cols {
    const std::vector<double>&x, &y, &phi, &vx, &vy, &wz;
  };
  const auto cols = [](const CsvColumns& c) {
    return Cols{c.column("x"), c.column("y"), c.column("phi"), c.column("vx"), c.column("vy"), c.column("wz")};
  };
  const Cols r = cols(ref), f = cols(fast);
  // The mean twist (vx, vy, L·wz) of samples [a, a + w) of one run.
  auto mean_twist = [&](const Cols& c, std::size_t a) {
    double m[3] = {0, 0, 0};
    for (std::size_t i = a; i < a + w; ++i) m[0] += c.vx[i], m[1] += c.vy[i], m[2] += L * c.wz[i];
    return std::array<double, 3>{m[0] / w, m[1] / w, m[2] / w};
  };
  TwistAgreement out;
  double diff2 = 0, ref2 = 0;
  for (std::size_t a = 0; a + w <= n; a += w, ++out.windows) {
    const auto mr = mean_twist(r, a), mf = mean_twist(f, a);
    for (int k = 0; k < 3; ++k) diff2 += (mf[k] - mr[k]) * (mf[k] - mr[k]), ref2 += mr[k] * mr[k];
  }
  out.twist_error = ref2 > 0 ? std::sqrt(diff2 / ref2) : 0.0;
  // The pose the reference travelled (translation plus L·rotation) and where the two ended.
  for (std::size_t i = 1; i < n; ++i)
    out.path_m += std::hypot(r.x[i] - r.x[i - 1], r.y[i] - r.y[i - 1]) + L * std::abs(r.phi[i] - r.phi[i - 1]);
  const std::size_t e = n - 1;
  out.final_pose_diff_m = std::hypot(f.x[e] - r.x[e], f.y[e] - r.y[e]) + L * std::abs(f.phi[e] - r.phi[e]);
  return out;
}

namespace {

struct ModelRun {
  double rtf = 0;       // sim seconds / wall seconds of run_scenario
  int exit_code = 0;
  std::string dir;
};

// One run of `scenario` on `variant` into `dir`, timed from load to records closed.
ModelRun run_model(const std::string& scenario, const char* variant, const std::vector<Override>& extra,
                   const fs::path& dir, const std::atomic<bool>* interrupt) {
  experiment::stop_if_interrupted(interrupt);
  std::vector<Override> o{{"bus", "direct"}, {"clock", "lockstep"}, {"platform.sim.variant", variant}};
  o.insert(o.end(), extra.begin(), extra.end());
  const auto t0 = std::chrono::steady_clock::now();
  Scenario s = load_scenario(scenario, o);
  s.outputs.video.enabled = false, s.outputs.report = false;
  RunOptions ro;
  ro.out_dir = dir.string();
  ro.interrupt = interrupt;
  const RunResult r = run_scenario(s, ro);
  experiment::stop_if_interrupted(interrupt);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return {r.metrics.at("sim_time_s").get<double>() / wall, r.exit_code, ro.out_dir};
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : (v[n / 2 - 1] + v[n / 2]) / 2;
}

}  // namespace

FastModelRow compare_fast_model(const std::string& scenario, const fs::path& dir, int reps,
                                const std::vector<Override>& fast_overrides, const std::atomic<bool>* interrupt) {
  FastModelRow row;
  row.scenario = fs::path(scenario).stem().string();
  std::vector<double> ref_rtf, fast_rtf;
  ModelRun ref, fast;
  for (int k = 0; k < std::max(1, reps); ++k) {
    ref = run_model(scenario, "rollers", {}, dir / "reference", interrupt);
    fast = run_model(scenario, "capsule", fast_overrides, dir / "fast", interrupt);
    ref_rtf.push_back(ref.rtf), fast_rtf.push_back(fast.rtf);
  }
  row.rtf_reference = median(ref_rtf), row.rtf_fast = median(fast_rtf);
  row.exit_reference = ref.exit_code, row.exit_fast = fast.exit_code;
  const Scenario s = load_scenario(scenario, {});
  row.agreement = twist_agreement(read_csv_columns(ref.dir + "/trajectory.csv"),
                                  read_csv_columns(fast.dir + "/trajectory.csv"), s.platform.geometry.L, 1.0);
  return row;
}

namespace {

std::string csv_text(const std::vector<FastModelRow>& rows) {
  std::string out = "scenario,fast_config,twist_error_pct,final_pose_diff_mm,path_m,rtf_reference,rtf_fast,speedup\n";
  for (const FastModelRow& r : rows)
    out += fmt::format("{},{},{:.4f},{:.3f},{:.4f},{:.2f},{:.2f},{:.3f}\n", r.scenario, r.config, 100 * r.agreement.twist_error,
                       1000 * r.agreement.final_pose_diff_m, r.agreement.path_m, r.rtf_reference, r.rtf_fast,
                       r.rtf_fast / r.rtf_reference);
  return out;
}

std::string markdown(const std::vector<FastModelRow>& rows, int reps, bool accurate) {
  std::string md =
      "# fast-model: the capsule model against the roller model\n\n"
      "`omnitwin experiment fast-model`: each scenario on bus direct in lockstep on the reference (variant "
      "`rollers`, 48 rollers on hinges) and on the fast model (variant `capsule`: one short capsule per wheel "
      "on the reference's effective contact line, one floor contact at its centre, anisotropic floor "
      "friction, pyramidal cone, Newton tolerance 1e-5; docs/platform.md), at the reference's 1 ms step and at a 2 ms step "
      "(`--set platform.sim.timestep=0.002`). " +
      fmt::format("{} interleaved run(s) per model; real-time factor = simulated s / wall s of the whole run "
                  "(model compile, physics, drive chains, master, records; no video), median.\n\n",
                  reps) +
      "Twist error: the platform's true twist (vx, vy, L·ωz) averaged over 1 s windows, RMS of the difference "
      "over the RMS of the reference (1 s averages the roller model's ripple, which a smooth wheel does not "
      "have). Final pose difference: where the two platforms ended, translation plus L·heading, against the "
      "reference's travel.\n\n"
      "| scenario | fast model | twist error | final pose difference | reference RTF | fast RTF | speed-up |\n"
      "|---|---|---|---|---|---|---|\n";
  for (const FastModelRow& r : rows)
    md += fmt::format("| {} | {} | {:.3f} % | {:.2f} mm of {:.2f} m ({:.3f} %) | {:.1f}× | {:.1f}× | {:.2f}× |\n",
                      r.scenario, r.config, 100 * r.agreement.twist_error, 1000 * r.agreement.final_pose_diff_m,
                      r.agreement.path_m, 100 * r.agreement.final_pose_diff_m / r.agreement.path_m,
                      r.rtf_reference, r.rtf_fast, r.rtf_fast / r.rtf_reference);
  md += fmt::format("\nAccuracy bound (twist error ≤ {:.1f} % on every scenario and step): **{}**.\n\n",
                    100 * kFastModelTwistBound, accurate ? "met" : "NOT met");
  md += "Speed target (the thesis line at ≥ 2× the reference's real-time factor), reported, not judged (it depends "
        "on the machine's load):";
  for (const FastModelRow& r : rows)
    if (r.scenario == "thesis_line")
      md += fmt::format(" {} {:.2f}× ({});", r.config, r.rtf_fast / r.rtf_reference,
                        r.rtf_fast >= 2 * r.rtf_reference ? "met" : "not met");
  md.back() = '.';
  md += "\n";
  return md;
}

}  // namespace

int run_fast_model(const ExperimentOptions& options) {
  const fs::path dir = experiment::output_dir("fast-model", options);
  const int reps = options.quick ? 1 : 3;
  std::vector<FastModelRow> rows;
  bool accurate = true;
  // The fast model at the reference's step, and at twice it (the step is a scenario key).
  const std::pair<const char*, std::vector<Override>> configs[] = {
      {"1 ms step", {}}, {"2 ms step", {{"platform.sim.timestep", "0.002"}}}};
  for (const char* name : {"thesis_line", "circle", "rotate"}) {
    const std::string scenario = std::string(OMNITWIN_SOURCE_DIR) + "/models/scenarios/" + name + ".yaml";
    for (const auto& [label, overrides] : configs) {
      rows.push_back(compare_fast_model(scenario, dir / "runs" / fmt::format("{}_{}", name, label[0]), reps, overrides,
                                        options.interrupt));
      FastModelRow& r = rows.back();
      r.config = label;
      accurate = accurate && r.agreement.twist_error <= kFastModelTwistBound;
      std::cout << fmt::format("{}, fast model at a {}: twist error {:.3f} %, final pose {:.2f} mm apart, RTF {:.1f}x "
                               "reference, {:.1f}x fast\n",
                               r.scenario, label, 100 * r.agreement.twist_error, 1000 * r.agreement.final_pose_diff_m,
                               r.rtf_reference, r.rtf_fast);
    }
  }
  experiment::stop_if_interrupted(options);
  experiment::write_text(dir / "fast_model.csv", csv_text(rows));
  experiment::write_text(dir / "fast_model.md", markdown(rows, reps, accurate));
  std::cout << "wrote " << (dir / "fast_model.md").string() << " and fast_model.csv\n";
  return accurate ? kExperimentOk : kExperimentCheckFailed;
}

}  // namespace omnitwin::twin
