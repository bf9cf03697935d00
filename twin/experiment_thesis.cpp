// twin layer — the thesis rig shared by thesis-platform and thesis-calibrate (see
// experiment_thesis.hpp): the thesis's numbers and one scored run of the thesis line.
#include "twin/experiment_thesis.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "twin/run.hpp"

namespace omnitwin::twin::thesis {

namespace fs = std::filesystem;

const std::array<Row, 4>& rows() {
  static const std::array<Row, 4> kRows = {{
      {125,
       {13612, 2091, 13702, 2971.9},
       {13919, 2041.9, 14419, 2611.3},
       {7.633, 1.092, 7.652, 2.067},
       {7.755, 1.244, 8.044, 1.807},
       {3174.5, 2453, 3655.5, 2604.5},
       {2278, 2354, 3021.7, 2791.5},
       {2.288, 1.712, 2.450, 1.819},
       {1.634, 1.663, 2.004, 1.927}},
      {250,
       {11207, 2673, 11549, 3069.3},
       {8448.7, 1752.4, 8636.5, 2217.9},
       {6.21, 1.432, 6.370, 2.154},
       {4.585, 0.933, 4.679, 1.550},
       {3338, 2406, 4046, 2487},
       {2107, 2084, 2609.7, 2071},
       {2.367, 1.800, 2.676, 1.771},
       {1.460, 1.458, 1.794, 1.488}},
      {500,
       {11456, 2514, 11758, 2626.5},
       {7850.5, 1617.3, 8035.2, 2238.7},
       {6.3, 1.349, 6.451, 1.809},
       {4.384, 0.864, 4.470, 1.558},
       {2659, 2186, 3343, 2318},
       {2111.3, 2063, 2600, 2180.3},
       {1.826, 1.545, 2.155, 1.709},
       {1.462, 1.420, 1.788, 1.563}},
      {1000,
       {11043, 2139.4, 11263, 2737.8},
       {6741.1, 1307.9, 6879.6, 2308.2},
       {6.07, 1.151, 6.177, 1.945},
       {3.726, 0.718, 3.798, 1.600},
       {2789.5, 2292.5, 3629, 2240},
       {2240, 1891, 3058, 2043.7},
       {2.057, 1.710, 2.382, 1.630},
       {1.501, 1.380, 1.954, 1.566}},
  }};
  return kRows;
}

const Row& row(int rate_kbps) {
  for (const Row& r : rows())
    if (r.rate_kbps == rate_kbps) return r;
  throw std::logic_error("thesis: no thesis row for this bit rate");
}

std::array<ClockReading, 2> clock_readings(const Scenario& s) {
  const double d = std::fabs(s.bus.can.drift[0]);
  const double drift_us = d * s.controller.period * 1e6;  // what the oscillator gains or loses per interrupt
  const double isr_us = s.bus.can.isr_us;                 // what a software reload loses per interrupt
  // Resync before the slip eats the T_post margin the resync leaves (can-dropout's rule).
  // (No slip never eats it: the scenario's K.)
  const auto k_for = [&](double slip_us) {
    const double k = s.bus.can.t_post_us / std::fabs(slip_us);
    return k < s.bus.can.sync_interval ? std::max(1, static_cast<int>(std::floor(k))) : s.bus.can.sync_interval;
  };
  const int k_fast = k_for(isr_us - drift_us);
  const int k_slow = isr_us > 0 ? k_for(isr_us + drift_us) : s.bus.can.sync_interval;
  return {ClockReading{"fast", -d, k_fast}, ClockReading{"slow", d, k_slow}};
}

std::vector<Override> firmware_overrides() { return {{"bus.isr_us", "3300"}}; }

namespace {

double mean(const std::array<double, 4>& v) { return (v[0] + v[1] + v[2] + v[3]) / 4.0; }

}  // namespace

std::vector<Override> bus_overrides(const ClockReading& clock, int rate_kbps, bool sync, int trial, int port) {
  std::vector<Override> o{{"bus", "can"},
                          {"bus.bit_rate", std::to_string(rate_kbps * 1000)},
                          {"bus.drift", fmt::format("{}", clock.drift)},
                          {"bus.sync", sync ? "true" : "false"},
                          {"bus.sync_interval", std::to_string(clock.sync_interval)},
                          {"bus.start_phase", "random"},
                          {"bus.seed", std::to_string(trial + 1)},
                          {"bus.transport", fmt::format("udp:239.74.163.2:{}", port)}};
  for (const auto& f : firmware_overrides()) o.push_back(f);
  return o;
}

Result run_one(const RunSetup& setup, const ClockReading& clock, int rate_kbps, bool sync, int trial, int port) {
  std::vector<Override> o = bus_overrides(clock, rate_kbps, sync, trial, port);
  if (setup.quick) o.push_back({"path.segments.0.line.duration", "4"}), o.push_back({"path.segments.0.line.dx", "0.4"});
  o.insert(o.end(), setup.overrides.begin(), setup.overrides.end());
  Scenario s = load_scenario(setup.scenario, o);
  if (!setup.records) s.outputs.video.enabled = false, s.outputs.report = false;
  RunOptions ro;
  ro.interrupt = setup.interrupt;
  ro.out_dir =
      (setup.dir / fmt::format("{}_{}k_{}_t{}", clock.name, rate_kbps, sync ? "sync" : "nosync", trial)).string();
  const RunResult r = run_scenario(s, ro);
  const nlohmann::json& m = r.metrics;
  const nlohmann::json& od = m.at("platform_odometry");
  Result x;
  x.clock = clock;
  x.rate_kbps = rate_kbps;
  x.sync = sync;
  x.iae_x = od.at("iae_x_cm"), x.iae_y = od.at("iae_y_cm"), x.iae_c = od.at("iae_contour_cm");
  x.std_x = od.at("std_x_cm"), x.std_y = od.at("std_y_cm"), x.std_c = od.at("std_contour_cm");
  x.true_iae_c = m.at("platform").at("iae_contour_cm");
  x.true_final = m.at("platform").at("final_error_cm");
  // The axes as the thesis's master logged them: per control period, the command it sent minus
  // the feedback it received (reading_sync.md, H9); a run without that view gives the slaves'.
  for (std::size_t k = 0; k < 4; ++k) {
    const nlohmann::json& a = m.at("axes").at(k);
    const bool at_master = a.contains("iae_velocity_pulse_at_master") && !a.at("iae_velocity_pulse_at_master").is_null();
    x.axes_iae[k] = a.at(at_master ? "iae_velocity_pulse_at_master" : "iae_velocity_pulse").get<double>();
    x.axes_std[k] = a.at(at_master ? "std_velocity_pulse_at_master" : "std_velocity_pulse").get<double>();
  }
  x.axis_iae = mean(x.axes_iae), x.axis_std = mean(x.axes_std);
  x.dropout_pct = 100.0 * m.at("bus").at("dropout_rate").get<double>();
  x.load_pct = 100.0 * m.at("bus").at("load").get<double>();
  x.exit_code = r.exit_code;
  x.master_state = m.at("master").at("state");
  for (const auto& sl : m.at("slaves")) x.stale += static_cast<double>(sl.at("stale_samples").get<std::uint64_t>());
  x.c_min = x.c_max = x.iae_c;
  x.a_min = x.a_max = x.axis_iae;
  x.run_dir = ro.out_dir;
  return x;
}

Result average(const std::vector<Result>& ts) {
  Result m = ts.front();
  m.trials = static_cast<int>(ts.size());
  for (double Result::*f : {&Result::iae_x, &Result::iae_y, &Result::iae_c, &Result::std_x, &Result::std_y,
                            &Result::std_c, &Result::true_iae_c, &Result::true_final, &Result::axis_iae,
                            &Result::axis_std, &Result::dropout_pct, &Result::load_pct, &Result::stale}) {
    double sum = 0;
    for (const Result& t : ts) sum += t.*f;
    m.*f = sum / static_cast<double>(ts.size());
  }
  for (std::size_t k = 0; k < 4; ++k) {
    double iae = 0, sd = 0;
    for (const Result& t : ts) iae += t.axes_iae[k], sd += t.axes_std[k];
    m.axes_iae[k] = iae / static_cast<double>(ts.size());
    m.axes_std[k] = sd / static_cast<double>(ts.size());
  }
  for (const Result& t : ts) {
    m.c_min = std::min(m.c_min, t.iae_c), m.c_max = std::max(m.c_max, t.iae_c);
    m.a_min = std::min(m.a_min, t.axis_iae), m.a_max = std::max(m.a_max, t.axis_iae);
    m.exit_code = std::max(m.exit_code, t.exit_code);
    if (t.master_state != m.master_state) m.master_state = "mixed";
  }
  return m;
}

Scenario load_with_sets(const std::string& path, const std::vector<Override>& sets) {
  std::vector<Override> o{{"bus", "can"}};
  for (const auto& f : firmware_overrides()) o.push_back(f);
  o.insert(o.end(), sets.begin(), sets.end());
  return load_scenario(path, o);
}

std::string sets_text(const std::vector<Override>& sets) {
  std::string t;
  for (const Override& o : sets) t += fmt::format("{}--set {}={}", t.empty() ? "" : " ", o.key, o.value);
  return t;
}

std::string note_sets(std::string text, const std::vector<Override>& sets, bool yaml) {
  if (sets.empty()) return text;
  if (yaml) {
    const std::size_t at = text.find("\nname:");
    return text.insert(at == std::string::npos ? 0 : at + 1,
                       fmt::format("# Every run of the fit had {}: give thesis-platform the same.\n", sets_text(sets)));
  }
  const std::size_t at = text.find("\n\n");
  return text.insert(at == std::string::npos ? text.size() : at + 2,
                     fmt::format("Every run also had `{}` (the experiment's --set).\n\n", sets_text(sets)));
}

std::string plain_scenario() { return std::string(OMNITWIN_SOURCE_DIR) + "/models/scenarios/thesis_line.yaml"; }
std::string fitted_scenario() { return std::string(OMNITWIN_SOURCE_DIR) + "/models/scenarios/thesis_line_fitted.yaml"; }
std::string source_relative(const fs::path& p) {
  const fs::path source = fs::path(OMNITWIN_SOURCE_DIR).lexically_normal();
  const std::string rel = fs::absolute(p).lexically_normal().lexically_relative(source).string();
  return !rel.empty() && rel.rfind("..", 0) != 0 ? rel : "";
}

std::string default_scenario() { return fs::exists(fitted_scenario()) ? fitted_scenario() : plain_scenario(); }

}  // namespace omnitwin::twin::thesis
