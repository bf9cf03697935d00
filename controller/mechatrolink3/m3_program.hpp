// controller/mechatrolink3 — the `omni-master --bus m3` program path, kept out of
// controller/programs/omni_master_main.cpp as the EtherCAT one is; main() only dispatches.
//
// A thin shell around the C1 master core (m3_master: the driver sequence of seed 000 figs.
// 9-11 and the cyclic exchange), one ServoAxis per wheel (fig. 8 start-up, then VELCTRL or
// INTERPOLATE every cycle) and the platform loop, with the configuration file (m3_config),
// the M-III transport (open_transport(spec, Role::master)) and the clock:
//  * --clock sim: exchange-level lockstep (m3_lockstep, docs/protocols/sim-clock.md "Inside a
//    tick"): each Grant is one transmission cycle; every frame is reported with Sent and
//    answered with a Horizon, so T_RSP runs out in simulated time; Done carries the frames
//    sent and the MasterReport (state, odometry, reference).
//  * --clock wall: CLOCK_MONOTONIC; the core's deadlines (cycle starts, T_RSP) are waited for
//    on the transport's descriptor, SCHED_FIFO and mlockall when permitted. Across processes
//    the transport's latency must be in margin_us (a real ASIC answers in microseconds).
// At the cyclic interrupt (INT_OFFSET) the axes read their responses and write their next
// commands; once every servo is on, the platform loop runs every loop period. A servo that
// stops answering (lost_cycles without a fresh response) or leaves operation stops the
// platform for good (every wheel commanded to zero, held where it is); the axis itself
// reconnects when its slave returns (ServoAxis recovery). The end of a run (--duration,
// SIGINT/SIGTERM; in lockstep a signal, in the ticks the twin still grants) takes every servo
// to zero speed, SV_OFF and DISCONNECT (fig. 8's end), waiting at most 100 ms for the answers;
// an End from the twin ends a lockstep run at once. Exit codes as omni-master: 0 normal end, 2 usage,
// configuration or transport spec, 3 runtime failure (the driver failed, the twin vanished).
#pragma once

#include <string>

namespace omnitwin::m3 {

struct ProgramOptions {
  std::string iface;          // M-III transport spec: raw:IFACE, udp:HOST:PORT, mem:NAME
  std::string config;         // m3_config YAML
  std::string clock = "wall"; // sim | wall
  std::string sim_clock;      // unix:PATH with --clock sim
  double duration = -1;       // wall: seconds, < 0 = until SIGINT/SIGTERM
  bool print_config = false;  // print what was loaded and exit
  std::string stats;          // write the counters as JSON here at exit ("" = no)
};

// Runs the M-III master program; returns the process exit code. Logs through spdlog.
int run_m3_program(const ProgramOptions& o);

}  // namespace omnitwin::m3
