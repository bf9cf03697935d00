// twin layer — the run's state stream: what a run hands its live observers (DDS) each
// control sample, and the run's discrete events.
//
// A StateSample is a fixed-size value (no heap) so that the run loop can copy it into a
// lock-free queue without allocating: observers must never block or slow the simulation
// loop. Units are SI (m, rad, s, N·m); times are the run's simulated nanoseconds. A value
// the twin cannot know (e.g. the platform command of a master in another process) is NaN.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>

namespace omnitwin::twin {

// A drive's (slave node's) state as observers see it; the same codes for every bus.
enum class DriveStateCode : std::uint8_t {
  off = 0,        // unpowered (power-loss fault) or not on the bus
  waiting = 1,    // powered, not started (CAN: before NMT start / after NMT stop)
  running = 2,    // operational: follows commands
  syncing = 3,    // running, holding for the synchronisation frame (CAN sync)
  fault = 4,      // error state (CAN: bus-off)
};
const char* to_string(DriveStateCode c);

struct DriveSample {
  std::uint8_t node = 0;             // bus address (CAN node id; 0 on the direct bus)
  DriveStateCode state = DriveStateCode::running;
  double command_rad_s = 0;          // the speed command the drive holds [rad/s]
  double setpoint_rad_s = 0;         // the velocity loop's output to the motor [rad/s]
  std::int32_t dac_code = 0;         // 12-bit DA code
  std::int64_t encoder_count = 0;    // HCTL-2032 count
  // The same state in the protocol's own words, for live views (static strings, "" where a
  // layer does not exist): the communication layer (EtherCAT AL state, CANopen NMT state,
  // M-III phase, Omni slave state) and the drive layer (CiA 402 state, servo on/off).
  const char* comm_state = "";
  const char* device_state = "";
};

struct BusSample {
  bool has_frames = false;           // false on the direct bus (shared memory, no frames)
  std::uint64_t frames_tx = 0;       // cumulative, as metrics.json bus.*
  std::uint64_t frames_rx = 0;
  std::uint64_t dropouts = 0;
  std::uint64_t errors = 0;
  double load = 0;                   // bus busy fraction over the last control period [0, 1]
  // EtherCAT: the working counter of the process data (logical datagrams) in the last cyclic
  // frame the segment returned, as the master checks it; -1 on buses without one.
  std::int32_t wkc = -1;
};

struct StateSample {
  std::int64_t t_ns = 0;             // simulated time
  std::uint64_t seq = 0;             // control-sample number, from 0
  double x = 0, y = 0, phi = 0;      // platform pose in the world [m, m, rad] (phi unwrapped)
  double vx = 0, vy = 0, wz = 0;     // world twist [m/s, m/s, rad/s]
  double ref_x = 0, ref_y = 0, ref_phi = 0;     // the master's reference pose
  double cmd_vx = 0, cmd_vy = 0, cmd_wz = 0;    // the master's twist command (NaN if unknown)
  std::array<double, 4> wheel_angle{};          // [rad], W1..W4
  std::array<double, 4> wheel_speed{};          // [rad/s]
  std::array<double, 4> wheel_cmd{};            // commanded wheel speed [rad/s]
  std::array<double, 4> wheel_torque{};         // motor torque [N·m]
  std::array<DriveSample, 4> drives{};
  BusSample bus;
  std::uint32_t active_faults = 0;   // scenario faults in force at t_ns
};

// A discrete run event (the same lines as events.log).
enum class RunEventKind : std::uint8_t { start = 0, fault = 1, expectation = 2, end = 3, info = 4 };
const char* to_string(RunEventKind k);

struct RunEvent {
  std::int64_t t_ns = 0;
  RunEventKind kind = RunEventKind::info;
  std::string source;                // "scenario", "master", "bus", "fault", …
  std::string text;
};

// What a live observer is told once, before the first sample.
struct RunInfo {
  std::string scenario;
  std::string bus;                   // "direct", "can", …
  std::string clock;                 // "lockstep" | "realtime"
  std::string run_dir;
  double control_period_s = 0.01;
  double duration_s = 0;
};

inline const char* to_string(DriveStateCode c) {
  switch (c) {
    case DriveStateCode::off: return "off";
    case DriveStateCode::waiting: return "waiting";
    case DriveStateCode::running: return "running";
    case DriveStateCode::syncing: return "syncing";
    case DriveStateCode::fault: return "fault";
  }
  return "?";
}

// The observers' event kind of an events.log line's kind column ("start", "master", "bus"…).
inline RunEventKind run_event_kind(std::string_view log_kind) {
  if (log_kind == "start") return RunEventKind::start;
  if (log_kind == "fault") return RunEventKind::fault;
  if (log_kind == "end" || log_kind == "interrupt" || log_kind == "error") return RunEventKind::end;
  return RunEventKind::info;
}

inline const char* to_string(RunEventKind k) {
  switch (k) {
    case RunEventKind::start: return "start";
    case RunEventKind::fault: return "fault";
    case RunEventKind::expectation: return "expectation";
    case RunEventKind::end: return "end";
    case RunEventKind::info: return "info";
  }
  return "?";
}

}  // namespace omnitwin::twin
