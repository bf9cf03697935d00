// twin layer — the `omnitwin` command line (CLI11): run, check, model.
//
// Exit codes (DESIGN §9): 0 ok and expectations met; 1 expectations failed; 2 bad usage or
// bad input (the message names file, line and key); 3 runtime failure (including a run
// ended by SIGINT/SIGTERM, whose records are still closed and valid).
#include <CLI/CLI.hpp>
#include <mujoco/mujoco.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <optional>

#include "physics/platform_mjcf.hpp"
#include "twin/clock.hpp"
#include "twin/experiment.hpp"
#include "twin/junit.hpp"
#include "twin/progress.hpp"
#include "twin/run.hpp"
#include "twin/scenario.hpp"

namespace fs = std::filesystem;
using namespace omnitwin;
using namespace omnitwin::twin;

namespace {

std::atomic<bool> g_interrupt{false};  // the one process-wide flag a signal handler may set

void on_signal(int) { g_interrupt.store(true); }

// MuJoCo's own handlers print to stdout, append to MUJOCO_LOG.TXT in the working directory
// and exit(1) on errors, which would read as "expectations failed". Route both through our
// log; a MuJoCo error is a runtime failure (exit 3).
void mujoco_warning(const char* msg) { spdlog::warn("MuJoCo: {}", msg); }
[[noreturn]] void mujoco_error(const char* msg) {
  spdlog::critical("MuJoCo error: {}", msg);
  std::exit(3);
}

void install_signal_handlers() {
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
}

struct RunArgs {
  std::string scenario;
  std::string out;
  std::string bus;
  std::string clock;
  std::vector<std::string> sets;
  bool no_progress = false;
  bool external_master = false;  // `omnitwin twin`
};

std::vector<Override> collect_overrides(const RunArgs& a) {
  std::vector<Override> o;
  if (!a.bus.empty()) o.push_back({"bus", a.bus});
  if (!a.clock.empty()) o.push_back({"clock", a.clock});
  for (const auto& s : a.sets) o.push_back(parse_override(s));
  return o;
}

void print_summary(const RunResult& r) {
  const auto& m = r.metrics;
  std::cout << fmt::format("{} ({} bus, {} clock): {:.2f} s simulated in {:.2f} s wall ({:.1f}x real time)\n",
                           m.value("scenario", "?"), m["bus"].value("name", "?"), m.value("clock", "?"),
                           m.value("sim_time_s", 0.0), m.value("wall_time_s", 0.0),
                           m.value("real_time_factor", 0.0));
  const auto& p = m["platform"];
  std::cout << fmt::format("  final error {:.3f} cm, max error {:.3f} cm, IAE contour {:.1f} cm, sigma contour {:.3f} cm\n",
                           p.value("final_error_cm", 0.0), p.value("max_error_cm", 0.0),
                           p.value("iae_contour_cm", 0.0), p.value("std_contour_cm", 0.0));
  if (m.contains("realtime")) {
    const auto& rt = m["realtime"];
    std::cout << fmt::format("  realtime ({}): {} ticks, {} overruns, jitter mean {:.1f} us, p99 {:.1f} us, max {:.1f} us\n",
                             rt.value("scheduling", "?"), rt.value("ticks", 0), rt.value("overruns", 0), rt.value("jitter_mean_us", 0.0),
                             rt.value("jitter_p99_us", 0.0), rt.value("jitter_max_us", 0.0));
  }
  if (m.contains("master")) {
    const auto& ms = m["master"];
    const auto& b = m["bus"];
    std::cout << fmt::format("  master {} ({}), {}; bus {} frames, {} error frames, load {:.1f} %, dropouts {} ({:.2f} %)\n",
                             ms.value("state", "?"), ms.value("stop_reason", "?"), ms.value("exit", "?"),
                             b.value("frames", 0), b.value("error_frames", 0), 100.0 * b.value("load", 0.0),
                             b.value("dropouts", 0), 100.0 * b.value("dropout_rate", 0.0));
  }
  if (r.interrupted) std::cout << "  INTERRUPTED: records were closed at the point reached\n";
  if (!r.error.empty()) std::cout << "  ERROR: " << r.error << "\n";
  for (const auto& f : m["expectations"]["failures"]) std::cout << "  FAILED: " << f.get<std::string>() << "\n";
  std::cout << "  expectations: " << (r.passed ? "passed" : "FAILED") << "\n";
  for (const char* f : {"metrics.json", "trajectory.csv", "events.log", "bus-can.pcap", "master.log"})
    if (fs::exists(fs::path(r.out_dir) / f)) std::cout << "  " << (fs::path(r.out_dir) / f).string() << "\n";
}

int cmd_run(const RunArgs& a) {
  try {
    const Scenario s = load_scenario(a.scenario, collect_overrides(a));
    RunOptions o;
    o.out_dir = a.out.empty() ? (fs::path("out") / s.name).string() : a.out;
    o.progress = !a.no_progress && stderr_is_terminal();
    o.interrupt = &g_interrupt;
    o.external_master = a.external_master;
    if (a.external_master)
      std::cout << fmt::format("twin {}: CAN bus on {} at {} bit/s, waiting for a master (Ctrl-C ends)\n", s.name,
                               s.bus.can.transport, s.bus.can.bit_rate)
                << std::flush;
    const RunResult r = run_scenario(s, o);
    print_summary(r);
    return r.exit_code;
  } catch (const ScenarioError& e) {
    std::cerr << "omnitwin: " << e.what() << "\n";
    return 2;
  } catch (const RunSetupError& e) {
    std::cerr << "omnitwin: " << a.scenario << ": " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "omnitwin: run failed: " << e.what() << "\n";
    return 3;
  }
}

// The scenario files under the given paths: files as given, directories searched
// recursively for *.yaml, in sorted order so reports are stable.
std::vector<std::string> scenario_files(const std::vector<std::string>& paths) {
  std::vector<std::string> files;
  for (const auto& p : paths) {
    if (!fs::is_directory(p)) {
      files.push_back(p);
      continue;
    }
    std::vector<std::string> found;
    for (const auto& e : fs::recursive_directory_iterator(p))
      if (e.is_regular_file() && (e.path().extension() == ".yaml" || e.path().extension() == ".yml"))
        found.push_back(e.path().string());
    std::sort(found.begin(), found.end());
    files.insert(files.end(), found.begin(), found.end());
  }
  return files;
}

JunitCase check_one(const std::string& file, const std::string& out_root, std::map<std::string, std::string>& used,
                    bool& bad_input) {
  JunitCase c;
  c.name = fs::path(file).stem().string();
  c.classname = "omnitwin.check";
  const std::int64_t t0 = monotonic_ns();
  try {
    const Scenario s = load_scenario(file);
    c.name = s.name;
    // Each scenario gets its own run directory: two files with one name would overwrite.
    if (const auto [it, fresh] = used.emplace(s.name, file); !fresh)
      throw ScenarioError(file, 0, "name", fmt::format("'{}' is already the name of {}", s.name, it->second));
    RunOptions o;
    o.out_dir = (fs::path(out_root) / s.name).string();
    o.interrupt = &g_interrupt;
    const RunResult r = run_scenario(s, o);
    c.passed = r.passed && !r.interrupted;
    for (const auto& f : r.metrics["expectations"]["failures"]) c.failures.push_back(f.get<std::string>());
    if (r.interrupted) c.failures.push_back("interrupted");
    c.system_out = r.metrics.dump(2);
  } catch (const ScenarioError& e) {
    c.error = true, bad_input = true;
    c.failures.push_back(e.what());
  } catch (const RunSetupError& e) {
    c.error = true, bad_input = true;
    c.failures.push_back(file + ": " + e.what());
  } catch (const std::exception& e) {
    c.error = true;
    c.failures.push_back(std::string("run failed: ") + e.what());
  }
  c.time_s = (monotonic_ns() - t0) * 1e-9;
  return c;
}

int cmd_check(const std::vector<std::string>& paths, const std::string& junit, const std::string& out_root) {
  const auto files = scenario_files(paths);
  if (files.empty()) {
    std::cerr << "omnitwin check: no scenario files under the given paths\n";
    return 2;
  }
  std::vector<JunitCase> cases;
  std::map<std::string, std::string> used;
  bool bad_input = false;
  int passed = 0, failed = 0;
  for (const auto& f : files) {
    if (g_interrupt.load()) break;
    JunitCase c = check_one(f, out_root, used, bad_input);
    (c.passed ? passed : failed)++;
    std::cout << fmt::format("{} {} ({:.1f} s)\n", c.passed ? "PASS" : (c.error ? "ERROR" : "FAIL"), c.name, c.time_s);
    for (const auto& msg : c.failures) std::cout << "     " << msg << "\n";
    cases.push_back(std::move(c));
  }
  std::cout << passed << " passed, " << failed << " failed\n";
  if (!junit.empty()) {
    try {
      write_junit(junit, "omnitwin check", cases);
    } catch (const std::exception& e) {
      std::cerr << "omnitwin check: cannot write the JUnit report: " << e.what() << "\n";
      return 3;
    }
  }
  if (bad_input) return 2;
  if (g_interrupt.load()) return 3;
  return failed ? 1 : 0;
}

int cmd_model(const std::string& scenario, const std::string& variant, const std::string& out) {
  try {
    physics::PlatformParams p;
    if (!scenario.empty()) p = load_scenario(scenario).platform;
    if (!p.sim.mjcf.empty()) {
      std::cerr << "omnitwin model: " << scenario << " runs its own MJCF (" << p.sim.mjcf << "); nothing is generated\n";
      return 2;
    }
    if (variant == "rollers") p.sim.variant = physics::ModelVariant::rollers;
    if (variant == "capsule") p.sim.variant = physics::ModelVariant::capsule;
    const std::string xml = physics::platform_mjcf(p);
    if (out.empty() || out == "-") {
      std::cout << xml;
      return 0;
    }
    std::ofstream f(out, std::ios::binary);
    f << xml;
    if (!f.flush()) throw std::runtime_error("cannot write " + out);
    std::cout << out << "\n";
    return 0;
  } catch (const ScenarioError& e) {
    std::cerr << "omnitwin: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "omnitwin model: " << e.what() << "\n";
    return 3;
  }
}

}  // namespace

int main(int argc, char** argv) {
  spdlog::set_level(spdlog::level::warn);
  mju_user_warning = mujoco_warning;
  mju_user_error = mujoco_error;
  CLI::App app{"omnitwin — co-simulation digital twin of the seed-002 four-omniwheel platform"};
  app.require_subcommand(1);
  bool verbose = false;
  app.add_flag("-v,--verbose", verbose, "log progress details to stderr");

  RunArgs ra;
  CLI::App* run = app.add_subcommand("run", "run one scenario and write its records");
  run->add_option("scenario", ra.scenario, "scenario file (YAML)")->required();
  run->add_option("--out", ra.out, "run directory (default out/<scenario name>/)");
  run->add_option("--bus", ra.bus, "bus between master and devices")
      ->check(CLI::IsMember({"direct", "can", "canopen", "ethercat", "m3", "tml"}));
  run->add_option("--clock", ra.clock, "clock mode")->check(CLI::IsMember({"lockstep", "realtime"}));
  run->add_option("--set", ra.sets, "override a scenario key, e.g. --set controller.period=0.005")
      ->type_name("KEY=VALUE");
  run->add_flag("--no-progress", ra.no_progress, "never draw the progress bar");

  RunArgs ta;
  ta.external_master = true;
  CLI::App* twin = app.add_subcommand("twin", "run the twin alone (bus can, realtime) for an external master");
  twin->add_option("scenario", ta.scenario, "scenario file (YAML)")->required();
  twin->add_option("--out", ta.out, "run directory (default out/<scenario name>/)");
  twin->add_option("--clock", ta.clock, "clock mode (realtime)")->check(CLI::IsMember({"realtime"}));
  twin->add_option("--set", ta.sets, "override a scenario key, e.g. --set bus.bit_rate=500000")->type_name("KEY=VALUE");
  twin->add_flag("--no-progress", ta.no_progress, "never draw the progress bar");

  std::vector<std::string> check_paths;
  std::string junit, check_out = "out/check";
  CLI::App* check = app.add_subcommand("check", "run regression scenarios and check their expectations");
  check->add_option("paths", check_paths, "scenario files or directories (searched for *.yaml)")->required();
  check->add_option("--junit", junit, "write a JUnit XML report to FILE");
  check->add_option("--out", check_out, "root of the run directories")->capture_default_str();

  std::string exp_name, exp_out;
  bool exp_quick = false;
  CLI::App* experiment = app.add_subcommand("experiment", "run one of seed 002's experiments (docs/experiments.md)");
  experiment->add_option("name", exp_name, "can-timing | can-dropout | thesis-platform")->required();
  experiment->add_option("--out", exp_out, "output folder (default out/<name>/)");
  experiment->add_flag("--quick", exp_quick, "fewer configurations (a smoke run; the same checks)");

  std::string model_scenario, model_variant, model_out;
  CLI::App* model = app.add_subcommand("model", "write the platform MJCF generated from the parameters");
  model->add_option("--scenario", model_scenario, "take parameters from this scenario (default: built-in)");
  model->add_option("--variant", model_variant, "rollers or capsule")->check(CLI::IsMember({"rollers", "capsule"}));
  model->add_option("--out", model_out, "output file (default: stdout)");

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return 2;
  }
  if (verbose) spdlog::set_level(spdlog::level::info);
  install_signal_handlers();

  try {
    if (*run) return cmd_run(ra);
    if (*twin) {
      // The twin alone: the CAN bus and the realtime clock are implied.
      ta.bus = "can";
      ta.clock = "realtime";
      return cmd_run(ta);
    }
    if (*check) return cmd_check(check_paths, junit, check_out);
    if (*model) return cmd_model(model_scenario, model_variant, model_out);
    if (*experiment) return run_experiment(exp_name, ExperimentOptions{exp_out, exp_quick});
  } catch (const std::exception& e) {
    // Anything not handled closer to its cause is a runtime failure, never an abort.
    std::cerr << "omnitwin: " << e.what() << "\n";
    return 3;
  }
  return 2;
}
