// twin layer — `omnitwin replay` (see replay.hpp).
#include "twin/replay.hpp"

#include "media/json_problem.hpp"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <stdexcept>

#include "physics/platform_sim.hpp"
#include "twin/clock.hpp"
#include "twin/csv_columns.hpp"

namespace omnitwin::twin {

namespace fs = std::filesystem;

namespace {

// Bad input in the run directory (exit 2), as opposed to a runtime failure.
struct BadRun : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct Replayed {
  double sim_s = 0, wall_s = 0;
  std::uint64_t steps = 0;
  double x = 0, y = 0;
  bool interrupted = false;
};

// The set-point columns, after checking every row: a header-only file (an interrupted run
// can leave one) or a torn row (NaN, t not increasing) is bad input naming the file and line
// (found in review: a crash on the first, "apart nan cm" and exit 0 on the second).
std::array<const std::vector<double>*, 4> checked_setpoints(const CsvColumns& tr) {
  if (tr.rows() == 0) throw BadRun(tr.file + " holds no samples (only a header)");
  const auto& t = tr.column("t");
  std::array<const std::vector<double>*, 4> w{};
  for (int i = 0; i < 4; ++i) w[static_cast<std::size_t>(i)] = &tr.column(fmt::format("w{}_setpoint_rad_s", i + 1));
  const auto& x = tr.column("x");
  const auto& y = tr.column("y");
  for (std::size_t k = 0; k < t.size(); ++k) {
    const std::size_t line = k + 2;  // line 1 is the header
    if (!std::isfinite(t[k])) throw BadRun(fmt::format("{}:{}: t is not a finite number", tr.file, line));
    if (k > 0 && !(t[k] > t[k - 1]))
      throw BadRun(fmt::format("{}:{}: t {} does not increase (the previous row's is {})", tr.file, line, t[k], t[k - 1]));
    bool finite = std::isfinite(x[k]) && std::isfinite(y[k]);
    for (const auto* c : w) finite = finite && std::isfinite((*c)[k]);
    if (!finite) throw BadRun(fmt::format("{}:{}: a set-point or the pose is not a finite number (a torn row?)", tr.file, line));
  }
  return w;
}

// Steps `sim` through the recorded samples: each row's set-points until the next row's time;
// it ends at the last sample's time, the instant whose recorded pose it is compared with.
Replayed replay(physics::PlatformSim& sim, const CsvColumns& tr, const std::array<const std::vector<double>*, 4>& w,
                const std::atomic<bool>* interrupt) {
  const auto& t = tr.column("t");
  Replayed r;
  const std::int64_t t0 = monotonic_ns();
  for (std::size_t k = 0; k < t.size(); ++k) {
    if (interrupt && interrupt->load()) {
      r.interrupted = true;
      break;
    }
    for (int i = 0; i < 4; ++i) sim.set_wheel_speed_setpoint(i, (*w[static_cast<std::size_t>(i)])[k]);
    const double until = k + 1 < t.size() ? t[k + 1] : t[k];
    while (sim.time() < until - 0.5 * sim.timestep()) {
      sim.step();
      ++r.steps;
    }
  }
  r.wall_s = (monotonic_ns() - t0) * 1e-9;
  r.sim_s = sim.time();
  r.x = sim.data()->qpos[0];
  r.y = sim.data()->qpos[1];
  return r;
}

// What the run was made with (run.json): its scenario's name, its --set overrides and start
// pose, so that the replay's physics is the run's (found in review: they were ignored).
struct RunRecord {
  std::string scenario;
  std::vector<Override> overrides;
  std::array<double, 3> start_pose{};
};

RunRecord read_run_json(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw BadRun(file.string() + ": no such file (is " + file.parent_path().string() + " a run directory?)");
  RunRecord r;
  try {
    const nlohmann::json j = nlohmann::json::parse(in);
    r.scenario = j.at("scenario").get<std::string>();
    for (const auto& o : j.at("overrides")) r.overrides.push_back(parse_override(o.get<std::string>()));
    const auto& p = j.at("start_pose");
    if (!p.is_array() || p.size() != 3) throw BadRun(file.string() + ": start_pose is not [x, y, phi]");
    for (std::size_t i = 0; i < 3; ++i) r.start_pose[i] = p.at(i).get<double>();
  } catch (const BadRun&) {
    throw;
  } catch (const std::exception& e) {
    throw BadRun(file.string() + ": " + media::json_problem(e));
  }
  return r;
}

}  // namespace

int cmd_replay(const std::string& scenario_path, const std::string& run_dir, const std::vector<Override>& overrides,
               const std::atomic<bool>* interrupt) {
  try {
    const fs::path dir(run_dir), model = dir / "platform.xml";
    if (!fs::is_regular_file(model)) {
      std::cerr << "omnitwin replay: " << model.string() << ": no such file (is " << run_dir << " a run directory?)\n";
      return 2;
    }
    const RunRecord rec = read_run_json(dir / "run.json");
    // The run's overrides first, then this command's --set on top.
    std::vector<Override> all = rec.overrides;
    all.insert(all.end(), overrides.begin(), overrides.end());
    const Scenario named = load_scenario(scenario_path, overrides);
    if (named.name != rec.scenario) {
      std::cerr << "omnitwin replay: " << scenario_path << " is scenario '" << named.name << "', but the run in "
                << run_dir << " was made from '" << rec.scenario << "' (run.json)\n";
      return 2;
    }
    Scenario s = load_scenario(scenario_path, all);
    const CsvColumns tr = read_csv_columns((dir / "trajectory.csv").string());
    const auto w = checked_setpoints(tr);
    physics::PlatformSim sim = physics::PlatformSim::from_file(model.string(), s.platform);
    sim.reset(rec.start_pose[0], rec.start_pose[1], rec.start_pose[2]);
    const Replayed r = replay(sim, tr, w, interrupt);
    if (r.interrupted) {
      std::cerr << "omnitwin replay: interrupted at " << fmt::format("{:.2f}", r.sim_s) << " s simulated\n";
      return 3;
    }
    const double rx = tr.column("x").back(), ry = tr.column("y").back();
    std::cout << fmt::format("replay {}: {} samples, {} physics steps, {:.2f} s simulated in {:.3f} s wall ({:.1f}x real time)\n",
                             run_dir, tr.rows(), r.steps, r.sim_s, r.wall_s, r.wall_s > 0 ? r.sim_s / r.wall_s : 0.0);
    std::cout << fmt::format("  final position {:.4f} {:.4f} m; the recorded run's {:.4f} {:.4f} m (apart {:.3f} cm)\n", r.x,
                             r.y, rx, ry, 100 * std::hypot(r.x - rx, r.y - ry));
    if (sim.warning_count() > 0) std::cout << "  MuJoCo warnings: " << sim.warning_count() << "\n";
    return 0;
  } catch (const ScenarioError& e) {
    std::cerr << "omnitwin replay: " << e.what() << "\n";
    return 2;
  } catch (const BadRun& e) {
    std::cerr << "omnitwin replay: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    // A missing or unreadable trajectory.csv or column names the file: bad input too.
    std::cerr << "omnitwin replay: " << e.what() << "\n";
    return 2;
  }
}

}  // namespace omnitwin::twin
