// twin layer — `omnitwin check`: regression campaigns. Runs scenario files (in parallel with
// -j), judges each by its expectations, writes one run directory per scenario, the index
// page, a JUnit report and check.json (the machine-readable results); splits a suite into
// deterministic shards for a CI matrix (--shard K/N) and joins shard results (--merge).
//
// Shards: the scenario files in the order `scenario_files` gives them (the paths as given,
// each directory's files sorted), file i goes to shard (i mod N) + 1. The same arguments on
// every machine of a matrix therefore cover every file exactly once, and each shard gets a
// share of every directory.
//
// check.json (in --out): {"title", "shard": "K/N" or "", "files_total": all files before
// sharding, "results": [the index entries of media/report/check_index.py plus "time_s",
// "error" (could not run), "classname" and "run_dir_rel" (the run directory relative to
// check.json's folder)]}. --merge reads it from every DIR, so shard results can be moved
// (CI artefacts) before they are joined; a scenario name in two shards is an error.
// Not real-time code: allocates, writes files, runs threads.
#pragma once

#include <atomic>
#include <string>
#include <vector>

namespace omnitwin::twin {

struct CheckOptions {
  std::string junit;
  std::string out_root = "out/check";
  bool video = false;   // --video: render every run (off by default: CI time)
  bool report = true;   // each run's report.html and the index page
  int jobs = 0;         // -j N: scenarios at once; 0 = the machine's cores
  int shard_k = 0, shard_n = 0;  // --shard K/N (0/0: all)
  std::atomic<bool>* interrupt = nullptr;  // set by a signal: start no more runs
};

// The scenario files under `paths`: files as given, directories searched recursively for
// *.yaml / *.yml, each directory's files in sorted order.
std::vector<std::string> scenario_files(const std::vector<std::string>& paths);

// Shard k of n (1-based) of `files`: every n-th file from the (k−1)-th.
std::vector<std::string> shard_of(const std::vector<std::string>& files, int k, int n);

// Parses "K/N" (1 ≤ K ≤ N ≤ 1000); false when it is not that.
bool parse_shard(const std::string& text, int& k, int& n);

// `omnitwin check PATHS…`: exit 0 all passed, 1 an expectation failed, 2 bad input, 3 a
// runtime failure or an interruption.
int cmd_check(const std::vector<std::string>& paths, const CheckOptions& opt);

// `omnitwin check --merge DIRS…`: the shards' check.json joined into one JUnit report
// (opt.junit) and one index page (opt.out_root); the same exit codes over all results
// (2 also for a missing or unreadable check.json, or a scenario in two shards).
int cmd_check_merge(const std::vector<std::string>& dirs, const CheckOptions& opt);

}  // namespace omnitwin::twin
