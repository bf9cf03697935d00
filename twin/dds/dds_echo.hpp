// twin/dds — `omnitwin echo`: a DDS listener for the twin's topics that prints one line per
// sample, as human-readable text or as JSON lines (one object per sample, for scripts and
// tests). It uses the same connection rules as the publisher (dds_common.hpp) and the
// subscriber side of the same QoS, so what it receives is what a ROS 2 node would.
#pragma once

#include <atomic>
#include <cstdint>
#include <ostream>
#include <string>

#include "twin/dds/dds_common.hpp"

namespace omnitwin::twin {

struct EchoOptions {
  int domain = -1;            // −1: $OMNITWIN_DDS_DOMAIN, else 0
  std::string interface;      // "": $OMNITWIN_DDS_INTERFACE, else Cyclone's default
  std::string config_file;    // a Cyclone DDS XML file; overrides interface
  // "all" (or "") for every topic, or one: a short name (state, odom, joint_states, cmd_vel,
  // drives, bus, events, clock), a full topic name (rt/omnitwin/odom) or its last part
  // (platform_state).
  std::string topic = "all";
  std::uint64_t count = 0;    // exit after this many samples (all topics together); 0 = no limit
  double timeout_s = 0;       // > 0: give up after this long without a sample [s]; 0 = wait forever
  bool json = false;          // JSON lines instead of text
};

// Exit codes of run_echo.
inline constexpr int kEchoOk = 0;       // count reached; or *stop set; or, with count 0, the
                                        // timeout ended a stream that delivered ≥ 1 sample
inline constexpr int kEchoTimeout = 1;  // timeout_s passed with no sample, or before count

// Subscribes and prints one line per sample to `out` (flushed per line) until count samples,
// the timeout, or *stop (checked every 50 ms; may be null). Text lines read
// "<topic> key=value …"; JSON lines are objects whose first member is "topic" (the topic name
// without "rt/omnitwin/"), then the message's fields (docs/protocols/dds.md). Throws
// std::invalid_argument for an unknown topic and DdsError for a set-up failure. Blocking.
int run_echo(const EchoOptions& options, std::ostream& out, const std::atomic<bool>* stop);

}  // namespace omnitwin::twin
