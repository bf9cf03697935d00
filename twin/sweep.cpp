// twin layer — `omnitwin sweep` (see sweep.hpp).
#include "twin/sweep.hpp"

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <mutex>
#include <random>
#include <set>
#include <thread>

#include "media/run_report.hpp"
#include "twin/expectations.hpp"
#include "twin/job_pool.hpp"
#include "twin/run.hpp"
#include "twin/run_directory.hpp"
#include "twin/run_outputs.hpp"
#include "twin/scenario.hpp"

extern char** environ;

namespace omnitwin::twin {

namespace fs = std::filesystem;

namespace {

using Point = std::vector<std::pair<std::string, std::string>>;

[[noreturn]] void bad(const SweepSpec& s, const YAML::Node& n, const std::string& key, const std::string& msg) {
  throw ScenarioError(s.file, n.IsDefined() ? n.Mark().line + 1 : 0, key, msg);
}

// A YAML value as the text a --set takes (flow style for lists and maps).
std::string as_set_value(const YAML::Node& n) {
  if (n.IsScalar()) return n.Scalar();
  YAML::Emitter e;
  e << YAML::Flow << n;
  return e.c_str();
}

void only_keys(const SweepSpec& s, const YAML::Node& map, const std::vector<std::string>& keys, const std::string& where) {
  for (const auto& kv : map) {
    const std::string k = kv.first.as<std::string>();
    if (std::find(keys.begin(), keys.end(), k) == keys.end())
      bad(s, kv.first, where + k, fmt::format("unknown key (expected one of: {})", fmt::join(keys, ", ")));
  }
}

// The most points a sweep may have (grid × draws).
constexpr std::size_t kMaxPoints = 100000;

// The grid's points: the cartesian product, the last key varying fastest.
std::vector<Point> grid_points(SweepSpec& s, const YAML::Node& grid) {
  std::vector<Point> pts{Point{}};
  if (!grid.IsDefined()) return pts;
  if (!grid.IsMap() || grid.size() == 0) bad(s, grid, "grid", "expected a mapping of scenario keys to lists of values");
  for (const auto& kv : grid) {
    const std::string key = kv.first.as<std::string>();
    if (!kv.second.IsSequence() || kv.second.size() == 0) bad(s, kv.second, "grid." + key, "expected a non-empty list");
    s.params.push_back(key);
    // Checked before the product is built: ten keys of 100 values would be 1e20 points.
    if (pts.size() * kv.second.size() > kMaxPoints)
      bad(s, kv.second, "grid." + key,
          fmt::format("the grid has {} × {} points here: more than {}", pts.size(), kv.second.size(), kMaxPoints));
    std::vector<Point> next;
    for (const Point& p : pts)
      for (const auto& v : kv.second) {
        Point q = p;
        q.emplace_back(key, as_set_value(v));
        next.push_back(std::move(q));
      }
    pts = std::move(next);
  }
  return pts;
}

// True when a YAML scalar is written as a whole number (no point, no exponent).
bool integer_scalar(const YAML::Node& n) {
  const std::string& t = n.Scalar();
  return !t.empty() && t.find_first_not_of("+-0123456789") == std::string::npos;
}

// One draw from {min, max} as the text a --set takes: a whole number when both bounds are
// written as whole numbers (a bit rate, a count), else the double's shortest exact text, so
// the value run is the value drawn and never falls outside [min, max].
std::string draw_in_range(const SweepSpec& s, const YAML::Node& d, const std::string& where, std::mt19937_64& rng) {
  if (integer_scalar(d["min"]) && integer_scalar(d["max"])) {
    const auto lo = d["min"].as<long long>(), hi = d["max"].as<long long>();
    if (lo > hi) bad(s, d, where, "min must not exceed max");
    return std::to_string(std::uniform_int_distribution<long long>(lo, hi)(rng));
  }
  const double lo = d["min"].as<double>(), hi = d["max"].as<double>();
  if (!(lo <= hi) || !std::isfinite(lo) || !std::isfinite(hi)) bad(s, d, where, "min must not exceed max");
  return fmt::format("{}", std::clamp(std::uniform_real_distribution<double>(lo, hi)(rng), lo, hi));
}

// `draws` seeded draws of the random parameters (none: one empty draw).
std::vector<Point> random_points(SweepSpec& s, const YAML::Node& r) {
  if (!r.IsDefined()) return {Point{}};
  if (!r.IsMap()) bad(s, r, "random", "expected a mapping with draws, seed and params");
  only_keys(s, r, {"draws", "seed", "params"}, "random.");
  const int draws = r["draws"].IsDefined() ? r["draws"].as<int>() : 0;
  if (draws < 1 || draws > 100000) bad(s, r["draws"], "random.draws", "expected 1 … 100000 draws");
  const std::uint64_t seed = r["seed"].IsDefined() ? r["seed"].as<std::uint64_t>() : 1;
  const YAML::Node params = r["params"];
  if (!params.IsDefined() || !params.IsMap() || params.size() == 0)
    bad(s, params.IsDefined() ? params : r, "random.params", "expected a mapping of keys to ranges");
  std::mt19937_64 rng(seed);
  std::vector<Point> pts(static_cast<std::size_t>(draws));
  for (const auto& kv : params) {
    const std::string key = kv.first.as<std::string>(), where = "random.params." + key;
    const YAML::Node d = kv.second;
    if (!d.IsMap()) bad(s, d, where, "expected {min, max} or {values: [...]}");
    only_keys(s, d, {"min", "max", "values"}, where + ".");
    s.params.push_back(key);
    for (Point& p : pts) {
      if (d["values"].IsDefined()) {
        if (!d["values"].IsSequence() || d["values"].size() == 0) bad(s, d["values"], where + ".values", "expected a non-empty list");
        std::uniform_int_distribution<std::size_t> pick(0, d["values"].size() - 1);
        p.emplace_back(key, as_set_value(d["values"][pick(rng)]));
      } else {
        if (!d["min"].IsDefined() || !d["max"].IsDefined()) bad(s, d, where, "expected {min, max} or {values: [...]}");
        p.emplace_back(key, draw_in_range(s, d, where, rng));
      }
    }
  }
  return pts;
}

void read_metrics_and_plot(SweepSpec& s, const YAML::Node& root) {
  const YAML::Node m = root["metrics"];
  if (!m.IsDefined() || !m.IsSequence() || m.size() == 0)
    bad(s, m.IsDefined() ? m : root, "metrics", "expected a non-empty list of metric paths");
  for (const auto& v : m) s.metrics.push_back(v.as<std::string>());
  s.plot_x = s.params.empty() ? "point" : s.params.front();
  s.plot_y = s.metrics.front();
  if (const YAML::Node p = root["plot"]; p.IsDefined()) {
    only_keys(s, p, {"x", "y"}, "plot.");
    if (p["x"].IsDefined()) s.plot_x = p["x"].as<std::string>();
    if (p["y"].IsDefined()) s.plot_y = p["y"].as<std::string>();
    if (std::find(s.params.begin(), s.params.end(), s.plot_x) == s.params.end())
      bad(s, p["x"], "plot.x", "'" + s.plot_x + "' is not one of the swept parameters");
    if (std::find(s.metrics.begin(), s.metrics.end(), s.plot_y) == s.metrics.end())
      bad(s, p["y"], "plot.y", "'" + s.plot_y + "' is not one of the metrics");
  }
}

// A metric of metrics.json by dotted path; empty when absent or not a number/bool/string.
std::string metric_text(const nlohmann::json& m, const std::string& path) {
  const nlohmann::json* j = find_metric(m, path);  // the same dotted paths as expectations
  if (j == nullptr) return "";
  if (j->is_number_float()) return fmt::format("{}", j->get<double>());
  if (j->is_number() || j->is_boolean()) return j->dump();
  if (j->is_string()) return j->get<std::string>();
  return "";
}

// A CSV field in double quotes, inner quotes doubled (RFC 4180).
std::string csv_quoted(const std::string& v);

// A CSV field, quoted only when it must be (a comma, a quote or a line break in it).
std::string csv_field(const std::string& v) {
  return v.find_first_of(",\"\r\n") == std::string::npos ? v : csv_quoted(v);
}

std::string csv_quoted(const std::string& v) {
  std::string q = "\"";
  for (const char c : v) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

fs::path point_dir(const fs::path& out, int k) { return out / "points" / fmt::format("{:04d}", k); }

// Runs point k (1-based) into its directory and writes point.json; returns its exit code and
// sets *notes to what its overrides changed beyond their own keys (Scenario::notes: a `bus` axis
// over a file's settings for another bus). `realtime`: RunOptions::realtime_turn (realtime points
// go one at a time).
int run_point(const SweepSpec& s, int k, const fs::path& out, const std::atomic<bool>* interrupt, std::mutex& realtime,
              std::vector<std::string>* notes) {
  const Point& p = s.points[static_cast<std::size_t>(k - 1)];
  nlohmann::json pj = {{"point", k}, {"params", nlohmann::json::object()}};
  for (const auto& [key, v] : p) pj["params"][key] = v;
  int code = 3;
  try {
    std::vector<Override> o;
    for (const auto& [key, v] : p) o.push_back({key, v});
    const Scenario sc = load_scenario(s.scenario, o);
    pj["notes"] = sc.notes;
    *notes = sc.notes;
    RunOptions ro;
    ro.out_dir = point_dir(out, k).string();
    ro.interrupt = interrupt;
    ro.realtime_turn = &realtime;
    const RunResult r = run_scenario(sc, ro);
    code = r.interrupted ? 3 : r.exit_code;
    pj["passed"] = r.passed;
    pj["error"] = r.error;
  } catch (const ScenarioError& e) {
    code = 2;
    pj["error"] = e.what();
  } catch (const std::exception& e) {
    pj["error"] = std::string("run failed: ") + e.what();
  }
  pj["exit_code"] = code;
  std::error_code ec;
  fs::create_directories(point_dir(out, k), ec);
  // Replacing bytes that are not UTF-8 (an error text may quote them): dump() would throw on a
  // -j worker, outside any try.
  std::ofstream(point_dir(out, k) / "point.json") << pj.dump(1, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
  return code;
}

// Every point locally, `jobs` at a time; prints one line per point, and each distinct note once,
// on stderr with the first point that gave it (every point's own are in its point.json and run.json).
void run_local(const SweepSpec& s, const fs::path& out, const SweepOptions& opt) {
  const std::size_t n = s.points.size();
  std::mutex print;
  std::mutex realtime;  // RunOptions::realtime_turn: realtime points one at a time
  std::set<std::string> noted;
  run_jobs(n, jobs_or_cores(opt.jobs), opt.interrupt, [&](std::size_t i) {
    const int k = static_cast<int>(i) + 1;
    std::vector<std::string> notes;
    const int code = run_point(s, k, out, opt.interrupt, realtime, &notes);
    const std::lock_guard lock(print);
    for (const std::string& note : notes)
      if (noted.insert(note).second)
        std::cerr << fmt::format("omnitwin sweep: note (point {}, printed once for the sweep): {}\n", k, note);
    std::cout << fmt::format("point {}/{}: exit {}\n", k, n, code) << std::flush;
  });
}

// Runs argv and waits for it; a Ctrl-C or SIGTERM to us (*interrupt) is passed on as SIGTERM
// (sbatch --wait then cancels its job array) and waited for. Its exit code, -1 if it cannot start.
int spawn_wait(const std::vector<std::string>& argv, const std::atomic<bool>* interrupt) {
  std::vector<char*> a;
  for (const auto& s : argv) a.push_back(const_cast<char*>(s.c_str()));
  a.push_back(nullptr);
  pid_t pid = 0;
  if (::posix_spawnp(&pid, a[0], nullptr, nullptr, a.data(), environ) != 0) return -1;
  int st = 0;
  bool passed_on = false;
  for (;;) {
    const pid_t r = ::waitpid(pid, &st, WNOHANG);
    if (r == pid) break;
    if (r < 0 && errno != EINTR) return -1;
    if (interrupt && interrupt->load() && !passed_on) {
      ::kill(pid, SIGTERM);
      passed_on = true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
}

// `text` as one word of a POSIX shell: in single quotes, each ' written as '\''.
std::string sh_quoted(const std::string& text) {
  std::string q = "'";
  for (const char c : text) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

// A Slurm job name from the sweep's name: only [A-Za-z0-9_.-], the rest as '_'.
std::string slurm_job_name(const std::string& name) {
  std::string n = "omnitwin-sweep-";
  for (const char c : name) n += std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.' || c == '-' ? c : '_';
  return n;
}

// sweep.sbatch (a job array, one task per point) submitted with `sbatch --wait`; "" or why not.
std::string run_slurm(const SweepSpec& s, const fs::path& out, const SweepOptions& opt) {
  std::error_code ec;
  // The tasks run the `omnitwin` launcher beside us (it holds signals until the handlers are
  // in place), or this program itself where there is none.
  fs::path self = fs::read_symlink("/proc/self/exe", ec);
  if (const fs::path launcher = self.parent_path() / "omnitwin"; ::access(launcher.c_str(), X_OK) == 0) self = launcher;
  const fs::path script = out / "sweep.sbatch";
  {
    // Paths go in single quotes with their own quotes escaped; the job name keeps only
    // [A-Za-z0-9_.-], and the log path goes on sbatch's command line, never into a #SBATCH
    // line that a space, quote or line break in it would break (found in review).
    std::ofstream f(script);
    f << "#!/bin/sh\n"
      << "#SBATCH --job-name=" << slurm_job_name(s.name) << "\n"
      << "#SBATCH --array=1-" << s.points.size() << "\n"
      << "#SBATCH --cpus-per-task=1\n"
      << "exec " << sh_quoted(self.string()) << " sweep " << sh_quoted(fs::absolute(s.file).string())
      << " --point \"$SLURM_ARRAY_TASK_ID\" --out " << sh_quoted(out.string()) << "\n";
    if (!f) return "cannot write " + script.string();
  }
  if (s.points.size() > 1000)
    std::cout << fmt::format("note: {} array tasks; Slurm's default MaxArraySize (1001) allows 1000\n", s.points.size());
  std::cout << "submitting " << script.string() << " (" << s.points.size() << " array tasks) and waiting\n" << std::flush;
  const int rc = spawn_wait({opt.sbatch, "--wait", "--output=" + (out / "slurm-%A_%a.out").string(), script.string()},
                            opt.interrupt);
  if (rc < 0) return "cannot start '" + opt.sbatch + "' (is Slurm installed? scripts/slurm-local)";
  if (rc == 0) return "";
  // No task wrote a result: the array never ran (a refused submission, Slurm unreachable), or
  // every task failed before its point began; either way there is nothing to collect.
  std::size_t wrote = 0;
  for (std::size_t k = 1; k <= s.points.size(); ++k) wrote += fs::exists(point_dir(out, static_cast<int>(k)) / "point.json", ec);
  if (wrote == 0 && !(opt.interrupt && opt.interrupt->load()))
    return fmt::format("sbatch --wait ended with {} and none of the {} tasks wrote a result: the job array did not "
                       "run (see sbatch's message above)",
                       rc, s.points.size());
  std::cout << fmt::format("sbatch --wait ended with {} (some tasks failed); collecting what they wrote\n", rc);
  return "";
}

// Removes what an earlier sweep into the same folder left under points/ (each point folder
// that holds a point.json or a run), so that no point of this sweep can be read with an
// earlier sweep's result: a point that fails to load starts no run that would clear it, and
// a Slurm task that never ran writes nothing. A point folder this sweep will use that holds
// something else (a user's files) is refused before anything runs: a run would refuse it as
// its --out only after the points before it had run. "" or why not.
std::string clear_points(const fs::path& out, std::size_t n_points) {
  std::error_code ec;
  const fs::path points = out / "points";
  if (!fs::is_directory(points, ec)) return "";
  for (const auto& e : fs::directory_iterator(points, ec)) {
    const fs::path d = e.path();
    if (!e.is_directory(ec) || d.filename().string().find_first_not_of("0123456789") != std::string::npos) continue;
    if (!fs::exists(d / "point.json", ec) && !fs::exists(d / kRunMarker, ec) && !fs::exists(d / "run.json", ec)) continue;
    fs::remove_all(d, ec);
    if (ec) return "cannot clear " + d.string() + " (an earlier sweep's point): " + ec.message();
  }
  if (ec) return "cannot read " + points.string() + ": " + ec.message();
  for (std::size_t k = 1; k <= n_points; ++k) {
    const fs::path d = point_dir(out, static_cast<int>(k));
    if (!fs::exists(d, ec)) continue;
    if (!fs::is_directory(d, ec) || !fs::is_empty(d, ec))
      return d.string() + " holds something that is not an earlier sweep's point; move it or choose another --out";
  }
  return "";
}

// sweep.csv over every point's point.json and metrics.json; returns how many points lack a
// result or failed to run. `notes` gets each distinct note of the points' point.json with how
// many points gave it and the first of them; `found` each metric some run's metrics.json has.
int write_table(const SweepSpec& s, const fs::path& out, std::map<std::string, std::pair<int, std::size_t>>& notes,
                std::set<std::string>& found) {
  std::ofstream f(out / "sweep.csv");
  f << "point";
  for (const auto& p : s.params) f << "," << csv_field(p);
  for (const auto& m : s.metrics) f << "," << csv_field(m);
  f << ",passed,exit_code\n";
  int bad_points = 0;
  for (std::size_t k = 1; k <= s.points.size(); ++k) {
    const fs::path d = point_dir(out, static_cast<int>(k));
    nlohmann::json pj, mj;
    try {
      pj = nlohmann::json::parse(std::ifstream(d / "point.json"));
    } catch (const std::exception&) {
      pj = {{"exit_code", 3}, {"passed", false}};  // no result: the task never ran
    }
    const int code = pj.value("exit_code", 3);
    for (const auto& n : pj.value("notes", nlohmann::json::array()))
      if (n.is_string()) notes.try_emplace(n.get<std::string>(), 0, k).first->second.first++;
    // Metrics only of a point that ran (clear_points() removed what an earlier sweep left).
    try {
      mj = code <= 1 ? nlohmann::json::parse(std::ifstream(d / "metrics.json")) : nlohmann::json::object();
    } catch (const std::exception&) {
      mj = nlohmann::json::object();
    }
    if (code >= 2) ++bad_points;
    f << k;
    for (const auto& [key, v] : s.points[k - 1]) f << "," << csv_quoted(v);
    for (const auto& m : s.metrics) {
      if (find_metric(mj, m) != nullptr) found.insert(m);
      f << "," << csv_field(metric_text(mj, m));
    }
    f << "," << (pj.value("passed", false) ? "true" : "false") << "," << code << "\n";
  }
  return bad_points;
}

// The points must load: unknown keys and bad values show now, not in a run. The first point
// whole, then each other value of each parameter in the first point's company, each distinct
// (key, value) once, up to kMaxChecks loads (a point beyond that fails when it runs).
constexpr std::size_t kMaxChecks = 1000;
void check_points(const SweepSpec& s, const std::string& path) {
  std::vector<Override> first;
  for (const auto& [key, v] : s.points.front()) first.push_back({key, v});
  std::set<std::pair<std::string, std::string>> checked;
  const auto load = [&](const std::vector<Override>& o, std::size_t k) {
    try {
      (void)load_scenario(s.scenario, o);
    } catch (const ScenarioError& e) {
      throw ScenarioError(path, 0, e.key(), fmt::format("point {} does not load: {}", k, e.what()));
    }
  };
  load(first, 1);
  for (const auto& [key, v] : s.points.front()) checked.insert({key, v});
  for (std::size_t k = 2; k <= s.points.size() && checked.size() < kMaxChecks; ++k)
    for (std::size_t i = 0; i < s.points[k - 1].size(); ++i) {
      const auto& [key, v] = s.points[k - 1][i];
      if (!checked.insert({key, v}).second) continue;
      std::vector<Override> o = first;
      o[i].value = v;
      load(o, k);
    }
}

SweepSpec load_sweep_tree(const std::string& path) {
  SweepSpec s;
  s.file = path;
  const YAML::Node root = load_yaml_file(path);
  if (!root.IsMap()) throw ScenarioError(path, 0, "", "expected a mapping at the top level");
  only_keys(s, root, {"name", "scenario", "grid", "random", "metrics", "plot"}, "");
  s.name = root["name"].IsDefined() ? root["name"].as<std::string>() : fs::path(path).stem().string();
  if (!root["scenario"].IsDefined()) bad(s, root, "scenario", "a sweep needs the scenario it varies");
  s.scenario = (fs::path(path).parent_path() / root["scenario"].as<std::string>()).lexically_normal().string();
  std::error_code ec;  // a name the file system refuses is no file either, not an exception
  if (!fs::is_regular_file(s.scenario, ec)) bad(s, root["scenario"], "scenario", "no such file: " + s.scenario);
  if (!root["grid"].IsDefined() && !root["random"].IsDefined()) bad(s, root, "grid", "a sweep needs grid or random");
  const auto grid = grid_points(s, root["grid"]);
  const auto draws = random_points(s, root["random"]);
  if (grid.size() * draws.size() > kMaxPoints)
    bad(s, root, "grid", fmt::format("{} grid points × {} draws: more than {} points", grid.size(), draws.size(), kMaxPoints));
  for (const Point& g : grid)
    for (const Point& r : draws) {
      Point p = g;
      p.insert(p.end(), r.begin(), r.end());
      s.points.push_back(std::move(p));
    }
  read_metrics_and_plot(s, root);
  check_points(s, path);
  return s;
}

}  // namespace

SweepSpec load_sweep(const std::string& path) {
  try {
    return load_sweep_tree(path);
  } catch (const YAML::Exception& e) {  // a value of the wrong type (as<int> of a word, …)
    throw ScenarioError(path, e.mark.line + 1, "", e.msg);
  }
}

int cmd_sweep(const std::string& spec_path, const SweepOptions& opt) {
  SweepSpec s;
  try {
    s = load_sweep(spec_path);
  } catch (const ScenarioError& e) {
    std::cerr << "omnitwin sweep: " << e.what() << "\n";
    return 2;
  }
  const fs::path out = fs::absolute(opt.out.empty() ? fs::path("out/sweep") / s.name : fs::path(opt.out));
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec || !fs::is_directory(out)) {
    std::cerr << "omnitwin sweep: cannot create output folder " << out.string() << ": "
              << (ec ? ec.message() : std::string("not a directory")) << "\n";
    return 2;
  }
  if (opt.point > 0) {
    if (opt.point > static_cast<int>(s.points.size())) {
      std::cerr << fmt::format("omnitwin sweep: --point {}: the sweep has {} points\n", opt.point, s.points.size());
      return 2;
    }
    std::mutex alone;
    std::vector<std::string> notes;
    const int code = run_point(s, opt.point, out, opt.interrupt, alone, &notes);
    for (const std::string& note : notes) std::cerr << "omnitwin sweep: note: " << note << "\n";
    return code;
  }
  std::cout << fmt::format("sweep {}: {} points of {} ({})\n", s.name, s.points.size(), s.scenario,
                           opt.slurm ? "Slurm job array" : "local");
  if (const std::string e = clear_points(out, s.points.size()); !e.empty()) {
    std::cerr << "omnitwin sweep: " << e << "\n";
    return 2;
  }
  if (opt.slurm) {
    if (const std::string e = run_slurm(s, out, opt); !e.empty()) {
      std::cerr << "omnitwin sweep: " << e << "\n";
      return 3;
    }
  } else {
    run_local(s, out, opt);
  }
  std::map<std::string, std::pair<int, std::size_t>> notes;
  std::set<std::string> found;
  const int bad_points = write_table(s, out, notes, found);
  const bool any_ran = bad_points < static_cast<int>(s.points.size());
  // A metric no run has is a typo or a path metrics.json does not hold (an empty column and
  // an empty plot passed for a result): bad input, found once the runs are there.
  std::vector<std::string> missing;
  if (any_ran)
    for (const auto& m : s.metrics)
      if (!found.count(m)) missing.push_back(m);
  for (const auto& m : missing)
    std::cerr << fmt::format("omnitwin sweep: {}: metrics: '{}' is in none of the runs' metrics.json (its dotted "
                             "path, as `expect` takes it: docs/run-directory.md)\n",
                             s.file, m);
  // The tasks said theirs in their Slurm logs only; a local sweep said each as it came.
  if (opt.slurm)
    for (const auto& [note, seen] : notes)
      std::cerr << fmt::format("omnitwin sweep: note ({} of {} points, the first point {}): {}\n", seen.first,
                               s.points.size(), seen.second, note);
  std::cout << "table: " << (out / "sweep.csv").string() << "\n";
  // A plot of no point is no plot (an empty frame passed for one).
  media::ReportResult plot;
  if (any_ran) {
    media::ReportTools tools = report_tools();
    plot = media::write_sweep_plot((out / "sweep.csv").string(), (out / "sweep.png").string(), s.plot_x, s.plot_y,
                                   s.params, tools);
  } else {
    std::error_code ec;
    fs::remove(out / "sweep.png", ec);  // an earlier sweep's
    plot.error = "no point ran";
  }
  if (plot.ok) std::cout << "plot: " << plot.path << "\n";
  else std::cerr << "omnitwin sweep: no plot: " << plot.error << "\n";
  std::cout << fmt::format("{} points, {} ran, {} failed to run\n", s.points.size(), s.points.size() - bad_points, bad_points);
  if (opt.interrupt && opt.interrupt->load()) return 3;
  if (bad_points > 0 || !plot.ok) return 3;
  return missing.empty() ? 0 : 2;
}

}  // namespace omnitwin::twin
