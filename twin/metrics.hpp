// twin layer — the thesis's tracking indices, accumulated over control samples.
//
// Seed 002 scores runs with IAE = Σ|e_i| (eq. 4-14) and σ = sqrt(Σe_i²/N) (eq. 4-15) over
// the samples of the control loop — sums, not integrals (no dt) — so our metrics.json and
// the thesis tables compare directly. The accumulators keep running sums only, so add() is
// allocation-free and can sit in the stepping loop; to_json() is called once at the end.
#pragma once

#include <nlohmann/json.hpp>

#include <array>
#include <cstddef>

#include "twin/run_state.hpp"

namespace omnitwin::twin {

// Position/heading error of the platform against the reference path.
class PoseErrorStats {
 public:
  // One control sample: errors in world x, y [m] and heading [rad] (reference - actual).
  // Real-time safe.
  void add(double ex_m, double ey_m, double ephi_rad);

  std::size_t samples() const { return n_; }

  // iae_x_cm, iae_y_cm, iae_contour_cm, std_x_cm, std_y_cm, std_contour_cm, final_error_cm,
  // max_error_cm, iae_phi_deg, std_phi_deg, final_phi_error_deg, max_phi_error_deg, samples.
  // The contour error is sqrt(ex² + ey²); every figure null with no samples, and the max
  // figures NaN once a sample was. Not real-time safe.
  nlohmann::json to_json() const;

 private:
  std::size_t n_ = 0;
  double abs_x_ = 0, abs_y_ = 0, abs_c_ = 0, abs_phi_ = 0;  // Σ|e| [m, m, m, rad]
  double sq_x_ = 0, sq_y_ = 0, sq_c_ = 0, sq_phi_ = 0;      // Σe² [m², m², m², rad²]
  double final_c_ = 0, max_c_ = 0, final_phi_ = 0, max_phi_ = 0;  // [m, m, rad, rad], abs
};

// Velocity error of one wheel axis, in encoder pulses (counts) per control sample.
class VelocityErrorStats {
 public:
  // One sample: commanded minus measured [pulses]. Real-time safe.
  void add(double err_pulses);

  std::size_t samples() const { return n_; }

  // iae_velocity_pulse, std_velocity_pulse (null with no samples), samples; with a suffix
  // (e.g. "_at_master") the same keys carry it. Not real-time safe.
  nlohmann::json to_json(const std::string& suffix = "") const;

 private:
  std::size_t n_ = 0;
  double abs_ = 0, sq_ = 0;
};

// What the drives did over a run, sampled at each control sample: how a master is judged when
// it commissions them (an external master of `omnitwin twin` above all). A drive counts as
// running when its state is running or syncing.
class DriveHistory {
 public:
  // One control sample at t [s] with the four drives' states; in_run: at or before the run's
  // end (its duration, or the interrupt), not in the master's shutdown after it. Real-time safe.
  void add(double t_s, const std::array<DriveStateCode, 4>& states, bool in_run = true);
  // all_running_at_s: the first sample with every drive running (-1: never);
  // stopped_at_s: the first sample after that with none running (-1: never);
  // faults: transitions of a drive into fault; running_at_end: drives running at the last
  // sample (what the master's shutdown left); running_at_duration: at the last sample in the
  // run (what the run left, before the shutdown). Not real-time safe.
  nlohmann::json to_json() const;

 private:
  double all_running_at_ = -1, stopped_at_ = -1;
  int faults_ = 0, running_now_ = 0, running_in_run_ = 0;
  std::array<DriveStateCode, 4> last_{};
};

// metrics.json `master`: the master's own counters (master-stats.json) merged into what the
// twin knows of it. The sim-clock report is authoritative for what both hold (`state`,
// `stop_reason`: by name, as docs/scenarios.md says): such a key keeps the twin's value and
// the master's own goes under `stats_KEY` (the EtherCAT master's free-text stop reason, its
// state word). Every other key is added as it is. Not real-time safe.
void merge_master_stats(nlohmann::json& master, const nlohmann::json& stats);

}  // namespace omnitwin::twin
