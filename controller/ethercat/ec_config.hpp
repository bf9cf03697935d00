// controller/ethercat — the EtherCAT master's configuration file (YAML), the counterpart of
// controller/master_config for `omni-master --bus ethercat`.
//
// It names the ESI files to load, the cycle, distributed clocks (on/off, SYNC0 shift), the
// segment watch (segment_loss_cycles and segment_loss_ms: silent cycles, and how long at least,
// before leaving OP), how long to wait for any slave to answer (startup_timeout), the start-up SDOs per
// slave (e.g. 0x6060 = 9 for CSV), which (slave, channel) drives each of the
// four wheels, how wheel speeds go out (CSV target velocity or CSP target position) and the
// wheel encoder counts per revolution, and the platform loop. The file is read with yaml-cpp.
// The platform section is kept as YAML text (re-emitted by yaml-cpp; comments are not kept) or
// a file name, in the vocabulary of controller/master_config (period, kp, ki, geometry, path,
// settle …), and is handed to that parser by the program, so the two masters share one
// platform vocabulary. Loading is all-or-nothing: the first problem is thrown as EcConfigError
// "FILE:LINE: KEY: message" (LINE 1-based, from yaml-cpp's marks). Set-up code only.
#pragma once

#include <array>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "controller/config_reader.hpp"
#include "controller/ethercat/ec_master.hpp"

namespace omnitwin::controller::ethercat {

using EcConfigError = config::ConfigFileError;

struct AxisRef {
  int slave = 1;    // 1-based, as in the Botnana word set
  int channel = 1;  // 1-based
  bool operator==(const AxisRef&) const = default;
};

enum class WheelMode : std::uint8_t { csv, csp };

struct EcConfig {
  std::vector<std::string> esi_files;      // resolved against the file's folder
  double cycle = 0.001;                    // [s], > 0
  bool dc = false;
  double sync0_shift_us = 0;               // [µs]
  int expected_slaves = -1;                // -1: whatever answers
  // Consecutive cycles without any WKC (frame lost or untouched) before the master declares
  // the segment lost, leaves OP and stops its drives; 0 = never.
  int segment_loss_cycles = 10;
  int segment_loss_ms = 10;  // …and at least this long (EcMasterConfig::segment_loss_ns)
  double startup_timeout = 10;  // [s] no slave answering the count this long → failed (exit 3)
  // [s] a wheel's slave out of OP this long, once the drives were enabled, stops the platform
  // loop; a shorter outage (a power blip the master recovers) lets the loop pull it back.
  double wheel_loss_timeout = 1.0;
  std::vector<StartupSdo> startup;         // position -1 = every slave
  bool has_wheels = false;                 // `wheels` given: the platform loop runs
  std::array<AxisRef, 4> wheels{};         // wheel i+1 → axis
  WheelMode wheel_mode = WheelMode::csv;
  double wheel_counts_per_rev = 10000;     // position actual counts per wheel revolution, > 0
  // Objects behind the Botnana user PDO words (wpdo1, wpdo2, rpdo1, rpdo2), index 0 = none.
  std::array<std::pair<std::uint16_t, std::uint8_t>, 4> user_pdos{};
  std::string platform_yaml;               // master_config vocabulary ("" = none)
  std::string platform_file;               // or a master_config file (resolved)
  std::string file;                        // where this came from
};

// Throws EcConfigError. Not real-time safe.
EcConfig load_ec_config(const std::string& path);
// `base_dir` resolves relative file names ("" = as given).
EcConfig parse_ec_config(std::string_view yaml, const std::string& file = "<config>", const std::string& base_dir = "");
// Loads the ESI files and fills the core's configuration, with the software limits 0x607D:1/2
// read back at start-up (seed 004's drive-nsl@ / drive-psl@). Throws EcConfigError naming the
// ESI file on a parse error.
EcMasterConfig make_master_config(const EcConfig& c);

}  // namespace omnitwin::controller::ethercat
