// twin/web — the view's data as JSON: a run's state samples and events (live, from the run's
// observer stream) and a recorded run read back from its run directory, in one format so that
// the page draws a live run and a recorded one with the same code (docs/web-view.md).
// Not real-time code: the live path converts on the web server's thread, never the run's.
#pragma once

#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "twin/run_state.hpp"

namespace omnitwin::twin {

// One sample: {"t" [s], "seq", "x","y","phi", "vx","vy","wz", "ref_*", "cmd_*", "wheels": [{angle,
// speed, cmd, torque}×4], "drives": [{node, state, command, setpoint}×4], "bus": {has_frames, tx,
// rx, dropouts, errors, load}, "faults"}. NaN (unknown) becomes null.
nlohmann::json sample_json(const StateSample& s);

// One event: {"t" [s], "kind", "source", "text"}.
nlohmann::json event_json(const RunEvent& e);

// What a live run's /api/info says before and after it starts.
nlohmann::json info_json(const RunInfo& info, bool started);

// The `end` message: {"passed", "exit_code" (null when not known), "metrics"} from
// metrics.json's content.
nlohmann::json end_json(const nlohmann::json& metrics, std::optional<int> exit_code);
// The exit code `omnitwin run` gave a recorded run, from its metrics.json: 3 when it was
// interrupted (in the run or in its outputs) or failed, else 0 passed / 1 failed; none without
// a verdict. (The view showed "passed" for a run interrupted during its outputs; found in review.)
std::optional<int> recorded_exit_code(const nlohmann::json& metrics);

// A recorded run directory as the view's /api/run: {"info", "samples" (taken every 1/rate_hz
// of simulated time, as a live view would have had them), "events", "end"}. Reads run.json,
// trajectory.csv, bus.csv, events.log and metrics.json (absent events or metrics: empty);
// info.video is "/run/video.mp4" when the directory has one. Throws std::runtime_error naming
// the file when a required record is missing or unreadable.
nlohmann::json recorded_run_json(const std::string& run_dir, double rate_hz);

}  // namespace omnitwin::twin
