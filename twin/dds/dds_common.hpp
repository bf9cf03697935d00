// twin/dds — what the DDS publisher and the echo share: the error type, where to connect
// (domain, interface, Cyclone XML) and how the environment fills it in, the topic table,
// and RAII owners for Cyclone DDS C API entities and QoS objects.
//
// Connection set-up is explicit: a named interface becomes a generated Cyclone XML passed to
// dds_create_domain, so that a process can hold several domains, each on its own interface,
// without touching the process-wide CYCLONEDDS_URI. Nothing here is real-time safe; it runs
// once at set-up.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include <dds/dds.h>

namespace omnitwin::twin {

// A DDS set-up failure (bad domain, unknown interface, unreadable or rejected config).
class DdsError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Where to connect. domain −1: $OMNITWIN_DDS_DOMAIN, else 0. interface "": $OMNITWIN_DDS_INTERFACE,
// else Cyclone's own choice (which honours $CYCLONEDDS_URI). config_file: a Cyclone XML file;
// when set it overrides interface (and the environment's interface).
struct DdsEndpoint {
  int domain = -1;
  std::string interface;
  std::string config_file;
};

inline constexpr int kMaxDdsDomain = 232;  // DDSI default port mapping: 7400 + 250·domain + …

// The endpoint with the environment applied and checked; throws DdsError.
struct ResolvedEndpoint {
  int domain = 0;
  std::string interface;    // "" when Cyclone chooses
  std::string config_file;  // absolute path, or ""
  std::string config;       // the string given to dds_create_domain ("" = Cyclone default)
  std::string describe() const;  // "domain 7 on interface lo", for messages
};
ResolvedEndpoint resolve_endpoint(const DdsEndpoint& ep);

// The Cyclone XML that pins a domain to one network interface (multicast forced on for a
// loopback interface, which Linux does not flag as multicast-capable although it is).
std::string interface_config_xml(const std::string& interface, bool loopback);

// One published topic: the short name `omnitwin echo --topic` accepts, the DDS topic name,
// and the DDS type name.
struct TopicInfo {
  std::string_view short_name;  // state, odom, joint_states, cmd_vel, drives, bus, events, clock
  std::string_view name;        // rt/omnitwin/…, and rt/clock (ROS 2's /clock)
  std::string_view type_name;   // e.g. nav_msgs::msg::dds_::Odometry_
  const dds_topic_descriptor_t* descriptor = nullptr;  // idlc's type descriptor
  std::string_view label() const;  // the name without "rt/omnitwin/" (or "rt/"): platform_state, odom, clock…
};
const std::vector<TopicInfo>& dds_topics();
// A topic by short name, full name or label; nullopt when unknown.
std::optional<TopicInfo> find_topic(std::string_view name);

// Owns one Cyclone entity handle (deleting it deletes its children). Move-only.
class DdsEntity {
 public:
  DdsEntity() = default;
  explicit DdsEntity(dds_entity_t h) : h_(h) {}
  DdsEntity(DdsEntity&& o) noexcept : h_(o.release()) {}
  DdsEntity& operator=(DdsEntity&& o) noexcept;
  DdsEntity(const DdsEntity&) = delete;
  DdsEntity& operator=(const DdsEntity&) = delete;
  ~DdsEntity() { reset(); }
  dds_entity_t get() const { return h_; }
  dds_entity_t release() { dds_entity_t h = h_; h_ = 0; return h; }
  void reset();
 private:
  dds_entity_t h_ = 0;
};

// A Cyclone QoS object.
struct QosDeleter {
  void operator()(dds_qos_t* q) const { dds_delete_qos(q); }
};
using DdsQos = std::unique_ptr<dds_qos_t, QosDeleter>;

// State topics: best-effort, volatile, keep-last `depth`.
DdsQos state_qos(int depth);
// Run events: reliable, transient-local, keep-last `depth` (late joiners get the history).
DdsQos event_qos(int depth);
inline constexpr int kEventHistory = 256;

// A participant on a resolved endpoint. Creates the domain with the endpoint's config, or,
// when this process already has that domain, joins it as it is. On destruction deletes the
// participant, then the domain if no participant is left in it. Throws DdsError.
class DdsParticipant {
 public:
  explicit DdsParticipant(const DdsEndpoint& ep);
  ~DdsParticipant();
  DdsParticipant(const DdsParticipant&) = delete;
  DdsParticipant& operator=(const DdsParticipant&) = delete;
  dds_entity_t get() const { return participant_; }
  const ResolvedEndpoint& endpoint() const { return ep_; }
 private:
  ResolvedEndpoint ep_;
  dds_entity_t participant_ = 0;
};

// Creates the topic on a participant; throws DdsError.
dds_entity_t create_topic(dds_entity_t participant, const TopicInfo& topic);
// "DDS <what> failed: <Cyclone's reason>".
[[noreturn]] void throw_dds(const std::string& what, dds_return_t rc);

}  // namespace omnitwin::twin
