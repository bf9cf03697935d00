// physics layer — the analog amplifier's input stage; see amplifier.hpp.
#include "physics/amplifier.hpp"

#include <algorithm>
#include <cmath>

namespace omnitwin::physics {

double driver_setpoint(const DriverParams& driver, const MotorParams& motor, double volts) {
  // Input dead band around the zero voltage: inside it the amplifier sees 0.
  const double v = volts - driver.zero_volts;
  const double outside = std::max(std::abs(v) - driver.dead_band, 0.0);
  const double w = driver.gain * std::copysign(outside, v);
  return std::clamp(w, -motor.speed_limit, motor.speed_limit);
}

}  // namespace omnitwin::physics
