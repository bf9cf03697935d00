// twin layer — `omnitwin sweep SPEC.yaml`: one scenario over a parameter grid or seeded random
// draws, every point a full run with its records, collected into one table and one plot.
//
// SPEC.yaml (paths relative to the spec's folder; unknown keys are errors naming line and key):
//   name: kp_sweep                      # the output folder's name (default: the file's stem)
//   scenario: ../models/scenarios/thesis_line.yaml
//   grid:                               # every combination, the last key varying fastest
//     controller.period: [0.005, 0.010]
//     controller.kp: [[2, 2, 2], [6, 6, 6]]   # any YAML value a --set takes
//   random:                             # and/or seeded draws (each combined with every grid point)
//     draws: 8
//     seed: 1
//     params:
//       platform.motor.friction_torque: {min: 0.0, max: 0.2}
//       bus.bit_rate: {values: [125000, 500000]}
//   metrics: [platform.final_error_cm, platform.iae_contour_cm, real_time_factor]
//   plot: {x: controller.period, y: platform.final_error_cm}   # default: first param, first metric
//
// Output (--out, default out/sweep/NAME): points/NNNN/ the run directory of point NNNN (1-based)
// with point.json {point, params, notes, exit_code, passed, error} (notes: what the point's
// overrides changed beyond their own keys, said once per distinct note on stderr); sweep.csv (point, each param, each
// metric, passed, exit_code); sweep.png (plot.y against plot.x, one line per combination of
// the other parameters, failed expectations marked). Locally the points run -j at a time;
// --slurm writes sweep.sbatch (a job array, one task per point, each `omnitwin sweep SPEC
// --point K`), submits it with `sbatch --wait`, then collects what the tasks wrote.
// Before the points run, what an earlier sweep left under points/ is removed, so the table
// holds this sweep's results only.
// Exit: 0 every point ran (its expectations are data, not a verdict); 2 a bad spec (its
// first point must load); 3 a later point did not load, failed to run or left no result, or
// an interruption.
// Not real-time code.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace omnitwin::twin {

struct SweepSpec {
  std::string file;      // the spec's path
  std::string name;
  std::string scenario;  // resolved against the spec's folder
  std::vector<std::string> params;                              // in column order
  std::vector<std::vector<std::pair<std::string, std::string>>> points;  // key → --set value, per point
  std::vector<std::string> metrics;
  std::string plot_x, plot_y;
};

// Loads and expands a spec; throws ScenarioError (file, line, key) on any problem.
SweepSpec load_sweep(const std::string& path);

struct SweepOptions {
  std::string out;       // default out/sweep/NAME
  int jobs = 0;          // points at once; 0 = the machine's cores
  int point = 0;         // > 0: run only this point (what a Slurm task does)
  bool slurm = false;
  std::string sbatch = "sbatch";  // the submit command (a test may point elsewhere)
  std::atomic<bool>* interrupt = nullptr;
};

int cmd_sweep(const std::string& spec, const SweepOptions& opt);

}  // namespace omnitwin::twin
