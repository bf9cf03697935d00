// twin layer — `omnitwin check` (see check.hpp).
#include "twin/check.hpp"

#include "media/json_problem.hpp"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <mutex>
#include <set>
#include <thread>

#include "twin/clock.hpp"
#include "twin/job_pool.hpp"
#include "twin/junit.hpp"
#include "twin/run.hpp"
#include "twin/run_outputs.hpp"
#include "twin/scenario.hpp"

namespace omnitwin::twin {

namespace fs = std::filesystem;

namespace {

bool interrupted(const CheckOptions& opt) { return opt.interrupt != nullptr && opt.interrupt->load(); }

// The prefix of a case's first failure when the run itself failed (exit 3 of `omnitwin run`),
// as opposed to a scenario that could not be loaded (exit 2).
const std::string kRunFailed = "run failed: ";
const std::string kIncompleteMerge = "incomplete merge: ";  // check --merge without all its shards
bool runtime_failure(const JunitCase& c) {
  return c.error && !c.failures.empty() &&
         (c.failures.front().starts_with(kRunFailed) || c.failures.front().starts_with(kIncompleteMerge));
}
// A case's exit code as `omnitwin run` gives it: 0 passed, 1 failed, 2 bad input, 3 runtime.
int case_exit_code(const JunitCase& c) { return c.passed ? 0 : (runtime_failure(c) ? 3 : (c.error ? 2 : 1)); }

int finish_check(const std::vector<JunitCase>& cases, const nlohmann::json& index, bool bad_input,
                 const CheckOptions& opt);

// Why the --junit file cannot be written, found before any scenario runs ("" when it can be
// tried): a folder in its place, or no folder to hold it. The suite ran whole first, then
// failed on the rename (found in review). The --out folder counts as there: check makes it
// (`--out D --junit D/junit.xml` was refused while D did not exist yet; found by a walkthrough).
std::string junit_problem(const std::string& junit, const std::string& out_root) {
  if (junit.empty()) return "";
  std::error_code ec;
  if (fs::is_directory(junit, ec)) return "--junit " + junit + " is a folder, not a file";
  const fs::path parent = fs::absolute(junit, ec).parent_path().lexically_normal();
  const bool made_by_check = !out_root.empty() && fs::absolute(out_root, ec).lexically_normal() == parent;
  if (!made_by_check && !fs::is_directory(parent, ec))
    return "--junit " + junit + ": no such folder " + parent.string();
  return "";
}

// The output folder exists (made if needed), or why not, as one line for the user.
std::string make_out_root(const std::string& out_root) {
  std::error_code ec;
  fs::create_directories(out_root, ec);
  if (ec) return "cannot create output folder " + out_root + ": " + ec.message();
  if (!fs::is_directory(out_root)) return "cannot create output folder " + out_root + ": not a directory";
  return "";
}

// check.json next to the index page, written whole under a temporary name; "" or why not.
std::string write_check_json(const std::string& out_root, const std::string& shard, std::size_t files_total,
                             const nlohmann::json& results) {
  std::error_code ec;
  fs::create_directories(out_root, ec);
  const fs::path file = fs::path(out_root) / "check.json", temp = fs::path(out_root) / ".check.json.part";
  {
    std::ofstream f(temp, std::ios::binary | std::ios::trunc);
    f << nlohmann::json{{"title", "omnitwin check"}, {"shard", shard}, {"files_total", files_total}, {"results", results}}
             .dump(1, ' ', false, nlohmann::json::error_handler_t::replace)
      << "\n";
    f.close();
    if (!f) return "cannot write " + temp.string();
  }
  fs::rename(temp, file, ec);
  return ec ? "cannot write " + file.string() + ": " + ec.message() : "";
}

// One scenario's line of the check index (media/report/check_index.py).
nlohmann::json index_entry(const std::string& file, const std::string& run_dir, const JunitCase& c,
                           const nlohmann::json& metrics) {
  nlohmann::json m = nlohmann::json::object();
  for (const char* k : {"sim_time_s", "wall_time_s", "real_time_factor", "clock", "interrupted"})
    if (metrics.contains(k)) m[k] = metrics[k];
  for (const char* k : {"platform", "bus"})
    if (metrics.contains(k)) m[k] = metrics[k];
  return {{"scenario", c.name},       {"file", file},
          {"run_dir", run_dir},      {"passed", c.passed},
          {"exit_code", case_exit_code(c)},
          {"failures", c.failures},  {"metrics", m},
          {"time_s", c.time_s},      {"error", c.error},
          {"classname", c.classname}};
}

// What the scenarios of one `check` share; guarded by `mutex` when they run in parallel.
struct CheckShared {
  std::mutex mutex;
  std::mutex realtime;  // RunOptions::realtime_turn of every run
  std::map<std::string, std::string> used;  // scenario name -> its file (one run directory each)
  bool bad_input = false;
};

JunitCase check_one(const std::string& file, const CheckOptions& opt, CheckShared& shared, nlohmann::json& entry) {
  const std::string out_root = opt.out_root;
  std::string run_dir;
  nlohmann::json metrics;
  std::string renderer;  // the GL that drew its video ("" when none was made)
  JunitCase c;
  c.name = fs::path(file).stem().string();
  c.classname = "omnitwin.check";
  const std::int64_t t0 = monotonic_ns();
  try {
    const Scenario s = load_scenario(file);
    c.name = s.name;
    // Each scenario gets its own run directory: two files with one name would overwrite.
    {
      const std::lock_guard lock(shared.mutex);
      // The owner is the first file in order with the name (claimed before any run started),
      // so which of two files is the duplicate does not depend on the threads' timing.
      if (const auto it = shared.used.find(s.name); it != shared.used.end() && it->second != file)
        throw ScenarioError(file, 0, "name", fmt::format("'{}' is already the name of {}", s.name, it->second));
    }
    RunOptions o;
    o.out_dir = (fs::path(out_root) / s.name).string();
    o.interrupt = opt.interrupt;
    o.realtime_turn = &shared.realtime;  // realtime runs one at a time (RunOptions)
    const RunResult r = run_scenario(s, o);
    run_dir = r.out_dir;
    metrics = r.metrics;
    OutputPlan plan;
    plan.video = opt.video && !interrupted(opt);
    plan.video_spec = s.outputs.video;
    plan.report = opt.report && s.outputs.report;
    const OutputsResult out = make_run_outputs(r.out_dir, plan, opt.interrupt);
    if (!out.video.empty()) renderer = out.renderer;
    // What `omnitwin run` ends with exit 3 for (a record, the video or the report not written
    // whole) is a runtime failure here too, whatever the bounds said: an <error>, not a pass.
    std::vector<std::string> broken;
    if (!r.interrupted) {
      if (!r.error.empty()) broken.push_back(r.error);
      for (const std::string& f : r.missing_records) broken.push_back(f + " was not written");
      for (const std::string& f : r.partial_records) broken.push_back(f + " is incomplete");
      broken.insert(broken.end(), out.errors.begin(), out.errors.end());
    }
    for (const std::string& b : broken) c.failures.push_back(kRunFailed + b);
    c.error = !broken.empty();
    c.passed = r.passed && !r.interrupted && !c.error;
    for (const auto& f : r.metrics["expectations"]["failures"]) c.failures.push_back(f.get<std::string>());
    if (r.interrupted) c.failures.push_back("interrupted");
    c.system_out = r.metrics.dump(2);
  } catch (const ScenarioError& e) {
    c.error = true;
    c.failures.push_back(e.what());
  } catch (const RunSetupError& e) {
    c.error = true;
    c.failures.push_back(file + ": " + e.what());
  } catch (const std::exception& e) {
    c.error = true;
    c.failures.push_back(kRunFailed + e.what());
  }
  if (c.error && !runtime_failure(c)) {
    const std::lock_guard lock(shared.mutex);
    shared.bad_input = true;
  }
  c.time_s = (monotonic_ns() - t0) * 1e-9;
  entry = index_entry(file, run_dir, c, metrics);
  std::error_code ec;  // the non-throwing form: this runs on a -j worker, outside the try above
  entry["run_dir_rel"] = run_dir.empty() ? "" : fs::relative(run_dir, opt.out_root, ec).generic_string();
  if (!renderer.empty()) entry["video_renderer"] = renderer;
  return c;
}

// Runs every file's scenario, `jobs` at a time (each lockstep run is isolated on its own
// bus, so they cannot disturb each other; realtime runs go one at a time; 0 = the machine's
// cores); prints each verdict as it comes. Results keep
// the files' order.
std::vector<JunitCase> run_checks(const std::vector<std::string>& files, const CheckOptions& opt, CheckShared& shared,
                                  nlohmann::json& index) {
  // Names first, in file order: the first file with a name owns its run directory.
  for (const auto& f : files) {
    try {
      shared.used.emplace(load_scenario(f).name, f);
    } catch (const std::exception&) {
      // reported when its turn comes
    }
  }
  std::vector<JunitCase> cases(files.size());
  std::vector<nlohmann::json> entries(files.size());
  std::vector<bool> done(files.size(), false);
  std::mutex print;
  bool said_renderer = false;  // which GL draws the videos: said once (one backend per process)
  run_jobs(files.size(), jobs_or_cores(opt.jobs), opt.interrupt, [&](std::size_t i) {
    JunitCase c = check_one(files[i], opt, shared, entries[i]);
    const std::lock_guard lock(print);
    std::cout << fmt::format("{} {} ({:.1f} s)\n", c.passed ? "PASS" : (c.error ? "ERROR" : "FAIL"), c.name, c.time_s);
    for (const auto& msg : c.failures) std::cout << "     " << msg << "\n";
    if (!said_renderer && entries[i].contains("video_renderer")) {
      std::cout << "     videos drawn by " << entries[i]["video_renderer"].get<std::string>() << "\n";
      said_renderer = true;
    }
    std::cout << std::flush;
    cases[i] = std::move(c);
    done[i] = true;
  });
  std::vector<JunitCase> ran;
  for (std::size_t i = 0; i < files.size(); ++i) {
    if (!done[i]) continue;  // not started: interrupted
    ran.push_back(std::move(cases[i]));
    index.push_back(std::move(entries[i]));
  }
  return ran;
}


// What one shard's check.json says about itself.
struct ShardInfo {
  int k = 1, n = 1;            // "K/N" ("" = a check of every file: 1/1)
  std::size_t files_total = 0; // the scenario files over all shards
  std::size_t results = 0;     // the results it holds
};

// One shard's check.json, its run directories made relative to here; "" or why not.
std::string read_shard(const std::string& dir, nlohmann::json& results, ShardInfo& info) {
  const fs::path file = fs::path(dir) / "check.json";
  std::ifstream f(file, std::ios::binary);
  if (!f) return file.string() + ": no check.json (is it the --out of an `omnitwin check`?)";
  try {
    const nlohmann::json j = nlohmann::json::parse(f);
    const std::string shard = j.value("shard", "");
    if (!shard.empty() && !parse_shard(shard, info.k, info.n)) return file.string() + ": bad shard '" + shard + "'";
    info.files_total = j.at("files_total").get<std::size_t>();
    for (nlohmann::json e : j.at("results")) {
      const std::string rel = e.value("run_dir_rel", "");
      e["run_dir"] = rel.empty() ? "" : (fs::path(dir) / rel).lexically_normal().string();
      results.push_back(std::move(e));
      ++info.results;
    }
  } catch (const std::exception& e) {
    return file.string() + ": " + media::json_problem(e);
  }
  return "";
}

// Why the shards do not add up to one whole check (a shard missing, one of another split or
// suite, one cut short), one line each; empty when they do.
std::vector<std::string> incomplete_shards(const std::vector<ShardInfo>& shards) {
  std::vector<std::string> why;
  const ShardInfo& first = shards.front();
  std::set<int> seen;
  for (const ShardInfo& s : shards) {
    if (s.n != first.n || s.files_total != first.files_total) {
      why.push_back(fmt::format("shard {}/{} of {} files does not belong with shard {}/{} of {} files", s.k, s.n,
                                s.files_total, first.k, first.n, first.files_total));
      continue;
    }
    seen.insert(s.k);
    // Shard K of N holds the files i with i mod N = K - 1 (shard_of()).
    const std::size_t n = static_cast<std::size_t>(s.n), k0 = static_cast<std::size_t>(s.k - 1);
    const std::size_t expected = s.files_total > k0 ? (s.files_total - k0 + n - 1) / n : 0;
    if (s.results != expected)
      why.push_back(fmt::format("shard {}/{} holds {} of its {} results (cut short?)", s.k, s.n, s.results, expected));
  }
  for (int k = 1; k <= first.n; ++k)
    if (!seen.contains(k)) why.push_back(fmt::format("shard {}/{} is missing", k, first.n));
  return why;
}

JunitCase case_of(const nlohmann::json& e) {
  JunitCase c;
  c.name = e.value("scenario", "");
  c.classname = e.value("classname", "omnitwin.check");
  c.time_s = e.value("time_s", 0.0);
  c.passed = e.value("passed", false);
  c.error = e.value("error", false);
  for (const auto& m : e.value("failures", nlohmann::json::array())) c.failures.push_back(m.get<std::string>());
  return c;
}

}  // namespace

// The scenario files under the given paths: files as given, directories searched
// recursively for *.yaml, in sorted order so reports are stable.
std::vector<std::string> scenario_files(const std::vector<std::string>& paths) {
  std::vector<std::string> files;
  for (const auto& p : paths) {
    std::error_code ec;  // a path the file system refuses is taken as a file: loading it says why
    if (!fs::is_directory(p, ec)) {
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



std::vector<std::string> shard_of(const std::vector<std::string>& files, int k, int n) {
  std::vector<std::string> out;
  for (std::size_t i = 0; i < files.size(); ++i)
    if (static_cast<int>(i % static_cast<std::size_t>(n)) == k - 1) out.push_back(files[i]);
  return out;
}

bool parse_shard(const std::string& text, int& k, int& n) {
  const auto slash = text.find('/');
  if (slash == std::string::npos || slash == 0 || slash + 1 == text.size()) return false;
  try {
    std::size_t used_k = 0, used_n = 0;
    k = std::stoi(text.substr(0, slash), &used_k);
    n = std::stoi(text.substr(slash + 1), &used_n);
    if (used_k != slash || used_n != text.size() - slash - 1) return false;
  } catch (const std::exception&) {
    return false;
  }
  return n >= 1 && n <= 1000 && k >= 1 && k <= n;
}

int cmd_check(const std::vector<std::string>& paths, const CheckOptions& opt) {
  if (const std::string e = junit_problem(opt.junit, opt.out_root); !e.empty()) {
    std::cerr << "omnitwin check: " << e << "\n";
    return 2;
  }
  const auto all = scenario_files(paths);
  if (all.empty()) {
    std::cerr << "omnitwin check: no scenario files under the given paths\n";
    return 2;
  }
  if (const std::string e = make_out_root(opt.out_root); !e.empty()) {
    std::cerr << "omnitwin check: " << e << "\n";
    return 2;
  }
  const auto files = opt.shard_n > 0 ? shard_of(all, opt.shard_k, opt.shard_n) : all;
  if (opt.shard_n > 0)
    std::cout << fmt::format("shard {}/{}: {} of {} scenario files\n", opt.shard_k, opt.shard_n, files.size(), all.size());
  CheckShared shared;
  nlohmann::json index = nlohmann::json::array();
  const std::vector<JunitCase> cases = run_checks(files, opt, shared, index);
  const std::string shard = opt.shard_n > 0 ? fmt::format("{}/{}", opt.shard_k, opt.shard_n) : "";
  if (const std::string e = write_check_json(opt.out_root, shard, all.size(), index); !e.empty()) {
    std::cerr << "omnitwin check: " << e << "\n";
    return 3;
  }
  return finish_check(cases, index, shared.bad_input, opt);
}


int cmd_check_merge(const std::vector<std::string>& dirs, const CheckOptions& opt) {
  if (const std::string e = junit_problem(opt.junit, opt.out_root); !e.empty()) {
    std::cerr << "omnitwin check --merge: " << e << "\n";
    return 2;
  }
  if (const std::string e = make_out_root(opt.out_root); !e.empty()) {
    std::cerr << "omnitwin check --merge: " << e << "\n";
    return 2;
  }
  nlohmann::json index = nlohmann::json::array();
  std::vector<ShardInfo> shards;
  for (const std::string& d : dirs) {
    if (const std::string e = read_shard(d, index, shards.emplace_back()); !e.empty()) {
      std::cerr << "omnitwin check --merge: " << e << "\n";
      return 2;
    }
  }
  std::map<std::string, std::string> seen;  // scenario → the run directory it came from
  std::vector<JunitCase> cases;
  bool bad_input = false;
  for (const auto& e : index) {
    const std::string name = e.value("scenario", ""), run = e.value("run_dir", "");
    if (const auto [it, fresh] = seen.emplace(name, run); !fresh) {
      std::cerr << fmt::format("omnitwin check --merge: scenario '{}' is in two shards ({} and {})\n", name,
                               it->second, run);
      return 2;
    }
    cases.push_back(case_of(e));
    bad_input = bad_input || (cases.back().error && !runtime_failure(cases.back()));
  }
  // A merge that lacks a shard, or holds one cut short, is not the suite's verdict: it ends as
  // a runtime failure, with a case that says what is missing.
  if (const std::vector<std::string> why = incomplete_shards(shards); !why.empty()) {
    JunitCase c;
    c.name = "merge";
    c.classname = "omnitwin.check";
    c.error = true;
    for (const std::string& w : why) {
      c.failures.push_back(kIncompleteMerge + w);
      std::cerr << "omnitwin check --merge: " << w << "\n";
    }
    index.push_back(index_entry("", "", c, nlohmann::json::object()));
    cases.push_back(std::move(c));
  }
  std::cout << fmt::format("merged {} results from {} shard folders\n", cases.size(), dirs.size());
  if (const std::string e = write_check_json(opt.out_root, "", cases.size(), index); !e.empty()) {
    std::cerr << "omnitwin check --merge: " << e << "\n";
    return 3;
  }
  return finish_check(cases, index, bad_input, opt);
}

namespace {
// The index page, the summary line, the JUnit report and the exit code of a check (or merge).
int finish_check(const std::vector<JunitCase>& cases, const nlohmann::json& index, bool bad_input,
                 const CheckOptions& opt) {
  // Failed counts every case that did not pass; of those, the ones that could not run (bad
  // input, a runtime failure: JUnit's errors) are named apart, so "failed" is never read as
  // "expectations not met" alone.
  int passed = 0, failed = 0, could_not_run = 0;
  for (const JunitCase& c : cases) {
    (c.passed ? passed : failed)++;
    if (!c.passed && c.error) ++could_not_run;
  }
  // The index first: the summary stays the last line, where CI logs show it.
  std::string index_error;
  if (opt.report) {
    index_error = write_check_index(opt.out_root, "omnitwin check", index);
    if (index_error.empty()) std::cout << "index: " << (fs::path(opt.out_root) / "index.html").string() << "\n";
  }
  std::cout << passed << " passed, " << failed << " failed"
            << (could_not_run ? fmt::format(" ({} of them could not run)", could_not_run) : "") << "\n";
  if (!index_error.empty()) {
    std::cerr << "omnitwin check: cannot write the index page: " << index_error << "\n";
    return 3;
  }
  if (!opt.junit.empty()) {
    try {
      write_junit(opt.junit, "omnitwin check", cases);
    } catch (const std::exception& e) {
      std::cerr << "omnitwin check: cannot write the JUnit report: " << e.what() << "\n";
      return 3;
    }
  }
  // No verdict: a runtime failure (a run that could not leave its records, video or report,
  // or an interrupted suite) before bad input, so that a script keying on 3 for "the
  // machinery failed" sees it even when a bad scenario file is in the same suite.
  if (interrupted(opt)) return 3;
  if (std::any_of(cases.begin(), cases.end(), runtime_failure)) return 3;
  if (bad_input) return 2;
  return failed ? 1 : 0;
}


}  // namespace

}  // namespace omnitwin::twin
