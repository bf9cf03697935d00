// physics layer — the analog velocity amplifier's input stage (seed 002 §4-3, DESIGN §5).
//
// The line between the emulated node and physics runs at the DA's output pin: the node's
// firmware (counter, velocity PI, DA: physics/drive_chain.hpp, used by bus_emulators/omni/)
// ends in a voltage, and everything from the amplifier's input on is physics. This is the
// first stage of that physics, a pure function so that it can be tested on its own;
// PlatformSim::set_wheel_amplifier_input applies it, then the amplifier's own gain error and
// speed limit, and the MuJoCo velocity servo is the amplifier's loop and the motor.
#pragma once

#include "physics/platform_params.hpp"

namespace omnitwin::physics {

// Analog velocity amplifier, input stage: speed setpoint [rad/s] = gain·(V − zero_volts) with
// the input dead band taken out (|V − zero_volts| <= dead_band gives 0, beyond it the band is
// subtracted, so the curve is continuous and odd about zero_volts), clamped to
// ±motor.speed_limit. `volts` is the input voltage [V]. Real-time safe.
double driver_setpoint(const DriverParams& driver, const MotorParams& motor, double volts);

}  // namespace omnitwin::physics
