// controller/tml — the `omni-master --bus tml` program path (main() only dispatches here): the
// configuration file (tml_config + the platform section), the CAN transport and the clock
// (controller/can_master_loop: lockstep with the twin, or the wall clock) around the TML master
// core (tml_master) and the platform loop, which reads APOS and sets each wheel's CSPD.
// Exit codes as omni-master: 0 normal end, 2 usage/configuration/transport spec, 3 runtime failure.
#pragma once

#include <string>

#include "controller/can_master_loop.hpp"

namespace omnitwin::controller::tml {

using ProgramOptions = controller::CanProgramOptions;  // controller/can_master_loop.hpp

int run_tml_program(const ProgramOptions& o);

}  // namespace omnitwin::controller::tml
