// twin layer — a bounded Nelder–Mead minimiser for the calibration experiments
// (`omnitwin experiment thesis-calibrate`).
//
// The objective there is a whole twin run (a master process, four slaves, MuJoCo): seconds per
// evaluation, no gradient, a little noise from the slaves' random start phases. Nelder–Mead
// needs nothing but values, and few of them. The search lives in the unit box [0, 1]^n (the
// caller maps each coordinate onto its parameter's bounds), every trial point is projected
// onto the box before it is evaluated, and every evaluation is kept so the caller can write
// the whole trace beside the result.
#pragma once

#include <functional>
#include <vector>

namespace omnitwin::twin {

struct NelderMeadOptions {
  int max_evaluations = 100;   // hard budget of objective calls, >= n + 1
  double initial_step = 0.25;  // edge of the starting simplex along each axis (box units)
  double tolerance = 1e-3;     // stop when the simplex's values differ by less than this
};

struct NelderMeadEvaluation {
  std::vector<double> x;  // the point evaluated (inside the box)
  double value = 0;
};

struct NelderMeadResult {
  std::vector<double> x;                    // best point found, in [0, 1]^n
  double value = 0;                         // objective there
  int evaluations = 0;                      // objective calls made
  bool converged = false;                   // the tolerance stopped it (false: the budget did)
  std::vector<NelderMeadEvaluation> trace;  // every call, in order
};

// Minimises `f` over [0, 1]^n from `x0` (clamped into the box). Deterministic for a
// deterministic `f`. Throws std::invalid_argument for an empty x0 or a budget below n + 1.
NelderMeadResult nelder_mead(const std::function<double(const std::vector<double>&)>& f, std::vector<double> x0,
                             const NelderMeadOptions& options = {});

}  // namespace omnitwin::twin
