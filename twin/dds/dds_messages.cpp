// twin/dds — StateSample/RunEvent → DDS message mapping (see dds_messages.hpp).
#include "twin/dds/dds_messages.hpp"

#include <cmath>

namespace omnitwin::twin::ddsmsg {
namespace {

constexpr std::int64_t kNsPerS = 1'000'000'000;
// Static text the messages point at; the C structs hold char*, writes only read them.
char kWheel1[] = "wheel1", kWheel2[] = "wheel2", kWheel3[] = "wheel3", kWheel4[] = "wheel4";
char kEmpty[] = "";

char* text(const char* s) { return const_cast<char*>(s); }

template <class Seq, class T>
void point_sequence(Seq& seq, T* data, std::uint32_t n) {
  seq._buffer = data;
  seq._length = n;
  seq._maximum = n;
  seq._release = false;
}

void fill_odometry(nav_msgs_msg_dds__Odometry_& o, const StateSample& s) {
  o.header.stamp = to_time(s.t_ns);
  o.header.frame_id = text(kWorldFrame);
  o.child_frame_id = text(kBaseFrame);
  o.pose.pose.position = {s.x, s.y, 0.0};
  o.pose.pose.orientation = yaw_quaternion(s.phi);
  const auto body = world_to_body(s.vx, s.vy, s.phi);
  o.twist.twist.linear = {body[0], body[1], 0.0};
  o.twist.twist.angular = {0.0, 0.0, s.wz};
}

void fill_platform_state(omnitwin_msg_dds__PlatformState_& p, const StateSample& s) {
  p.t_ns = s.t_ns;
  p.seq = s.seq;
  p.x = s.x, p.y = s.y, p.phi = s.phi;
  p.vx = s.vx, p.vy = s.vy, p.wz = s.wz;
  p.ref_x = s.ref_x, p.ref_y = s.ref_y, p.ref_phi = s.ref_phi;
  p.cmd_vx = s.cmd_vx, p.cmd_vy = s.cmd_vy, p.cmd_wz = s.cmd_wz;
  for (std::size_t i = 0; i < 4; ++i) {
    p.wheel_angle[i] = s.wheel_angle[i];
    p.wheel_speed[i] = s.wheel_speed[i];
    p.wheel_cmd[i] = s.wheel_cmd[i];
    p.wheel_torque[i] = s.wheel_torque[i];
  }
  p.active_faults = s.active_faults;
}

void fill_drives(omnitwin_msg_dds__DriveStates_& m, const StateSample& s) {
  m.t_ns = s.t_ns;
  m.seq = s.seq;
  for (std::size_t i = 0; i < 4; ++i) {
    const DriveSample& d = s.drives[i];
    omnitwin_msg_dds__DriveState_& o = m.drives[i];
    o.node = d.node;
    o.state = static_cast<std::uint8_t>(d.state);
    o.state_name = text(to_string(d.state));
    o.command_rad_s = d.command_rad_s;
    o.setpoint_rad_s = d.setpoint_rad_s;
    o.dac_code = d.dac_code;
    o.encoder_count = d.encoder_count;
  }
}

void fill_bus(omnitwin_msg_dds__BusStatistics_& b, const StateSample& s, const std::string& bus_name) {
  b.t_ns = s.t_ns;
  b.seq = s.seq;
  b.bus = text(bus_name.c_str());
  b.has_frames = s.bus.has_frames;
  b.frames_tx = s.bus.frames_tx;
  b.frames_rx = s.bus.frames_rx;
  b.dropouts = s.bus.dropouts;
  b.errors = s.bus.errors;
  b.load = s.bus.load;
}

}  // namespace

builtin_interfaces_msg_dds__Time_ to_time(std::int64_t t_ns) {
  std::int64_t sec = t_ns / kNsPerS, ns = t_ns % kNsPerS;
  if (ns < 0) ns += kNsPerS, --sec;
  return {static_cast<std::int32_t>(sec), static_cast<std::uint32_t>(ns)};
}

std::int64_t to_ns(const builtin_interfaces_msg_dds__Time_& t) {
  return static_cast<std::int64_t>(t.sec) * kNsPerS + t.nanosec;
}

geometry_msgs_msg_dds__Quaternion_ yaw_quaternion(double phi) {
  return {0.0, 0.0, std::sin(phi / 2), std::cos(phi / 2)};
}

std::array<double, 2> world_to_body(double vx, double vy, double phi) {
  const double c = std::cos(phi), s = std::sin(phi);
  return {c * vx + s * vy, -s * vx + c * vy};
}

StateMessages::StateMessages() {
  joint_names_ = {kWheel1, kWheel2, kWheel3, kWheel4};
  joints.header.frame_id = kEmpty;
  point_sequence(joints.name, joint_names_.data(), 4);
  point_sequence(joints.position, position_.data(), 4);
  point_sequence(joints.velocity, velocity_.data(), 4);
  point_sequence(joints.effort, effort_.data(), 4);
  bus.bus = kEmpty;
}

void StateMessages::fill(const StateSample& s, const std::string& bus_name) {
  fill_platform_state(state, s);
  fill_odometry(odom, s);
  joints.header.stamp = to_time(s.t_ns);
  position_ = s.wheel_angle;
  velocity_ = s.wheel_speed;
  effort_ = s.wheel_torque;
  has_cmd_vel = !(std::isnan(s.cmd_vx) || std::isnan(s.cmd_vy) || std::isnan(s.cmd_wz));
  const auto body = world_to_body(s.cmd_vx, s.cmd_vy, s.phi);
  cmd_vel.linear = {body[0], body[1], 0.0};
  cmd_vel.angular = {0.0, 0.0, s.cmd_wz};
  fill_drives(drives, s);
  fill_bus(bus, s, bus_name);
  clock.clock = to_time(s.t_ns);
}

omnitwin_msg_dds__RunEvent_ to_message(const RunEvent& e, const std::string& scenario) {
  omnitwin_msg_dds__RunEvent_ m{};
  m.t_ns = e.t_ns;
  m.kind = static_cast<std::uint8_t>(e.kind);
  m.kind_name = text(to_string(e.kind));
  m.source = text(e.source.c_str());
  m.text = text(e.text.c_str());
  m.scenario = text(scenario.c_str());
  return m;
}

}  // namespace omnitwin::twin::ddsmsg
