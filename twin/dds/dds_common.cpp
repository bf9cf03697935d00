// twin/dds — connection set-up shared by the publisher and the echo (see dds_common.hpp).
#include "twin/dds/dds_common.hpp"

#include <ifaddrs.h>
#include <net/if.h>

#include <charconv>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "omnitwin_msgs.h"

namespace omnitwin::twin {
namespace {

std::string env_or_empty(const char* name) {
  const char* v = std::getenv(name);
  return v ? std::string(v) : std::string();
}

int parse_domain(const std::string& text, const char* origin) {
  int d = -1;
  const char* end = text.data() + text.size();
  auto [p, ec] = std::from_chars(text.data(), end, d);
  if (ec != std::errc() || p != end || d < 0 || d > kMaxDdsDomain)
    throw DdsError("DDS domain '" + text + "' from " + origin + " is not an integer in 0.." +
                   std::to_string(kMaxDdsDomain));
  return d;
}

int resolve_domain(int domain) {
  if (domain >= 0) {
    if (domain > kMaxDdsDomain)
      throw DdsError("DDS domain " + std::to_string(domain) + " is out of range 0.." +
                     std::to_string(kMaxDdsDomain));
    return domain;
  }
  if (domain != -1) throw DdsError("DDS domain " + std::to_string(domain) + " is negative");
  const std::string env = env_or_empty("OMNITWIN_DDS_DOMAIN");
  return env.empty() ? 0 : parse_domain(env, "$OMNITWIN_DDS_DOMAIN");
}

// Whether the interface exists, and whether it is a loopback one.
struct InterfaceFacts {
  bool exists = false;
  bool loopback = false;
};
InterfaceFacts interface_facts(const std::string& name) {
  InterfaceFacts f;
  f.exists = if_nametoindex(name.c_str()) != 0;
  ifaddrs* list = nullptr;
  if (!f.exists || getifaddrs(&list) != 0) return f;
  for (const ifaddrs* a = list; a; a = a->ifa_next)
    if (a->ifa_name && name == a->ifa_name && (a->ifa_flags & IFF_LOOPBACK)) f.loopback = true;
  freeifaddrs(list);
  return f;
}

std::string xml_escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&apos;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string resolve_config_file(const std::string& path) {
  std::error_code ec;
  const auto abs = std::filesystem::absolute(path, ec);
  std::ifstream probe(path);
  if (ec || !probe || std::filesystem::is_directory(abs))
    throw DdsError("cannot read the Cyclone DDS config file '" + path + "'");
  return abs.string();
}

}  // namespace

std::string ResolvedEndpoint::describe() const {
  std::string s = "domain " + std::to_string(domain);
  if (!config_file.empty()) return s + " with config " + config_file;
  if (!interface.empty()) return s + " on interface " + interface;
  return s + " (Cyclone's default configuration)";
}

std::string interface_config_xml(const std::string& interface, bool loopback) {
  return "<CycloneDDS><Domain id=\"any\"><General><Interfaces><NetworkInterface name=\"" +
         xml_escape(interface) + "\"" + (loopback ? " multicast=\"true\"" : "") +
         "/></Interfaces></General></Domain></CycloneDDS>";
}

ResolvedEndpoint resolve_endpoint(const DdsEndpoint& ep) {
  ResolvedEndpoint r;
  r.domain = resolve_domain(ep.domain);
  if (!ep.config_file.empty()) {
    r.config_file = resolve_config_file(ep.config_file);
    r.config = "file://" + r.config_file;
    // Cyclone reads its configuration string as a comma-separated list, so a path with a
    // comma would be cut there (found in review): such a file goes in as its XML text.
    if (r.config_file.find(',') != std::string::npos) {
      std::ifstream f(r.config_file, std::ios::binary);
      std::ostringstream text;
      text << f.rdbuf();
      if (!f) throw DdsError("DDS configuration file " + r.config_file + ": cannot read it");
      r.config = text.str();
    }
    return r;
  }
  r.interface = ep.interface.empty() ? env_or_empty("OMNITWIN_DDS_INTERFACE") : ep.interface;
  if (r.interface.empty()) return r;
  const InterfaceFacts f = interface_facts(r.interface);
  if (!f.exists) throw DdsError("DDS network interface '" + r.interface + "' does not exist");
  r.config = interface_config_xml(r.interface, f.loopback);
  return r;
}

std::string_view TopicInfo::label() const {
  // "rt/" is ROS 2's prefix for topics; ours are under omnitwin/, /clock is ROS 2's own.
  for (const std::string_view prefix : {std::string_view("rt/omnitwin/"), std::string_view("rt/")})
    if (name.starts_with(prefix)) return name.substr(prefix.size());
  return name;
}

const std::vector<TopicInfo>& dds_topics() {
  static const std::vector<TopicInfo> topics{
      {"state", "rt/omnitwin/platform_state", "omnitwin::msg::dds_::PlatformState_",
       &omnitwin_msg_dds__PlatformState__desc},
      {"odom", "rt/omnitwin/odom", "nav_msgs::msg::dds_::Odometry_", &nav_msgs_msg_dds__Odometry__desc},
      {"joint_states", "rt/omnitwin/joint_states", "sensor_msgs::msg::dds_::JointState_",
       &sensor_msgs_msg_dds__JointState__desc},
      {"cmd_vel", "rt/omnitwin/cmd_vel", "geometry_msgs::msg::dds_::Twist_", &geometry_msgs_msg_dds__Twist__desc},
      {"drives", "rt/omnitwin/drive_states", "omnitwin::msg::dds_::DriveStates_",
       &omnitwin_msg_dds__DriveStates__desc},
      {"bus", "rt/omnitwin/bus_statistics", "omnitwin::msg::dds_::BusStatistics_",
       &omnitwin_msg_dds__BusStatistics__desc},
      {"events", "rt/omnitwin/run_events", "omnitwin::msg::dds_::RunEvent_", &omnitwin_msg_dds__RunEvent__desc},
      {"clock", "rt/clock", "rosgraph_msgs::msg::dds_::Clock_", &rosgraph_msgs_msg_dds__Clock__desc},
  };
  return topics;
}

std::optional<TopicInfo> find_topic(std::string_view name) {
  for (const TopicInfo& t : dds_topics())
    if (name == t.short_name || name == t.name || name == t.label()) return t;
  return std::nullopt;
}

DdsEntity& DdsEntity::operator=(DdsEntity&& o) noexcept {
  if (this != &o) {
    reset();
    h_ = o.release();
  }
  return *this;
}

void DdsEntity::reset() {
  if (h_ > 0) dds_delete(h_);
  h_ = 0;
}

DdsQos state_qos(int depth) {
  DdsQos q(dds_create_qos());
  dds_qset_reliability(q.get(), DDS_RELIABILITY_BEST_EFFORT, 0);
  dds_qset_durability(q.get(), DDS_DURABILITY_VOLATILE);
  dds_qset_history(q.get(), DDS_HISTORY_KEEP_LAST, depth);
  return q;
}

DdsQos event_qos(int depth) {
  DdsQos q(dds_create_qos());
  dds_qset_reliability(q.get(), DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
  dds_qset_durability(q.get(), DDS_DURABILITY_TRANSIENT_LOCAL);
  dds_qset_history(q.get(), DDS_HISTORY_KEEP_LAST, depth);
  // Cyclone keeps a transient-local writer's history for late joiners as the durability
  // service's history says (default: keep-last 1), not as the writer's history.
  dds_qset_durability_service(q.get(), 0, DDS_HISTORY_KEEP_LAST, depth, DDS_LENGTH_UNLIMITED,
                              DDS_LENGTH_UNLIMITED, DDS_LENGTH_UNLIMITED);
  return q;
}

void throw_dds(const std::string& what, dds_return_t rc) {
  throw DdsError("DDS " + what + " failed: " + dds_strretcode(rc));
}

DdsParticipant::DdsParticipant(const DdsEndpoint& ep) : ep_(resolve_endpoint(ep)) {
  dds_entity_t created = 0;
  if (!ep_.config.empty()) {
    const dds_entity_t d = dds_create_domain(static_cast<dds_domainid_t>(ep_.domain), ep_.config.c_str());
    if (d < 0 && d != DDS_RETCODE_PRECONDITION_NOT_MET)  // not-met: this process has it already
      throw DdsError("cannot create DDS " + ep_.describe() + ": " + dds_strretcode(d) +
                     " (Cyclone DDS logs the reason on stderr)");
    created = d > 0 ? d : 0;
  }
  participant_ = dds_create_participant(static_cast<dds_domainid_t>(ep_.domain), nullptr, nullptr);
  if (participant_ < 0) {
    const dds_return_t rc = participant_;
    participant_ = 0;
    if (created > 0) dds_delete(created);
    throw DdsError("cannot create a DDS participant in " + ep_.describe() + ": " + dds_strretcode(rc));
  }
}

DdsParticipant::~DdsParticipant() {
  const dds_entity_t domain = dds_get_parent(participant_);
  dds_delete(participant_);
  // An explicit domain outlives its participants; delete it once the last one has gone.
  if (domain > 0 && dds_get_children(domain, nullptr, 0) == 0) dds_delete(domain);
}

dds_entity_t create_topic(dds_entity_t participant, const TopicInfo& topic) {
  const std::string name(topic.name);
  const dds_entity_t t = dds_create_topic(participant, topic.descriptor, name.c_str(), nullptr, nullptr);
  if (t < 0) throw_dds("create_topic " + name, t);
  return t;
}

}  // namespace omnitwin::twin
