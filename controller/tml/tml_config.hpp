// controller/tml — the TML master program's configuration file (YAML) for `omni-master --bus
// tml`: the CAN protocol (TMLCAN, 29-bit, or TechCAN, 11-bit), the master's tick, the wheels'
// axis IDs and the host's, the drives' IU time base, the wheels' counts per revolution, the
// acceleration every speed change uses, how many ticks without an answer count as a lost axis,
// the start-up time and the platform loop (controller/master_config's vocabulary). Errors are
// thrown as TmlConfigError "FILE:LINE: KEY: message". Set-up only.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>

#include "controller/config_reader.hpp"

namespace omnitwin::controller::tml {

using TmlConfigError = config::ConfigFileError;

struct TmlProgramConfig {
  bool techcan = false;                   // protocol: tmlcan (false) or techcan
  double cycle = 0.002;                   // the master's tick [s]
  std::array<std::uint8_t, 4> axes{1, 2, 3, 4};  // axis ID of wheel 1..4
  std::uint8_t host_axis = 120;           // the master's axis ID (TechCAN: 1..31)
  double sample_period = 0.001;           // the drives' IU time base [s]
  double wheel_counts_per_rev = 131072;   // APOS counts per wheel revolution
  double acceleration = 2'000'000;        // CACC for every speed change [counts/s²]
  int lost_ticks = 10;                    // ticks without an APOS answer: the axis is lost
  double startup_timeout = 2.0;           // [s] from the first tick to every axis on
  std::string platform_yaml, platform_file;
  std::string file;
};

TmlProgramConfig parse_tml_config(std::string_view yaml, const std::string& file, const std::string& base_dir);
TmlProgramConfig load_tml_config(const std::string& path);
std::string dump_tml_config(const TmlProgramConfig& c);

}  // namespace omnitwin::controller::tml
