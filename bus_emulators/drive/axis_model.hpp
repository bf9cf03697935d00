// bus_emulators/drive — a 1-DOF motor + load for tests, homing runs and benches without
// MuJoCo: inertia, viscous and Coulomb friction (with stiction), a torque limit and a holding
// brake, driven by the drive's Command. In velocity mode the actuator is a first-order
// velocity servo (the torque that would bring the velocity to the set-point with time
// constant servo_time_constant_s, plus friction compensation, clamped to the torque limits) —
// the same kind of actuator as the twin's MuJoCo wheel velocity servos; in torque mode the
// commanded torque is applied. Everything is on the load shaft [rad], [rad/s], [Nm].
// Pure computation; step() is RT-safe (no allocation, no throw).
#pragma once

#include "bus_emulators/drive/cia402_drive.hpp"

namespace omnitwin::drive {

struct AxisModelConfig {
  double inertia_kg_m2 = 2e-3;        // motor + load, reflected to the load shaft
  double viscous_nm_s = 1e-3;         // viscous friction [Nm per rad/s]
  double coulomb_nm = 0.02;           // Coulomb (and static) friction [Nm]
  double torque_limit_nm = 10;        // actuator limit [Nm]
  double servo_time_constant_s = 0.002;  // velocity servo (velocity mode)
  double substep_s = 1e-4;            // integration step
};

class AxisModel {
 public:
  explicit AxisModel(const AxisModelConfig& config = {}, double position_rad = 0);
  // Integrates the axis over dt_s [s] under `cmd` (brake engaged: held at standstill; no
  // power: no actuator torque).
  void step(const Command& cmd, double dt_s) noexcept;
  Feedback feedback() const noexcept { return {pos_, vel_, torque_}; }
  double position_rad() const noexcept { return pos_; }
  double velocity_rad_s() const noexcept { return vel_; }
  double applied_torque_nm() const noexcept { return torque_; }
  void set_position(double rad) noexcept { pos_ = rad; vel_ = 0; }

 private:
  AxisModelConfig cfg_;
  double pos_ = 0, vel_ = 0, torque_ = 0;
};

}  // namespace omnitwin::drive
