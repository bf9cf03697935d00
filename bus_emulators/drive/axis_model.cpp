// bus_emulators/drive — 1-DOF motor + load (see axis_model.hpp).
#include "bus_emulators/drive/axis_model.hpp"

#include <algorithm>
#include <cmath>

namespace omnitwin::drive {

AxisModel::AxisModel(const AxisModelConfig& config, double position_rad)
    : cfg_(config), pos_(position_rad) {}

void AxisModel::step(const Command& cmd, double dt_s) noexcept {
  if (dt_s <= 0) return;
  const int n = std::max(1, static_cast<int>(std::ceil(dt_s / cfg_.substep_s - 1e-9)));
  const double h = dt_s / n;
  const double j = std::max(cfg_.inertia_kg_m2, 1e-9);
  double limit = cfg_.torque_limit_nm;
  if (cmd.torque_limit_nm > 0) limit = std::min(limit, cmd.torque_limit_nm);
  for (int i = 0; i < n; ++i) {
    if (cmd.brake_engaged) {  // the brake holds the shaft
      vel_ = 0;
      torque_ = 0;
      continue;
    }
    double tau = 0;
    if (cmd.power) {
      if (cmd.torque_mode) {
        tau = cmd.torque_nm;
      } else {
        const double fric_dir = std::fabs(vel_) > 1e-9 ? (vel_ > 0 ? 1.0 : -1.0)
                                : (cmd.velocity_rad_s > 0 ? 1.0 : (cmd.velocity_rad_s < 0 ? -1.0 : 0.0));
        const double tau_c = std::max(cfg_.servo_time_constant_s, h);
        tau = j * (cmd.velocity_rad_s - vel_) / tau_c + cfg_.viscous_nm_s * vel_ +
              cfg_.coulomb_nm * fric_dir;
      }
      tau = std::clamp(tau, -limit, limit);
    }
    torque_ = tau;
    // Friction: viscous always, Coulomb opposing motion; stiction holds a slow axis.
    const double drive = tau - cfg_.viscous_nm_s * vel_;
    if (std::fabs(vel_) < 1e-9 && std::fabs(drive) <= cfg_.coulomb_nm) {
      vel_ = 0;
      continue;
    }
    const double dir = std::fabs(vel_) > 1e-9 ? (vel_ > 0 ? 1.0 : -1.0) : (drive > 0 ? 1.0 : -1.0);
    const double acc = (drive - cfg_.coulomb_nm * dir) / j;
    double v_new = vel_ + acc * h;
    if ((vel_ > 0 && v_new < 0) || (vel_ < 0 && v_new > 0)) {
      // Friction cannot reverse the motion: stop unless the drive torque overcomes it.
      if (std::fabs(drive) <= cfg_.coulomb_nm) v_new = 0;
    }
    pos_ += 0.5 * (vel_ + v_new) * h;
    vel_ = v_new;
  }
}

}  // namespace omnitwin::drive
