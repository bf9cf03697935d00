// controller/canopen — the `omni-master --bus canopen` program path, kept out of
// controller/programs/omni_master_main.cpp (main() only dispatches here), as the EtherCAT and
// M-III paths are.
//
// A thin shell around the master core (co_master): the configuration file (co_config + the
// platform section in controller/master_config's vocabulary), the drives' EDS, the CAN
// transport (UDP multicast, SocketCAN, in-process) and the clock:
//  * --clock sim: lockstep with the twin's sim clock exactly as the CAN path: each Grant
//    carries the twin's cumulative frames; they are drained until that many arrived, the tick
//    runs at the grant's time, its frames go out in one batch, Done carries our cumulative
//    frames sent and the MasterReport (state, odometry, reference).
//  * --clock wall: CLOCK_MONOTONIC absolute deadlines, one tick per SYNC period, frames
//    handled as they arrive; SCHED_FIFO where permitted.
// Each tick: the platform loop (once every drive is operation enabled) reads wheel positions
// from TPDO1 and sets target velocities [counts/s] that RPDO1 carries; then the core's tick
// (SYNC, RPDOs, SDO, NMT). Exit codes as omni-master: 0 normal end, 2 usage/configuration/EDS/
// transport spec, 3 runtime failure (start-up failed, the twin vanished).
#pragma once

#include <string>

#include "controller/can_master_loop.hpp"

namespace omnitwin::controller::canopen {

using ProgramOptions = controller::CanProgramOptions;  // controller/can_master_loop.hpp

// Runs the CANopen master program; returns the process exit code. Logs through spdlog.
int run_canopen_program(const ProgramOptions& o);

}  // namespace omnitwin::controller::canopen
