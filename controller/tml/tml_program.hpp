// controller/tml — the `omni-master --bus tml` program path (main() only dispatches here): the
// configuration file (tml_config + the platform section), the CAN transport and the clock
// (controller/can_master_loop: lockstep with the twin, or the wall clock) around the TML master
// core (tml_master) and the platform loop, which reads APOS and sets each wheel's CSPD.
// Exit codes as omni-master: 0 normal end, 2 usage/configuration/transport spec, 3 runtime failure.
#pragma once

#include <string>

namespace omnitwin::controller::tml {

struct ProgramOptions {
  std::string iface;          // CAN transport spec: udp:GROUP:PORT, socketcan:IFACE, mem:NAME
  std::string config;         // tml_config YAML
  std::string clock = "wall"; // sim | wall
  std::string sim_clock;      // unix:PATH with --clock sim
  double duration = -1;       // wall: seconds, < 0 = until SIGINT/SIGTERM
  bool print_config = false;
  std::string stats;          // write the counters as JSON here at exit ("" = no)
};

int run_tml_program(const ProgramOptions& o);

}  // namespace omnitwin::controller::tml
