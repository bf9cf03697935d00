// twin layer — the video and the report of a finished run; see run_outputs.hpp.
#include "twin/run_outputs.hpp"

#include <fmt/format.h>

#include <filesystem>

#include "media/run_report.hpp"
#include "media/run_video.hpp"
#include "twin/clock.hpp"

namespace omnitwin::twin {

media::ReportTools report_tools() {
  media::ReportTools t;
  t.scripts_dir = report_scripts_dir();
  return t;
}

namespace {

namespace fs = std::filesystem;

void render_video(const std::string& run_dir, const OutputPlan& plan, const std::atomic<bool>* stop,
                  OutputsResult& r) {
  const media::VideoOptions& o = plan.video_spec;
  const std::string file = plan.video_file.empty() ? (fs::path(run_dir) / "video.mp4").string() : plan.video_file;
  try {
    const media::VideoResult v = media::render_run(run_dir, file, o, stop);
    r.video = v.path;
    r.video_frames = v.frames;
    r.video_s = v.duration_s;
    r.video_stopped_early = v.stopped_early;
    r.render_wall_s = v.render_s;
    r.renderer = v.renderer;
  } catch (const media::BadRunRecord& e) {
    r.errors.push_back(fmt::format("video: {}", e.what()));
    r.bad_record = true;
  } catch (const std::exception& e) {
    r.errors.push_back(fmt::format("video: {}", e.what()));
  }
}

void write_report(const std::string& run_dir, OutputsResult& r) {
  // A video made elsewhere (--video FILE) is the run's video too: the report embeds it.
  std::error_code ec;
  const bool elsewhere = !r.video.empty() && !fs::equivalent(r.video, fs::path(run_dir) / "video.mp4", ec);
  const media::ReportResult rep =
      media::write_run_report(run_dir, report_tools(), elsewhere ? r.video : "", r.video.empty() ? "" : r.renderer);
  if (rep.ok) {
    r.report = rep.path;
    r.report_wall_s = rep.seconds;
  } else {
    r.errors.push_back(fmt::format("report: {}", rep.error));
  }
}

}  // namespace

std::string report_scripts_dir() { return (fs::path(OMNITWIN_SOURCE_DIR) / "media" / "report").string(); }

OutputsResult make_run_outputs(const std::string& run_dir, const OutputPlan& plan, const std::atomic<bool>* stop) {
  OutputsResult r;
  // The video first: the report links it when it exists.
  if (plan.video) render_video(run_dir, plan, stop, r);
  if (plan.report && plan.before_report) plan.before_report();
  if (plan.report) write_report(run_dir, r);
  return r;
}

std::string write_check_index(const std::string& out_root, const std::string& title, const nlohmann::json& results) {
  const nlohmann::json summary = {{"title", title}, {"results", results}};
  const media::ReportResult rep =
      media::write_check_index((fs::path(out_root) / "index.html").string(), summary, report_tools());
  return rep.ok ? "" : rep.error;
}

}  // namespace omnitwin::twin
