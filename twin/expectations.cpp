// twin layer — expectation checks; see expectations.hpp.
#include "twin/expectations.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>

namespace omnitwin::twin {

namespace {

constexpr std::array<std::string_view, 3> kRunMetrics = {"sim_time_s", "wall_time_s",
                                                         "real_time_factor"};
constexpr std::array<std::string_view, 12> kPoseMetrics = {
    "iae_x_cm",       "iae_y_cm",       "iae_contour_cm",      "std_x_cm",
    "std_y_cm",       "std_contour_cm", "final_error_cm",      "max_error_cm",
    "iae_phi_deg",    "std_phi_deg",    "final_phi_error_deg", "max_phi_error_deg"};
// The true pose at the end (platform only): "the platform reached a pose"; and when the plan
// reached the path's end (−1: the run ended first), without which final_error_cm is only the
// error against a plan still on its way.
constexpr std::array<std::string_view, 4> kFinalPose = {"final_x_m", "final_y_m", "final_phi_deg", "path_done_s"};
// What the drives did (DriveHistory): how a master commissioning them is judged.
constexpr std::array<std::string_view, 5> kDriveMetrics = {"all_running_at_s", "stopped_at_s", "faults",
                                                           "running_at_end", "running_at_duration"};
// (the _at_master pair: bus can, per master period as the master sees it)
constexpr std::array<std::string_view, 4> kAxisMetrics = {"iae_velocity_pulse", "std_velocity_pulse",
                                                          "iae_velocity_pulse_at_master",
                                                          "std_velocity_pulse_at_master"};
// bus can, ethercat, m3 and canopen (not_returned … op_since_s are EtherCAT's, the next two
// M-III's, the next three CANopen's; foreign_frames, refused_frames and master_changes
// EtherCAT's, M-III's and the CAN family's over UDP; extended_frames the CAN family's: frames with a 29-bit identifier).
constexpr std::array<std::string_view, 26> kBusMetrics = {
    "frames_tx",    "frames_rx",   "dropouts",       "dropout_rate", "errors",       "frames",
    "error_frames", "lost_frames", "bus_off_events", "load",         "transport_rx_malformed",
    "not_returned", "malformed",   "send_failures",  "overflow",     "op_since_s",
    "corrupted_frames", "servos_on_since_s", "emcy", "sdo_aborts", "power_cycles",
    "foreign_frames", "refused_frames", "extended_frames", "other_pdu_types", "master_changes"};
// The master's reaction: when it stopped, why (simclock::StopReason code), which node; for
// bus ethercat also its own counters (from the master's statistics file).
// The twin's view (lockstep report, realtime supervision: lost_at_s; a master on its own
// clock: sigterm_at_s, exited_at_s, shutdown_s at the run's end) and the EtherCAT and
// M-III masters' own counters (master-stats.json: segment losses and returns among them;
// M-III: exchanges … int_offset_ns, summed over the slaves where per slave, and on the wall
// clock wakes_late and wake_late_max_ns, its deadlines reached half a cycle or more late; CANopen: syncs …
// tpdo_rx, with recoveries = drives brought back to OPERATIONAL; TML: answers, axes_lost).
constexpr std::array<std::string_view, 42> kMasterMetrics = {
    "stopped_at_s", "stop_reason_code", "missing_node", "path_origin_s", "ticks",      "cycles",
    "wkc_errors",   "lost_frames",      "recoveries",   "slaves_lost",   "timeouts",   "sdo_failed",
    "last_wkc",     "segment_losses",   "segment_returns", "lost_at_s",
    "exchanges",    "retries",          "retry_recovered", "missed",     "late",       "bad",
    "lost_axis",    "foreign_master_frames", "min_cycle_ns", "int_offset_ns",
    "syncs",        "sdo_done",         "sdo_aborts",   "emcy",          "heartbeat_timeouts", "boot_ups",
    "tpdo_rx",      "answers",          "axes_lost",    "emergencies",
    "sigterm_at_s", "exited_at_s",      "shutdown_s",   "exit_code",     "wakes_late", "wake_late_max_ns"};
// Per slave: CAN's first nine, EtherCAT's next three, M-III's next nine, CANopen's last nine
// (tec, bus_off_events and error_code serve CANopen too), then TML's three; then the drive
// core's mode of operation (0x6061; every bus with CiA 402 drives) and EtherCAT's SYNC0.
constexpr std::array<std::string_view, 37> kSlaveMetrics = {
    "samples", "dropouts",       "dropout_percent", "resyncs",         "commands",   "bad_frames",
    "tec",     "bus_off_events", "stale_samples",   "al_status_code",  "station_address", "error_code",
    "phase",   "responses",      "fcs_errors",      "missed_syncs",    "missed_commands", "wdt_errors",
    "phase_errors", "comm_alarms", "repeated",
    "emcy",    "sdo_aborts",     "rpdo_rx",         "tpdo_tx",         "pdo_length_errors", "syncs",
    "heartbeats", "faults",      "comm_faults",
    "handled", "take_data2",     "unknown_opcodes", "rpdo_per_s", "tpdo_per_s",
    "mode",    "dc_sync0"};
constexpr std::array<std::string_view, 4> kRealtimeMetrics = {"overruns", "jitter_mean_us",
                                                              "jitter_p99_us", "jitter_max_us"};
constexpr int kAxes = 4;

template <std::size_t N>
bool in(const std::array<std::string_view, N>& list, std::string_view s) {
  return std::find(list.begin(), list.end(), s) != list.end();
}

// A non-negative decimal index, or -1.
long parse_index(std::string_view s) {
  long v = -1;
  if (s.empty()) return -1;
  const auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  return (ec == std::errc() && p == s.data() + s.size() && v >= 0) ? v : -1;
}

}  // namespace

bool is_known_metric(std::string_view path) {
  const auto parts = split_dots(path);
  if (parts.size() == 1) return in(kRunMetrics, parts[0]);
  if (parts.size() == 2) {
    if (parts[0] == "platform" && in(kFinalPose, parts[1])) return true;
    if (parts[0] == "platform" || parts[0] == "platform_odometry") return in(kPoseMetrics, parts[1]);
    if (parts[0] == "drives") return in(kDriveMetrics, parts[1]);
    if (parts[0] == "bus") return in(kBusMetrics, parts[1]);
    if (parts[0] == "realtime") return in(kRealtimeMetrics, parts[1]);
    if (parts[0] == "master") return in(kMasterMetrics, parts[1]);
    return false;
  }
  if (parts.size() == 3 && (parts[0] == "axes" || parts[0] == "slaves")) {
    const long axis = parse_index(parts[1]);
    if (axis < 0 || axis >= kAxes) return false;
    return parts[0] == "axes" ? in(kAxisMetrics, parts[2]) : in(kSlaveMetrics, parts[2]);
  }
  return false;
}

const nlohmann::json* find_metric(const nlohmann::json& metrics, std::string_view path) {
  const nlohmann::json* cur = &metrics;
  for (const auto part : split_dots(path)) {
    // Objects by key, arrays by numeric index; anything else ends the walk.
    if (cur->is_object()) {
      const auto it = cur->find(std::string(part));
      if (it == cur->end()) return nullptr;
      cur = &*it;
    } else if (cur->is_array()) {
      const long i = parse_index(part);
      if (i < 0 || static_cast<std::size_t>(i) >= cur->size()) return nullptr;
      cur = &(*cur)[static_cast<std::size_t>(i)];
    } else {
      return nullptr;
    }
  }
  return cur;
}

ExpectationResult evaluate_expectations(const std::vector<Expectation>& expectations,
                                        const nlohmann::json& metrics) {
  ExpectationResult result;
  for (const auto& e : expectations) {
    const nlohmann::json* value = find_metric(metrics, e.metric);
    // A metric that is absent, not a number or not finite cannot meet any bound.
    if (value == nullptr) {
      result.failures.push_back(fmt::format("{}: missing from metrics", e.metric));
      continue;
    }
    if (value->is_null()) {
      // Null: the run has no value (no samples; a master that reports no state).
      const bool master = e.metric.rfind("master.", 0) == 0;
      result.failures.push_back(fmt::format("{}: not known in this run{}", e.metric,
                                            master ? " (a master on its own clock reports no state; judge it in lockstep)"
                                                   : " (null)"));
      continue;
    }
    if (!value->is_number()) {
      result.failures.push_back(fmt::format("{}: not a number ({})", e.metric, value->dump()));
      continue;
    }
    const double v = value->get<double>();
    if (!std::isfinite(v)) {
      result.failures.push_back(fmt::format("{} = {} is not finite", e.metric, v));
    } else if (e.max && v > *e.max) {
      result.failures.push_back(fmt::format("{} = {} > max {}", e.metric, v, *e.max));
    } else if (e.min && v < *e.min) {
      result.failures.push_back(fmt::format("{} = {} < min {}", e.metric, v, *e.min));
    }
  }
  result.passed = result.failures.empty();
  return result;
}

nlohmann::json ExpectationResult::to_json() const {
  return nlohmann::json{{"passed", passed}, {"failures", failures}};
}

std::vector<std::string_view> split_dots(std::string_view path) {
  std::vector<std::string_view> parts;
  std::size_t start = 0;
  while (true) {
    const auto dot = path.find('.', start);
    parts.push_back(path.substr(start, dot == std::string_view::npos ? dot : dot - start));
    if (dot == std::string_view::npos) return parts;
    start = dot + 1;
  }
}

}  // namespace omnitwin::twin
