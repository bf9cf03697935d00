// controller layer — the Omni master's configuration file (docs/protocols/omni-master.md).
//
// The master is its own process (DESIGN §2), so it reads its own YAML file instead of the
// twin's scenario: the platform loop's settings, the wheel geometry, the path in the same
// vocabulary as a scenario's path, and the master's bus rules (start-up, node detection,
// feedback watchdog, settle time, the slave controller setting). Loading is all-or-nothing:
// every key is checked (unknown keys, wrong types, out-of-range values) and the first problem
// is thrown as one line "FILE:LINE: KEY: message". The loaded MasterConfig is fixed
// configuration; nothing in it changes while the master runs. The controller does not link
// the twin, so this file has its own small YAML walker rather than the twin's.
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "controller/path.hpp"
#include "controller/platform_loop.hpp"

namespace omnitwin::controller {

// A bad configuration file. what() is one line: "FILE:LINE: KEY: message" (":LINE" left out
// when there is no line, e.g. for a missing file; "KEY: " left out for the whole file).
class MasterConfigError : public std::runtime_error {
 public:
  MasterConfigError(std::string file, int line, std::string key, const std::string& message);
  const std::string& file() const { return file_; }
  int line() const { return line_; }  // 1-based; 0 = no line
  const std::string& key() const { return key_; }

 private:
  std::string file_;
  int line_;
  std::string key_;
};

// One path segment, as written in the file (the scenario's vocabulary, twin/scenario.hpp).
struct SegmentSpec {
  enum class Kind { line, arc, rotate, dwell, square, circle, figure_eight };
  Kind kind = Kind::line;
  double duration = 0;    // [s], > 0 (square: per side)
  double dx = 0, dy = 0;  // line [m]
  double dphi_deg = 0;    // line / arc / rotate heading change [deg]
  double cx = 0, cy = 0;  // arc centre relative to the segment's start [m]
  double sweep_deg = 0;   // arc sweep, ccw positive [deg]
  double side = 0;        // square side [m]
  double radius = 0;      // circle / figure_eight [m]
  bool ccw = true;        // square / circle / figure_eight turning sense
};

// The path: a start pose and segments, each starting where the previous one ended.
struct PathSpec {
  double x = 0, y = 0, phi_deg = 0;  // start pose (world) [m, m, deg]
  std::vector<SegmentSpec> segments;
};

struct MasterConfig {
  // period, kp, ki, feedforward, max_speed, max_yaw_rate and geometry (L, r, counts_per_rev).
  PlatformLoopConfig loop;
  PathSpec path;
  double settle = 2.0;          // [s] after the path ends before the normal stop; < 0: never
  bool wait_for_pc = false;     // stay `waiting` until the PC sends NMT start to the master
  int detect_every = 1;         // node detection every N running ticks; 0 = off
  int detect_misses = 1;        // consecutive missed detection rounds → node missing, >= 1
  int feedback_timeout = 10;    // running ticks without a node's feedback → stop; 0 = off
  double startup_timeout = 1.0; // [s] to find all four slaves after detection began, (0, 3600]
  std::optional<std::uint16_t> slave_kp;  // axis controller setting sent before NMT start
};

// Reads and validates a configuration file. Throws MasterConfigError. Not real-time safe.
MasterConfig load_master_config(const std::string& path);
// The same from YAML text; `file` names it in error messages. Throws MasterConfigError.
MasterConfig parse_master_config(std::string_view yaml, const std::string& file = "<config>");
// A master program's platform section: the file `file` names, else the YAML `yaml` written
// inline in the configuration file `config` (named in errors), else none. Throws
// MasterConfigError. Not real-time safe.
std::optional<MasterConfig> load_platform_section(const std::string& file, const std::string& yaml,
                                                  const std::string& config);
// The configuration as YAML that parse_master_config() reads back to the same values
// (numbers written with round-trip precision). Not real-time safe.
std::string dump_master_config(const MasterConfig& config);

// Checks the values of a configuration built in code (the loader checks each key itself):
// throws MasterConfigError (file "<config>") naming the first bad key. Not real-time safe.
void validate_master_config(const MasterConfig& config);

// The controller::Path the spec describes (degrees → radians). Allocates; set-up only.
Path build_path(const PathSpec& spec);

}  // namespace omnitwin::controller
