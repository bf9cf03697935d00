// twin/dds — the mapping from the twin's StateSample and RunEvent to the DDS messages
// (idlc-generated C structs, see idl/*.idl and docs/protocols/dds.md). Kept apart from the
// publisher so that tests and the echo use the same conventions: ROS frames ("world" fixed,
// "base_link" on the platform), the twist in the child frame, yaw-only quaternions.
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "omnitwin_msgs.h"
#include "ros2_msgs.h"
#include "twin/run_state.hpp"

namespace omnitwin::twin::ddsmsg {

inline constexpr const char* kWorldFrame = "world";
inline constexpr const char* kBaseFrame = "base_link";

// builtin_interfaces/Time from simulated nanoseconds (floor division: nanosec in [0, 1e9)).
builtin_interfaces_msg_dds__Time_ to_time(std::int64_t t_ns);
std::int64_t to_ns(const builtin_interfaces_msg_dds__Time_& t);

// The rotation by phi about z [rad] as a unit quaternion (x, y, z, w).
geometry_msgs_msg_dds__Quaternion_ yaw_quaternion(double phi);
// A world-frame planar vector expressed in a frame rotated by phi: (vx, vy) → body.
std::array<double, 2> world_to_body(double vx, double vy, double phi);

// Every state message of one sample. Strings and sequences point into this object or at
// static text, so filling never allocates; the object must outlive the writes.
struct StateMessages {
  omnitwin_msg_dds__PlatformState_ state{};
  nav_msgs_msg_dds__Odometry_ odom{};
  sensor_msgs_msg_dds__JointState_ joints{};
  geometry_msgs_msg_dds__Twist_ cmd_vel{};
  bool has_cmd_vel = false;  // false when the master's command is unknown (NaN)
  omnitwin_msg_dds__DriveStates_ drives{};
  omnitwin_msg_dds__BusStatistics_ bus{};
  rosgraph_msgs_msg_dds__Clock_ clock{};  // /clock: the sample's simulated time

  StateMessages();
  StateMessages(const StateMessages&) = delete;  // holds pointers into itself
  StateMessages& operator=(const StateMessages&) = delete;
  // Fills every message from s; bus_name is kept by pointer (must outlive the writes).
  void fill(const StateSample& s, const std::string& bus_name);

 private:
  std::array<char*, 4> joint_names_{};
  std::array<double, 4> position_{}, velocity_{}, effort_{};
};

// A RunEvent_ that points into `e` and `scenario` (valid while they live).
omnitwin_msg_dds__RunEvent_ to_message(const RunEvent& e, const std::string& scenario);

}  // namespace omnitwin::twin::ddsmsg
