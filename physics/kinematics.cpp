// physics layer — kinematics of the four-omniwheel platform; see kinematics.hpp.
#include "physics/kinematics.hpp"

#include <cmath>

namespace omnitwin::physics {

DecouplingMatrix decoupling_matrix(double phi, double L) {
  const double s = std::sin(phi), c = std::cos(phi);
  const double k = 1.0 / std::sqrt(2.0);
  DecouplingMatrix m;
  m << k * (s + c), k * (s - c), -L,
       k * (-s + c), k * (s + c), -L,
       k * (-s - c), k * (-s + c), -L,
       k * (s - c), k * (-s - c), -L;
  return m;
}

InverseMatrix inverse_matrix(double phi, double L) {
  const double s = std::sin(phi), c = std::cos(phi);
  const double k = std::sqrt(2.0) / 4.0;
  const double w = -1.0 / (4.0 * L);
  InverseMatrix m;
  m << k * (s + c), k * (-s + c), k * (-s - c), k * (s - c),
       k * (s - c), k * (s + c), k * (-s + c), k * (-s - c),
       w, w, w, w;
  return m;
}

WheelVector wheel_speeds(const Twist& world_twist, double phi, double L, double r) {
  return decoupling_matrix(phi, L) * world_twist / r;
}

Twist platform_twist(const WheelVector& omega, double phi, double L, double r) {
  return inverse_matrix(phi, L) * (r * omega);
}

}  // namespace omnitwin::physics
