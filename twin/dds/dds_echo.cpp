// twin/dds — the echo listener (see dds_echo.hpp): one reader per topic on one waitset,
// samples taken by loan and formatted through one JSON object per message type, from which
// the text form is also derived, so both formats carry the same fields.
#include "twin/dds/dds_echo.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <stdexcept>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "twin/dds/dds_messages.hpp"

namespace omnitwin::twin {
namespace {

using Json = nlohmann::ordered_json;
using Clock = std::chrono::steady_clock;

double seconds(std::int64_t t_ns) { return static_cast<double>(t_ns) / 1e9; }

Json header_json(const char* topic, const std_msgs_msg_dds__Header_& h) {
  const std::int64_t t_ns = ddsmsg::to_ns(h.stamp);
  return Json{{"topic", topic}, {"t", seconds(t_ns)}, {"t_ns", t_ns}, {"frame_id", h.frame_id}};
}

template <std::size_t N>
Json array_json(const double (&a)[N]) {
  return Json(std::vector<double>(a, a + N));
}

Json state_json(const void* p) {
  const auto& m = *static_cast<const omnitwin_msg_dds__PlatformState_*>(p);
  return Json{{"topic", "platform_state"}, {"t", seconds(m.t_ns)}, {"t_ns", m.t_ns}, {"seq", m.seq},
              {"x", m.x}, {"y", m.y}, {"phi", m.phi}, {"vx", m.vx}, {"vy", m.vy}, {"wz", m.wz},
              {"ref_x", m.ref_x}, {"ref_y", m.ref_y}, {"ref_phi", m.ref_phi},
              {"cmd_vx", m.cmd_vx}, {"cmd_vy", m.cmd_vy}, {"cmd_wz", m.cmd_wz},
              {"wheel_angle", array_json(m.wheel_angle)}, {"wheel_speed", array_json(m.wheel_speed)},
              {"wheel_cmd", array_json(m.wheel_cmd)}, {"wheel_torque", array_json(m.wheel_torque)},
              {"active_faults", m.active_faults}};
}

Json odom_json(const void* p) {
  const auto& m = *static_cast<const nav_msgs_msg_dds__Odometry_*>(p);
  Json j = header_json("odom", m.header);
  const auto& pose = m.pose.pose;
  const auto& tw = m.twist.twist;
  j.update(Json{{"child_frame_id", m.child_frame_id},
                {"x", pose.position.x}, {"y", pose.position.y}, {"z", pose.position.z},
                {"qx", pose.orientation.x}, {"qy", pose.orientation.y}, {"qz", pose.orientation.z},
                {"qw", pose.orientation.w}, {"vx", tw.linear.x}, {"vy", tw.linear.y}, {"vz", tw.linear.z},
                {"wx", tw.angular.x}, {"wy", tw.angular.y}, {"wz", tw.angular.z}});
  return j;
}

template <class Seq>
Json sequence_json(const Seq& s) {
  Json a = Json::array();
  for (std::uint32_t i = 0; i < s._length; ++i) a.push_back(s._buffer[i]);
  return a;
}

Json joints_json(const void* p) {
  const auto& m = *static_cast<const sensor_msgs_msg_dds__JointState_*>(p);
  Json j = header_json("joint_states", m.header);
  j.update(Json{{"name", sequence_json(m.name)}, {"position", sequence_json(m.position)},
                {"velocity", sequence_json(m.velocity)}, {"effort", sequence_json(m.effort)}});
  return j;
}

Json cmd_vel_json(const void* p) {
  const auto& m = *static_cast<const geometry_msgs_msg_dds__Twist_*>(p);
  return Json{{"topic", "cmd_vel"}, {"vx", m.linear.x}, {"vy", m.linear.y}, {"vz", m.linear.z},
              {"wx", m.angular.x}, {"wy", m.angular.y}, {"wz", m.angular.z}};
}

Json drives_json(const void* p) {
  const auto& m = *static_cast<const omnitwin_msg_dds__DriveStates_*>(p);
  Json drives = Json::array();
  for (const auto& d : m.drives)
    drives.push_back(Json{{"node", d.node}, {"state", d.state}, {"state_name", d.state_name},
                          {"command_rad_s", d.command_rad_s}, {"setpoint_rad_s", d.setpoint_rad_s},
                          {"dac_code", d.dac_code}, {"encoder_count", d.encoder_count}});
  return Json{{"topic", "drive_states"}, {"t", seconds(m.t_ns)}, {"t_ns", m.t_ns}, {"seq", m.seq},
              {"drives", drives}};
}

Json bus_json(const void* p) {
  const auto& m = *static_cast<const omnitwin_msg_dds__BusStatistics_*>(p);
  return Json{{"topic", "bus_statistics"}, {"t", seconds(m.t_ns)}, {"t_ns", m.t_ns}, {"seq", m.seq},
              {"bus", m.bus}, {"has_frames", m.has_frames}, {"frames_tx", m.frames_tx},
              {"frames_rx", m.frames_rx}, {"dropouts", m.dropouts}, {"errors", m.errors}, {"load", m.load}};
}

Json clock_json(const void* p) {
  const auto& m = *static_cast<const rosgraph_msgs_msg_dds__Clock_*>(p);
  const std::int64_t t_ns = ddsmsg::to_ns(m.clock);
  return Json{{"topic", "clock"}, {"t", seconds(t_ns)}, {"t_ns", t_ns}, {"sec", m.clock.sec}, {"nanosec", m.clock.nanosec}};
}

Json event_json(const void* p) {
  const auto& m = *static_cast<const omnitwin_msg_dds__RunEvent_*>(p);
  return Json{{"topic", "run_events"}, {"t", seconds(m.t_ns)}, {"t_ns", m.t_ns}, {"kind", m.kind_name},
              {"source", m.source}, {"text", m.text}, {"scenario", m.scenario}};
}

using Formatter = Json (*)(const void*);

Formatter formatter_for(std::string_view short_name) {
  if (short_name == "state") return state_json;
  if (short_name == "odom") return odom_json;
  if (short_name == "joint_states") return joints_json;
  if (short_name == "cmd_vel") return cmd_vel_json;
  if (short_name == "drives") return drives_json;
  if (short_name == "bus") return bus_json;
  if (short_name == "clock") return clock_json;
  return event_json;
}

// The text form: "<topic> key=value …", numbers with 6 significant digits, nested values
// in brackets.
std::string text_value(const Json& v) {
  if (v.is_number_float()) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.6g", v.get<double>());
    return buf;
  }
  if (v.is_string()) return v.get<std::string>();
  if (v.is_array() || v.is_object()) {
    std::string s = v.is_array() ? "[" : "{";
    for (auto it = v.begin(); it != v.end(); ++it) {
      if (it != v.begin()) s += v.is_array() ? "," : " ";
      if (v.is_object()) s += it.key() + "=";
      s += text_value(*it);
    }
    return s + (v.is_array() ? "]" : "}");
  }
  return v.dump();
}

std::string text_line(const Json& j) {
  std::string line = j.at("topic").get<std::string>();
  for (auto it = j.begin(); it != j.end(); ++it) {
    if (it.key() == "topic" || it.key() == "t_ns") continue;
    line += " " + it.key() + "=" + text_value(*it);
  }
  return line;
}

std::vector<TopicInfo> select_topics(const std::string& name) {
  if (name.empty() || name == "all") return dds_topics();
  if (auto t = find_topic(name)) return {*t};
  std::string known;
  for (const TopicInfo& t : dds_topics()) known += " " + std::string(t.short_name);
  throw std::invalid_argument("unknown DDS topic '" + name + "' (known: all" + known +
                              ", or a full name such as rt/omnitwin/odom)");
}

// The readers and the waitset that wakes on any of them.
class Subscription {
 public:
  Subscription(dds_entity_t participant, const std::vector<TopicInfo>& topics);
  // Waits up to `timeout` for samples and prints them; returns how many were printed
  // (at most `limit`, 0 = no limit).
  std::uint64_t wait_and_print(dds_duration_t timeout, std::uint64_t limit, bool json, std::ostream& out);

 private:
  std::uint64_t take_and_print(std::size_t reader, std::uint64_t limit, bool json, std::ostream& out);
  std::vector<dds_entity_t> readers_;
  std::vector<Formatter> formatters_;
  DdsEntity waitset_;
};

Subscription::Subscription(dds_entity_t participant, const std::vector<TopicInfo>& topics)
    : waitset_(dds_create_waitset(participant)) {
  if (waitset_.get() < 0) throw_dds("create_waitset", waitset_.release());
  // Up to 65536 unread states per reader (memory only for what is unread): a lockstep run
  // publishes faster than real time (about a state per wall millisecond on the thesis line),
  // and an echo that a loaded machine leaves unscheduled must not lose them to a shallow
  // cache. At 1024 a machine at load 5 on 2 cores dropped the first 1177 states of the thesis
  // line, the reader keeping only the newest 1024 (found by a walkthrough).
  const DdsQos state = state_qos(65536), events = event_qos(kEventHistory);
  for (const TopicInfo& t : topics) {
    const bool is_events = t.short_name == "events";
    const dds_entity_t topic = create_topic(participant, t);
    const dds_entity_t r = dds_create_reader(participant, topic, is_events ? events.get() : state.get(), nullptr);
    if (r < 0) throw_dds("create_reader " + std::string(t.name), r);
    const dds_entity_t cond = dds_create_readcondition(r, DDS_ANY_STATE);
    if (cond < 0) throw_dds("create_readcondition", cond);
    const dds_return_t rc = dds_waitset_attach(waitset_.get(), cond, static_cast<dds_attach_t>(readers_.size()));
    if (rc < 0) throw_dds("waitset_attach", rc);
    readers_.push_back(r);
    formatters_.push_back(formatter_for(t.short_name));
  }
}

std::uint64_t Subscription::wait_and_print(dds_duration_t timeout, std::uint64_t limit, bool json,
                                           std::ostream& out) {
  std::vector<dds_attach_t> triggered(readers_.size());
  const dds_return_t n = dds_waitset_wait(waitset_.get(), triggered.data(), triggered.size(), timeout);
  std::uint64_t printed = 0;
  for (dds_return_t i = 0; i < n; ++i) {
    const std::uint64_t left = limit ? limit - printed : 0;
    printed += take_and_print(static_cast<std::size_t>(triggered[static_cast<std::size_t>(i)]), left, json, out);
    if (limit && printed >= limit) break;
  }
  return printed;
}

std::uint64_t Subscription::take_and_print(std::size_t reader, std::uint64_t limit, bool json, std::ostream& out) {
  constexpr std::size_t kBatch = 64;
  void* samples[kBatch] = {nullptr};
  dds_sample_info_t infos[kBatch];
  const dds_return_t n = dds_take(readers_[reader], samples, infos, kBatch, kBatch);
  std::uint64_t printed = 0;
  for (dds_return_t i = 0; i < n && (!limit || printed < limit); ++i) {
    if (!infos[i].valid_data) continue;
    const Json j = formatters_[reader](samples[i]);
    // Bytes that are not UTF-8 (a run directory's name may hold them) are replaced: dump()
    // threw on them and ended the echo with exit 3 (found in review).
    out << (json ? j.dump(-1, ' ', false, Json::error_handler_t::replace) : text_line(j)) << '\n';
    out.flush();
    ++printed;
  }
  if (n > 0) dds_return_loan(readers_[reader], samples, n);
  return printed;
}

}  // namespace

int run_echo(const EchoOptions& o, std::ostream& out, const std::atomic<bool>* stop) {
  const std::vector<TopicInfo> topics = select_topics(o.topic);
  DdsParticipant participant(DdsEndpoint{o.domain, o.interface, o.config_file});
  Subscription sub(participant.get(), topics);
  const auto timeout = std::chrono::duration<double>(o.timeout_s);
  constexpr dds_duration_t kSlice = DDS_MSECS(50);
  std::uint64_t printed = 0;
  Clock::time_point last = Clock::now();
  for (;;) {
    if (stop && stop->load()) return kEchoOk;
    dds_duration_t slice = kSlice;
    if (o.timeout_s > 0) {
      const auto left = timeout - (Clock::now() - last);
      if (left.count() <= 0) {
        if (o.count == 0 && printed > 0) return kEchoOk;
        // Say why the exit is 1 (it said nothing; found by a walkthrough).
        if (printed == 0) std::cerr << fmt::format("omnitwin echo: no sample within {:g} s\n", o.timeout_s);
        else std::cerr << fmt::format("omnitwin echo: {} of {} samples, then none within {:g} s\n", printed, o.count, o.timeout_s);
        return kEchoTimeout;
      }
      slice = std::min<dds_duration_t>(slice, static_cast<dds_duration_t>(left.count() * 1e9) + 1);
    }
    const std::uint64_t got = sub.wait_and_print(slice, o.count ? o.count - printed : 0, o.json, out);
    printed += got;
    if (o.count && printed >= o.count) return kEchoOk;
    if (got) last = Clock::now();
  }
}

}  // namespace omnitwin::twin
