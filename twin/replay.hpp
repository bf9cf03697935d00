// twin layer — `omnitwin replay SCENARIO.yaml RUN_DIR`: physics alone, driven by a recorded
// run's wheel set-points.
//
// Builds the platform exactly as the run did (RUN_DIR/platform.xml with the scenario's
// parameters, its start pose), then feeds each control sample's recorded set-points
// (trajectory.csv `w1_setpoint_rad_s` … `w4_setpoint_rad_s`) to the wheel motors and steps
// MuJoCo to the next sample: no master, bus, scheduler or records. It prints the simulated
// and wall time and the real-time factor: the physics floor under any bus's figure
// (scripts/bench-cli). It also prints how far the replayed pose ends from the recorded one:
// near zero for bus direct; for a bus whose devices change set-points between samples the
// replay only approximates. The run's own run.json says what it was made with: its
// overrides (`--set`) and start pose apply on top of SCENARIO, and a SCENARIO of another name
// is refused. It ends at the last sample's time. Exit 0; 2 for a missing file or column, a
// trajectory without samples or with a torn row (t not finite or not increasing), another
// scenario or a bad one; 3 when `interrupt` is set (Ctrl-C, SIGTERM).
// Not real-time code.
#pragma once

#include <atomic>
#include <string>
#include <vector>

#include "twin/scenario.hpp"

namespace omnitwin::twin {

int cmd_replay(const std::string& scenario, const std::string& run_dir, const std::vector<Override>& overrides,
               const std::atomic<bool>* interrupt = nullptr);

}  // namespace omnitwin::twin
