// twin layer — `omnitwin replay` (see replay.hpp).
#include "twin/replay.hpp"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>

#include "physics/platform_sim.hpp"
#include "twin/clock.hpp"
#include "twin/csv_columns.hpp"

namespace omnitwin::twin {

namespace fs = std::filesystem;

namespace {

struct Replayed {
  double sim_s = 0, wall_s = 0;
  std::uint64_t steps = 0;
  double x = 0, y = 0;
};

// Steps `sim` through the recorded samples: each row's set-points until the next row's time.
Replayed replay(physics::PlatformSim& sim, const CsvColumns& tr) {
  const auto& t = tr.column("t");
  std::array<const std::vector<double>*, 4> w{};
  for (int i = 0; i < 4; ++i) w[static_cast<std::size_t>(i)] = &tr.column(fmt::format("w{}_setpoint_rad_s", i + 1));
  Replayed r;
  const std::int64_t t0 = monotonic_ns();
  for (std::size_t k = 0; k < t.size(); ++k) {
    for (int i = 0; i < 4; ++i) sim.set_wheel_speed_setpoint(i, (*w[static_cast<std::size_t>(i)])[k]);
    const double until = k + 1 < t.size() ? t[k + 1] : t[k] + (k > 0 ? t[k] - t[k - 1] : 0);
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

}  // namespace

int cmd_replay(const std::string& scenario_path, const std::string& run_dir, const std::vector<Override>& overrides) {
  try {
    const Scenario s = load_scenario(scenario_path, overrides);
    const fs::path dir(run_dir), model = dir / "platform.xml";
    if (!fs::is_regular_file(model)) {
      std::cerr << "omnitwin replay: " << model.string() << ": no such file (is " << run_dir << " a run directory?)\n";
      return 2;
    }
    const CsvColumns tr = read_csv_columns((dir / "trajectory.csv").string());
    physics::PlatformSim sim = physics::PlatformSim::from_file(model.string(), s.platform);
    sim.reset(s.path.x0, s.path.y0, s.path.phi0_deg * std::acos(-1.0) / 180.0);
    const Replayed r = replay(sim, tr);
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
  } catch (const std::exception& e) {
    std::cerr << "omnitwin replay: " << e.what() << "\n";
    return 2;
  }
}

}  // namespace omnitwin::twin
