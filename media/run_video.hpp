// media layer — the video of a recorded run: run directory in, MP4 out.
//
// render_run reads only the files of the run directory (docs/run-directory.md): run.json
// (faults), platform.xml (the exact model), trajectory.csv (pose, speed, wheel angles,
// reference) and bus.csv if present (bus health). It never touches a live simulation, so
// `omnitwin render RUN_DIR` works later or on another machine, and `omnitwin run --video`
// calls it after the run, keeping rendering out of lockstep stepping (DESIGN §8).
//
// Timing: frame k shows the state at sim time t = k / fps, interpolated linearly between
// the two control samples around it (clamped to the first/last sample); frames run from
// t = 0 to the last sample, so a run of T seconds gives floor(T * fps) + 1 frames, and one
// more showing the state at T when T * fps is not whole: the final state is the last frame. The chassis height and tilt come from the model's qpos0.
#pragma once

#include <atomic>
#include <functional>
#include <stdexcept>
#include <string>

namespace omnitwin::media {

struct VideoOptions {
  int width = 640;              // frame size [pixels]; both even (H.264 yuv420p)
  int height = 480;
  double fps = 30;              // frames per second of sim time [1/s], in (0, 1000]
  bool overview_inset = true;   // fixed "overview" camera as a top-right inset
  bool overlay = true;          // text overlay top-left (time, pose, speed, bus, faults)
  bool high_quality = false;    // shadows + 4x multisampling: 3-5x slower in software
  std::string camera = "track"; // model camera filling the frame ("track", "top", "overview")
  // Off-screen GL backend: "osmesa" (software, no GPU) or "egl" (a GPU through EGL if there
  // is one, else Mesa llvmpipe; see media/offscreen_gl.hpp). Empty: the environment variable
  // OMNITWIN_GL (osmesa|egl), osmesa if unset. One process renders with one backend only.
  std::string backend;
  // Called after each encoded frame with (frames done, frames in all), on the rendering
  // thread; e.g. a progress bar. May be empty.
  std::function<void(int, int)> progress;
};

struct VideoResult {
  std::string path;          // the MP4 written ("" when stopped before its first frame)
  int frames = 0;            // frames encoded
  double duration_s = 0;     // frames / fps [s]
  bool stopped_early = false;  // `stop` was set before the last frame
  double render_s = 0;       // wall time spent [s]
  std::string renderer{};    // the GL that drew it: vendor / renderer / version (backend)
};

// A run directory's record that render_run needs is missing or malformed (trajectory.csv,
// platform.xml): bad input, not a failure of the renderer. The message names the file and,
// where there is one, the line.
struct BadRunRecord : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// "" when out_file may be written, else why not: it exists and is not an MP4 (a run's record,
// any other file: a typo in --out would have deleted it; found in review) or not a regular
// file. Not real-time safe.
std::string video_file_problem(const std::string& out_file);

// Renders the recorded run in run_dir into out_file (its directory must exist), written as
// DIR/.NAME.part and renamed to out_file only once the MP4 is complete (VideoEncoder), so
// out_file is whole or absent, never cut. An older out_file is removed first: it never
// passes for this render. `stop` (may be null) is polled before every frame: once it is true
// the frames so far are finalised into a playable file (finalising reads no flag, so more
// stop requests cannot cut it) and the result says stopped_early. Throws
// BadRunRecord for a missing or malformed trajectory.csv or platform.xml (run.json and
// bus.csv are optional: one that is absent or unreadable only drops its overlay line, with a
// warning), std::runtime_error otherwise (unknown camera, unwritable output, disk full), each
// with a message naming the file ("; the older FILE was removed" when one was), after
// which nothing is under out_file; std::invalid_argument for bad options or an out_file that
// video_file_problem() refuses (nothing removed). The frames are at k/fps and, when the
// run's length T is not a whole number of frames, one more at T: the final state is the
// last frame.
// Not real-time safe: allocates, renders in software, writes files. Uses an off-screen GL
// context current on the calling thread for the duration of the call.
VideoResult render_run(const std::string& run_dir, const std::string& out_file,
                       const VideoOptions& options, const std::atomic<bool>* stop = nullptr);

}  // namespace omnitwin::media
