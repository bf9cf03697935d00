// twin/web — samples, events and recorded runs as the view's JSON (see web_samples.hpp).
#include "twin/web/web_samples.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "twin/csv_columns.hpp"
#include "twin/dds/rate_decimator.hpp"

namespace omnitwin::twin {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

// A number for JSON: NaN and infinities (unknown) as null.
json num(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

json bus_json(const BusSample& b) {
  return {{"has_frames", b.has_frames}, {"tx", b.frames_tx},     {"rx", b.frames_rx},
          {"dropouts", b.dropouts},     {"errors", b.errors},    {"load", num(b.load)},
          {"wkc", b.wkc >= 0 ? json(b.wkc) : json(nullptr)}};
}

json read_json_file(const fs::path& p) {
  std::ifstream f(p);
  if (!f) throw std::runtime_error("cannot read " + p.string());
  try {
    return json::parse(f);
  } catch (const json::exception& e) {
    throw std::runtime_error(p.string() + ": " + e.what());
  }
}

// events.log lines: "%12.6f  %-10s  text" (records.cpp).
json read_events(const fs::path& p) {
  json events = json::array();
  std::ifstream f(p);
  std::string line;
  while (std::getline(f, line)) {
    std::istringstream in(line);
    double t = 0;
    std::string kind;
    if (!(in >> t >> kind)) continue;
    std::string text;
    std::getline(in >> std::ws, text);
    events.push_back({{"t", t}, {"kind", to_string(run_event_kind(kind))}, {"source", kind}, {"text", text}});
  }
  return events;
}

// The drive state code as bus.csv stores it (DriveStateCode's number).
const char* state_name(double code) {
  if (!std::isfinite(code) || code < 0 || code > 4) return "?";
  return to_string(static_cast<DriveStateCode>(static_cast<int>(code)));
}

// Row `r` of trajectory.csv and the bus.csv row `b` taken at the same time, as one sample.
json recorded_sample(const CsvColumns& tr, std::size_t r, const CsvColumns& bus, std::size_t b, bool has_frames,
                     std::uint64_t seq) {
  auto at = [&](const std::string& c) { return num(tr.column(c)[r]); };
  auto bus_at = [&](const std::string& c) { return bus.column(c)[b]; };
  json s{{"t", tr.column("t")[r]}, {"seq", seq}};
  for (const char* k : {"x", "y", "phi", "vx", "vy", "wz", "ref_x", "ref_y", "ref_phi", "cmd_vx", "cmd_vy", "cmd_wz"})
    s[k] = at(k);
  json wheels = json::array(), drives = json::array();
  for (int i = 1; i <= 4; ++i) {
    const std::string w = "w" + std::to_string(i) + "_";
    wheels.push_back({{"angle", at(w + "angle_rad")}, {"speed", at(w + "speed_rad_s")},
                      {"cmd", at(w + "cmd_rad_s")}, {"torque", at(w + "torque_nm")}});
    drives.push_back({{"node", has_frames ? i : 0}, {"state", state_name(bus_at("s" + std::to_string(i) + "_state"))},
                      {"command", at(w + "cmd_rad_s")}, {"setpoint", at(w + "setpoint_rad_s")}});
  }
  s["wheels"] = std::move(wheels);
  s["drives"] = std::move(drives);
  s["bus"] = {{"has_frames", has_frames},
              {"tx", bus_at("frames_tx")},
              {"rx", bus_at("frames_rx")},
              {"dropouts", bus_at("dropouts")},
              {"errors", bus_at("errors")},
              {"load", num(bus_at("load"))}};
  s["faults"] = bus_at("active_faults");
  return s;
}

}  // namespace

json sample_json(const StateSample& s) {
  json wheels = json::array(), drives = json::array();
  for (int i = 0; i < 4; ++i) {
    wheels.push_back({{"angle", num(s.wheel_angle[i])}, {"speed", num(s.wheel_speed[i])},
                      {"cmd", num(s.wheel_cmd[i])}, {"torque", num(s.wheel_torque[i])}});
    const DriveSample& d = s.drives[i];
    drives.push_back({{"node", d.node},
                      {"state", to_string(d.state)},
                      {"comm", d.comm_state ? d.comm_state : ""},
                      {"device", d.device_state ? d.device_state : ""},
                      {"command", num(d.command_rad_s)},
                      {"setpoint", num(d.setpoint_rad_s)}});
  }
  return {{"t", static_cast<double>(s.t_ns) * 1e-9},
          {"seq", s.seq},
          {"x", num(s.x)}, {"y", num(s.y)}, {"phi", num(s.phi)},
          {"vx", num(s.vx)}, {"vy", num(s.vy)}, {"wz", num(s.wz)},
          {"ref_x", num(s.ref_x)}, {"ref_y", num(s.ref_y)}, {"ref_phi", num(s.ref_phi)},
          {"cmd_vx", num(s.cmd_vx)}, {"cmd_vy", num(s.cmd_vy)}, {"cmd_wz", num(s.cmd_wz)},
          {"wheels", std::move(wheels)},
          {"drives", std::move(drives)},
          {"bus", bus_json(s.bus)},
          {"faults", s.active_faults}};
}

json event_json(const RunEvent& e) {
  return {{"t", static_cast<double>(e.t_ns) * 1e-9}, {"kind", to_string(e.kind)}, {"source", e.source}, {"text", e.text}};
}

json info_json(const RunInfo& info, bool started) {
  return {{"mode", "live"},
          {"started", started},
          {"scenario", info.scenario},
          {"bus", info.bus},
          {"clock", info.clock},
          {"control_period_s", info.control_period_s},
          {"duration_s", info.duration_s},
          {"run_dir", info.run_dir},
          {"video", nullptr}};
}

json end_json(const json& metrics, std::optional<int> exit_code) {
  json passed = nullptr;
  if (metrics.contains("expectations") && metrics["expectations"].contains("passed"))
    passed = metrics["expectations"]["passed"];
  return {{"passed", passed}, {"exit_code", exit_code ? json(*exit_code) : json(nullptr)}, {"metrics", metrics}};
}

std::optional<int> recorded_exit_code(const json& metrics) {
  if (!metrics.is_object() || !metrics.contains("expectations")) return std::nullopt;
  if (metrics.value("interrupted", false) || metrics.contains("error")) return 3;
  return metrics["expectations"].value("passed", false) ? 0 : 1;
}

json recorded_run_json(const std::string& run_dir, double rate_hz) {
  const fs::path dir(run_dir);
  const json run = read_json_file(dir / "run.json");
  const CsvColumns tr = read_csv_columns((dir / "trajectory.csv").string());
  const CsvColumns bus = read_csv_columns((dir / "bus.csv").string());
  const std::string bus_kind = run.value("bus", "");
  json info{{"mode", "recorded"},
            {"started", true},
            {"scenario", run.value("scenario", "")},
            {"bus", bus_kind},
            {"clock", run.value("clock", "")},
            {"control_period_s", run.value("control_period_s", 0.0)},
            {"duration_s", run.value("duration_s", 0.0)},
            {"run_dir", fs::absolute(dir).lexically_normal().string()},
            {"video", fs::exists(dir / "video.mp4") ? json("/run/video.mp4") : json(nullptr)}};
  // Decimate by simulated time as the live view does; bus.csv rows pair with trajectory rows
  // by time (both are written at every control sample).
  RateDecimator keep(rate_hz);
  json samples = json::array();
  const auto& t = tr.column("t");
  const auto& bt = bus.column("t");
  std::size_t b = 0;
  for (std::size_t r = 0; r < tr.rows() && bus.rows() > 0; ++r) {
    if (!keep.take(std::llround(t[r] * 1e9)) && r + 1 != tr.rows()) continue;
    while (b + 1 < bus.rows() && bt[b + 1] <= t[r] + 1e-9) ++b;
    samples.push_back(recorded_sample(tr, r, bus, b, bus_kind != "direct", r));
  }
  json metrics = fs::exists(dir / "metrics.json") ? read_json_file(dir / "metrics.json") : json::object();
  const std::optional<int> exit_code = recorded_exit_code(metrics);
  return {{"info", std::move(info)},
          {"samples", std::move(samples)},
          {"events", read_events(dir / "events.log")},
          {"end", end_json(metrics, exit_code)}};
}

}  // namespace omnitwin::twin
