// twin layer — what a run leaves for people after its records: the MP4 and the report.
//
// Both are made from the run directory's files once the run has ended (docs/run-directory.md),
// never from inside the stepping loop: a lockstep run is exactly as fast with video on as off
// (DESIGN §8), and `omnitwin render RUN_DIR` does the same for any recorded run. A failure
// here (no python3-matplotlib, a full disk) is reported, never thrown: the records stand.
#pragma once

#include <atomic>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "media/run_report.hpp"
#include "twin/scenario.hpp"

namespace omnitwin::twin {

struct OutputPlan {
  bool video = false;
  std::string video_file;  // "" = RUN_DIR/video.mp4
  VideoSpec video_spec;
  bool report = false;
  std::function<void()> before_report;  // may be empty: runs after the video, before the report
};

struct OutputsResult {
  std::string video;                // the MP4 written ("" if none)
  int video_frames = 0;
  double video_s = 0;               // its duration [s]
  bool video_stopped_early = false; // `stop` cut the rendering short (the file is still valid)
  double render_wall_s = 0;
  std::string renderer;             // the GL that drew the video (vendor / renderer / version)
  std::string report;               // report.html ("" if none)
  double report_wall_s = 0;
  std::vector<std::string> errors;  // one line per output that could not be made
  bool bad_record = false;          // the video failed on a missing or malformed run record
};

// Renders the video and/or writes the report of the run in `run_dir`. `stop` (may be
// null) ends the rendering early; what was rendered is finalised into a playable file. Not
// real-time safe; call after the run.
OutputsResult make_run_outputs(const std::string& run_dir, const OutputPlan& plan, const std::atomic<bool>* stop);

// Writes DIR/index.html over the runs `omnitwin check` made; `summary` as
// media/report/check_index.py reads it. Returns "" or the reason it failed.
std::string write_check_index(const std::string& out_root, const std::string& title, const nlohmann::json& results);

// Where the report scripts live (the source tree's media/report).
std::string report_scripts_dir();
// The report scripts' tools (this build's media/report, Debian's python3).
media::ReportTools report_tools();

}  // namespace omnitwin::twin
