// twin layer — a scenario: everything one run needs, loaded and validated up front.
//
// A scenario file (YAML, models/scenarios/*.yaml) names the platform parameter file and
// overrides, the bus, the controller settings, the path, faults, the run length and the
// expectations. Loading is all-or-nothing: every key is checked (unknown keys, wrong types,
// out-of-range values) before anything is run or written, and the first problem is
// reported as a ScenarioError naming the file, line and key. The loaded Scenario is fixed
// configuration; nothing in it changes while a run steps.
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "physics/platform_params.hpp"

namespace omnitwin::twin {

// A bad scenario (or parameter file, or --set override). what() is one line:
// "FILE:LINE: KEY: MESSAGE" (LINE omitted when unknown, e.g. for a missing file).
class ScenarioError : public std::runtime_error {
 public:
  ScenarioError(std::string file, int line, std::string key, const std::string& message);
  const std::string& file() const { return file_; }
  int line() const { return line_; }  // 1-based; 0 = no line
  const std::string& key() const { return key_; }

 private:
  std::string file_;
  int line_;
  std::string key_;
};

// One piece of the reference path, in world coordinates. Each segment starts where the
// previous one ended (pose and time) and runs the trapezoidal profile of seed 002
// (eq. 4-9 … 4-13) over its own duration unless stated otherwise.
struct PathSegment {
  enum class Kind {
    line,          // straight move by (dx, dy) and turn by dphi, simultaneously
    arc,           // around `center` (relative to the segment's start) by sweep_deg
    rotate,        // turn in place by dphi
    dwell,         // hold the pose
    square,        // 4 lines of `side`, turning left (ccw) or right; duration per side
    circle,        // full circle of `radius`, centre to the left (ccw) or right
    figure_eight,  // two tangent circles of `radius`, one trapezoid over the whole length
  };
  Kind kind = Kind::line;
  double duration = 0;    // [s] (square: per side)
  double dx = 0, dy = 0;  // line [m]
  double dphi_deg = 0;    // line/rotate/arc heading change [deg]
  double cx = 0, cy = 0;  // arc centre relative to the segment start [m]
  double sweep_deg = 0;   // arc sweep, ccw positive [deg]
  double side = 0;        // square [m]
  double radius = 0;      // circle, figure_eight [m]
  bool ccw = true;        // square/circle/figure_eight turning sense (first loop)
  int line = 0;           // line in the scenario file (for messages)
};

struct PathSpec {
  double x0 = 0, y0 = 0, phi0_deg = 0;  // start pose (world) [m, m, deg]
  std::vector<PathSegment> segments;
};

// The platform loop of the master (seed 002, fig. 4-13).
struct ControllerSpec {
  double period = 0.010;                   // master sample period [s]
  double kp[3] = {6.0, 6.0, 6.0};          // PI on x, y [1/s], phi [1/s]
  double ki[3] = {6.0, 6.0, 6.0};          // [1/s²]
  bool feedforward = false;                // add the planned velocity to the PI output
  double max_speed = 0.5;                  // |platform speed command| limit [m/s]
  double max_yaw_rate = 2.0;               // [rad/s]
};

enum class BusKind { direct, can, canopen, ethercat, m3, tml };
enum class ClockMode { lockstep, realtime };

struct BusSpec {
  BusKind kind = BusKind::direct;
};

// A scripted fault. Issue 2 knows physics faults; bus faults arrive with the buses.
struct FaultSpec {
  enum class Kind { wheel_slip };
  Kind kind = Kind::wheel_slip;
  double at = 0;              // start [s]
  double duration = 0;        // [s]; 0 = until the end
  int wheel = 0;              // 0-based wheel index (scenario files say 1..4)
  double friction_scale = 0;  // wheel_slip: multiplies the wheel's floor friction
  int line = 0;
};

// A bound on one metric of metrics.json, addressed by its dotted path
// (e.g. "platform.final_error_cm", "axes.0.iae_velocity_pulse").
struct Expectation {
  std::string metric;
  std::optional<double> min, max;
  int line = 0;
};

struct Scenario {
  std::string name;            // default: the file's stem
  std::string description;
  std::string file;            // the scenario file as given
  physics::PlatformParams platform;
  BusSpec bus;
  ClockMode clock = ClockMode::lockstep;
  ControllerSpec controller;
  PathSpec path;
  double settle = 2.0;         // time after the path ends before the run stops [s]
  double duration = 0;         // total simulated time [s] (path length + settle if absent)
  std::vector<FaultSpec> faults;
  std::vector<Expectation> expectations;
};

// "key=value" overrides from the command line, applied to the YAML tree before
// validation. Keys are dotted scenario paths (e.g. controller.period=0.005,
// platform.geometry.L=0.3, bus=direct).
struct Override {
  std::string key;
  std::string value;
};

// Loads, merges (parameter file ← scenario platform section ← overrides) and validates.
// Throws ScenarioError on any problem. Not real-time safe (file I/O).
Scenario load_scenario(const std::string& path, const std::vector<Override>& overrides = {});

// Parses "key=value" (as given to --set). Throws ScenarioError naming "--set".
Override parse_override(const std::string& text);

const char* to_string(BusKind b);
const char* to_string(ClockMode c);

}  // namespace omnitwin::twin
