// twin layer — IAE and σ accumulators; see metrics.hpp.
#include "twin/metrics.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace omnitwin::twin {

namespace {

constexpr double kCm = 100.0;                       // m -> cm
constexpr double kDeg = 180.0 / std::numbers::pi;  // rad -> deg

// σ of eq. 4-15 from Σe² over n samples (0 with no samples).
double rms(double sum_sq, std::size_t n) { return n == 0 ? 0.0 : std::sqrt(sum_sq / n); }

// The larger of a and b, NaN once either is: a worst case that skipped a NaN sample would
// pass a bound no sample was checked against (std::max drops a NaN second argument).
double max_keeping_nan(double a, double b) { return std::isnan(a) || std::isnan(b) ? std::nan("") : std::max(a, b); }

// The figures of an accumulator that got no sample: each null, and "samples": 0.
nlohmann::json without_samples(std::initializer_list<const char*> keys) {
  nlohmann::json j = nlohmann::json::object();
  for (const char* k : keys) j[k] = nullptr;
  j["samples"] = 0;
  return j;
}

}  // namespace

void PoseErrorStats::add(double ex_m, double ey_m, double ephi_rad) {
  const double ec = std::hypot(ex_m, ey_m);
  // Running sums for IAE (eq. 4-14) and σ (eq. 4-15).
  abs_x_ += std::abs(ex_m);
  abs_y_ += std::abs(ey_m);
  abs_c_ += ec;
  abs_phi_ += std::abs(ephi_rad);
  sq_x_ += ex_m * ex_m;
  sq_y_ += ey_m * ey_m;
  sq_c_ += ec * ec;
  sq_phi_ += ephi_rad * ephi_rad;
  // Last and worst samples.
  final_c_ = ec;
  final_phi_ = std::abs(ephi_rad);
  max_c_ = max_keeping_nan(max_c_, ec);
  max_phi_ = max_keeping_nan(max_phi_, final_phi_);
  ++n_;
}

nlohmann::json PoseErrorStats::to_json() const {
  // No sample, no figure: null, so that a bound on it fails as "not a number" instead of
  // passing on a 0 nothing was measured for (e.g. odometry outside lockstep).
  if (n_ == 0) return without_samples({"iae_x_cm", "iae_y_cm", "iae_contour_cm", "std_x_cm", "std_y_cm",
                                       "std_contour_cm", "final_error_cm", "max_error_cm", "iae_phi_deg",
                                       "std_phi_deg", "final_phi_error_deg", "max_phi_error_deg"});
  return nlohmann::json{
      {"iae_x_cm", abs_x_ * kCm},
      {"iae_y_cm", abs_y_ * kCm},
      {"iae_contour_cm", abs_c_ * kCm},
      {"std_x_cm", rms(sq_x_, n_) * kCm},
      {"std_y_cm", rms(sq_y_, n_) * kCm},
      {"std_contour_cm", rms(sq_c_, n_) * kCm},
      {"final_error_cm", final_c_ * kCm},
      {"max_error_cm", max_c_ * kCm},
      {"iae_phi_deg", abs_phi_ * kDeg},
      {"std_phi_deg", rms(sq_phi_, n_) * kDeg},
      {"final_phi_error_deg", final_phi_ * kDeg},
      {"max_phi_error_deg", max_phi_ * kDeg},
      {"samples", n_},
  };
}

void VelocityErrorStats::add(double err_pulses) {
  abs_ += std::abs(err_pulses);
  sq_ += err_pulses * err_pulses;
  ++n_;
}

nlohmann::json VelocityErrorStats::to_json(const std::string& suffix) const {
  if (n_ == 0)
    return nlohmann::json{
        {"iae_velocity_pulse" + suffix, nullptr}, {"std_velocity_pulse" + suffix, nullptr}, {"samples" + suffix, 0}};
  return nlohmann::json{
      {"iae_velocity_pulse" + suffix, abs_},
      {"std_velocity_pulse" + suffix, rms(sq_, n_)},
      {"samples" + suffix, n_},
  };
}

void DriveHistory::add(double t_s, const std::array<DriveStateCode, 4>& states, bool in_run) {
  int running = 0;
  for (std::size_t i = 0; i < states.size(); ++i) {
    const DriveStateCode st = states[i];
    if (st == DriveStateCode::running || st == DriveStateCode::syncing) ++running;
    if (st == DriveStateCode::fault && last_[i] != DriveStateCode::fault) ++faults_;
    last_[i] = st;
  }
  running_now_ = running;
  if (in_run) running_in_run_ = running;
  if (all_running_at_ < 0 && running == static_cast<int>(states.size())) all_running_at_ = t_s;
  if (all_running_at_ >= 0 && stopped_at_ < 0 && running == 0) stopped_at_ = t_s;
}

nlohmann::json DriveHistory::to_json() const {
  return {{"all_running_at_s", all_running_at_},
          {"stopped_at_s", stopped_at_},
          {"faults", faults_},
          {"running_at_end", running_now_},
          {"running_at_duration", running_in_run_}};
}

void merge_master_stats(nlohmann::json& master, const nlohmann::json& stats) {
  if (!stats.is_object()) return;
  for (const auto& [key, value] : stats.items()) {
    if (master.contains(key))
      master["stats_" + key] = value;  // the twin's value (the sim-clock report) stays
    else
      master[key] = value;
  }
}

}  // namespace omnitwin::twin
