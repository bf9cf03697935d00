// media layer — the run report (report.html, plots/*.png) and the `omnitwin check` index page.
//
// The pages are drawn by two Python scripts (media/report/run_report.py, check_index.py) with
// Debian's python3-matplotlib, so the C++ side needs no plotting library. These functions
// only find and start them (posix_spawn, no shell), wait, and turn every way that can go
// wrong (no python3, no matplotlib, a missing script, a bad run directory, a script error, a
// hung script) into ok = false and a one-line error: a report is an extra after a run whose
// records already stand, so nothing here throws.
//
// The scripts read only the run directory's files (docs/run-directory.md), so a report can
// be made later or on another machine. The media library has no compile-time source path:
// the caller says where the scripts are (ReportTools::scripts_dir).
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

namespace omnitwin::media {

// How to run the report scripts.
struct ReportTools {
  std::string python = "/usr/bin/python3";  // an interpreter with matplotlib (Debian: python3-matplotlib)
  std::string scripts_dir;                  // folder holding run_report.py and check_index.py
  double timeout_s = 120;                   // the script is killed after this long [s]
};

struct ReportResult {
  bool ok = false;
  std::string path;     // the HTML page written (when ok)
  std::string error;    // why not, one line (when !ok)
  double seconds = 0;   // wall time the whole call took [s]
};

// Writes RUN_DIR/report.html and RUN_DIR/plots/*.png from the files in run_dir (each file
// written to a temporary name and renamed). Missing optional files are noted in the page;
// an interrupted run or one without metrics.json still gets a page saying so. ok = false
// when run_dir is missing or is not a run directory, or the tools cannot run.
// Takes about a second for a run of a few thousand samples. Not real-time safe: spawns a
// process, blocks until it ends (or tools.timeout_s passes), allocates. Thread-safe.
// `video`: the run's video when it is not RUN_DIR/video.mp4 (run --video FILE, render --out
// FILE); the report embeds and links it by a path relative to the run directory.
// `renderer`: the GL that drew the video (VideoResult::renderer), said under it; "" for none.
ReportResult write_run_report(const std::string& run_dir, const ReportTools& tools, const std::string& video = "",
                              const std::string& renderer = "");

// Writes out_html, the index page over the scenarios `omnitwin check` ran. `summary` is
// {"title": str, "results": [{"scenario", "file", "run_dir", "exit_code", "passed",
// "failures": [str], "metrics": {...}}]} (media/report/check_index.py); links to each
// run's report.html are relative to out_html's folder, which is created if needed. The
// summary passes through a temporary file beside out_html, removed afterwards.
// Not real-time safe (spawns a process and blocks); thread-safe for distinct out_html.
ReportResult write_check_index(const std::string& out_html, const nlohmann::json& summary,
                               const ReportTools& tools);

// Writes png, the plot of `omnitwin sweep`: metric y against parameter x from the sweep's
// table (csv: point, the params, the metrics, passed, exit_code), one line per combination of
// the other parameters, points whose expectations failed marked (media/report/sweep_plot.py).
// Not real-time safe (spawns a process and blocks); thread-safe for distinct png.
ReportResult write_sweep_plot(const std::string& csv, const std::string& png, const std::string& x,
                              const std::string& y, const std::vector<std::string>& params, const ReportTools& tools);

}  // namespace omnitwin::media
