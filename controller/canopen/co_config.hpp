// controller/canopen — the CANopen master program's configuration file (YAML), the counterpart
// of controller/ethercat/ec_config for `omni-master --bus canopen`.
//
// It names the EDS of the drives (the same file the emulated nodes are built from, and that
// third-party tools load), the SYNC period (the master's cycle), the node IDs of the four
// wheel drives, the heartbeat times (the nodes' producer time written to their 0x1017, the
// master's own heartbeat and the time after which either side counts the other as lost), how
// the wheels are commanded (CSV: 0x60FF every SYNC in a synchronous RPDO; PV: the same object
// in profile velocity mode, ramped by the drive), the drives' counts per wheel revolution, the
// SDO timeout and the start-up time allowed, and the platform loop (controller/master_config's
// vocabulary, as YAML text or a file name). Errors are thrown as CoConfigError
// "FILE:LINE: KEY: message". Set-up only.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>

#include "controller/config_reader.hpp"

namespace omnitwin::controller::canopen {

using CoConfigError = config::ConfigFileError;

enum class WheelMode : std::uint8_t { csv, pv };

struct CoProgramConfig {
  std::string eds;                        // resolved against the file's folder
  double cycle = 0.001;                   // SYNC period [s]
  // Who produces SYNC: 0 = the master, every tick (tick = cycle); a wheel's node ID = that drive
  // (0x1005 gen bit, 0x1006 = cycle), and the master ticks every `tick` (its control period),
  // its RPDOs taking effect at the drive's next SYNC.
  std::uint8_t sync_producer = 0;
  double tick = 0;                        // the master's tick [s] with a node producing SYNC (0: cycle)
  std::array<std::uint8_t, 4> nodes{1, 2, 3, 4};  // node ID of wheel 1..4
  std::uint8_t master_node_id = 0x7F;     // the master's heartbeat COB-ID 0x700 + this (0: none)
  std::uint16_t master_heartbeat_ms = 50; // the master's heartbeat period (0: none)
  std::uint16_t node_heartbeat_ms = 50;   // written to each node's 0x1017
  std::uint16_t heartbeat_timeout_ms = 150;  // either side counts the other lost after this
  std::uint8_t sync_counter = 0;          // 0x1019 / the SYNC's counter overflow (0: no counter)
  WheelMode mode = WheelMode::csv;
  double wheel_counts_per_rev = 131072;   // position actual counts per wheel revolution
  double sdo_timeout_ms = 100;
  double startup_timeout = 3.0;           // [s] reset → every drive operation enabled
  std::string platform_yaml, platform_file;
  std::string file;
};

CoProgramConfig parse_co_config(std::string_view yaml, const std::string& file, const std::string& base_dir);
CoProgramConfig load_co_config(const std::string& path);
// The master's tick [s]: the SYNC period when it produces SYNC, else `tick`.
double master_tick(const CoProgramConfig& c);
// The configuration as YAML (what omni-master --print-config shows).
std::string dump_co_config(const CoProgramConfig& c);

}  // namespace omnitwin::controller::canopen
