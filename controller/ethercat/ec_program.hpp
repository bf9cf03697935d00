// controller/ethercat — the `omni-master --bus ethercat` program path (and `omni-master
// shell`, `--script`), kept out of controller/programs/omni_master_main.cpp so that the CAN
// program stays as it is; main() only dispatches here.
//
// A thin shell around the protocol core (ec_master) and its drive layer (ec_drive): the
// configuration file (ec_config + the platform section in controller/master_config's
// vocabulary), D's transport (open_transport(spec, Role::master)), and the clock:
//  * --clock sim: lockstep with the twin's sim clock exactly as the CAN path: each Grant
//    carries the twin's cumulative frames on bus 0; the replies are drained until that many
//    arrived, the cycle runs at the grant's time, Done carries our cumulative frames sent and
//    the MasterReport (state, odometry, reference). SIGINT/SIGTERM ends it as the end of a
//    wall-clock run does, in the ticks the twin still grants; End ends it at once.
//  * --clock wall: CLOCK_MONOTONIC absolute deadlines (clock_nanosleep TIMER_ABSTIME),
//    SCHED_FIFO and mlockall when permitted; at the start of each cycle the previous cycle's
//    frame is received. Its end (SIGINT/SIGTERM, --duration, the script's): drives stopped,
//    slaves to INIT, within 100 ms.
// Each cycle: the drive layer reads the image, the platform loop (when `wheels` are
// configured, once every drive is in OP and operation enabled) turns wheel speeds into target
// velocities (CSV, counts/s) or positions (CSP) and reads odometry from position actual, the
// Botnana interpreter's tasks step (shell/script), then the master core sends its frame.
// Exit codes as omni-master: 0 normal end, 2 usage/configuration/transport spec, 3 runtime
// failure (the master failed, the twin vanished, a script error).
#pragma once

#include <string>

namespace omnitwin::controller::ethercat {

struct ProgramOptions {
  std::string iface;          // D's transport spec: raw:IFACE, udp:HOST:PORT, mem:NAME
  std::string config;         // ec_config YAML
  std::string clock = "wall"; // sim | wall
  std::string sim_clock;      // unix:PATH with --clock sim
  double duration = -1;       // wall: seconds, < 0 = until SIGINT/SIGTERM
  bool shell = false;         // interactive Botnana shell (wall clock)
  std::string script;         // Botnana script to run (exit when its tasks end)
  bool print_config = false;  // print what was loaded and exit
  std::string stats;          // write the counters as JSON here at exit ("" = no)
};

// Runs the EtherCAT master program; returns the process exit code. Logs through spdlog.
int run_ethercat_program(const ProgramOptions& o);

}  // namespace omnitwin::controller::ethercat
