// controller/mechatrolink3 — the C1 master program's configuration file (YAML), the
// counterpart of controller/ethercat/ec_config for `omni-master --bus m3`.
//
// It names the transmission cycle, the retry slots, the slaves in wheel order (station
// address, cyclic data length, the response time the master allows for), the margin added to
// every T_RSP (the transport's latency in a realtime run across processes), the time the
// application needs after INT_OFFSET, how wheel speeds go out (VELCTRL or INTERPOLATE), the
// servos' reference units per wheel revolution, servo parameters written at start-up
// (SVPRM_WR) and the platform loop (controller/master_config's vocabulary, as YAML text or a
// file name). Errors are thrown as M3ConfigError "FILE:LINE: KEY: message". Set-up only.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "controller/config_reader.hpp"
#include "controller/mechatrolink3/m3_master.hpp"

namespace omnitwin::m3 {

using M3ConfigError = controller::config::ConfigFileError;

enum class WheelCommand : std::uint8_t { velctrl, interpolate };

struct M3ProgramConfig {
  double cycle = 0.001;                 // transmission cycle [s]
  int retry_slots = 1;                  // 0..4
  std::array<std::uint8_t, 4> wheels{0x03, 0x04, 0x05, 0x06};  // station address of wheel 1..4
  // Servo axes beside the wheels, at the addresses after the highest wheel's; started as the
  // wheels are and held in VELCTRL at zero speed (a full line: up to 62 stations in all).
  int extra_axes = 0;
  std::size_t data_bytes = 32;          // 32 or 48 (subcommands); 64 when event-driven
  // Event-driven communication instead of cyclic: no SYNC, the servos stay in phase 2, and
  // the program asks for one exchange per axis every `cycle` (its tick), each answered within
  // the servo's T_RSP (at most 50 ms) or retried by the driver; lost_cycles counts these ticks.
  // VELCTRL only (INTERPOLATE needs phase 3).
  bool event_driven = false;
  double response_us = 2.0;             // each slave's response time allowed for [µs]
  double margin_us = 1.0;               // added to every T_RSP [µs]
  double software_us = 100.0;           // the application's time after INT_OFFSET [µs]
  double detect_timeout_ms = 0.1;       // per station, detection and delay measurement [ms]
  double startup_timeout = 3.0;         // [s] the servos have to reach SV_ON from the start
  int lost_cycles = 20;                 // cycles without a fresh response: the axis is lost
  WheelCommand command = WheelCommand::velctrl;
  double wheel_counts_per_rev = 131072; // the servos' reference units per wheel revolution
  std::vector<std::pair<std::uint16_t, std::int32_t>> params;  // SVPRM_WR at start-up
  std::string platform_yaml, platform_file;  // the platform loop ("" both: none)
  std::string file;
};

M3ProgramConfig parse_m3_config(std::string_view yaml, const std::string& file, const std::string& base_dir);
M3ProgramConfig load_m3_config(const std::string& path);
// Every station's address: the four wheels, then the extra axes.
std::vector<std::uint8_t> station_addresses(const M3ProgramConfig& c);
// The C1 master core's configuration (cycle and T_RSP inputs in ns).
MasterConfig make_master_config(const M3ProgramConfig& c);
// The configuration as YAML (what omni-master --print-config shows).
std::string dump_m3_config(const M3ProgramConfig& c);

}  // namespace omnitwin::m3
