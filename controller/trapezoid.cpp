// controller layer — the trapezoidal velocity profile of seed 002; see trapezoid.hpp.
#include "controller/trapezoid.hpp"

#include <stdexcept>

namespace omnitwin::controller {

Trapezoid::Trapezoid(double distance, double duration)
    : d_(distance), t_(duration) {
  if (!(duration > 0.0)) throw std::invalid_argument("Trapezoid: duration must be > 0");
  // Eq. 4-9 … 4-11: Ta = T/3, Vmax = D/(T − Ta), Amax = Vmax/Ta.
  ta_ = t_ / 3.0;
  vmax_ = d_ / (t_ - ta_);
  amax_ = vmax_ / ta_;
}

double Trapezoid::position(double t) const {
  // Ramp up, cruise, ramp down (eq. 4-12/4-13 integrated); the last phase counts back from D
  // so that the end lands on D exactly.
  if (t <= 0.0) return 0.0;
  if (t >= t_) return d_;
  if (t < ta_) return 0.5 * amax_ * t * t;
  if (t <= t_ - ta_) return 0.5 * vmax_ * ta_ + vmax_ * (t - ta_);
  const double left = t_ - t;
  return d_ - 0.5 * amax_ * left * left;
}

double Trapezoid::velocity(double t) const {
  // Eq. 4-12: V(t) rises linearly to Vmax, holds, falls linearly to 0.
  if (t <= 0.0 || t >= t_) return 0.0;
  if (t < ta_) return amax_ * t;
  if (t <= t_ - ta_) return vmax_;
  return amax_ * (t_ - t);
}

double Trapezoid::acceleration(double t) const {
  if (t <= 0.0 || t >= t_) return 0.0;
  if (t < ta_) return amax_;
  if (t <= t_ - ta_) return 0.0;
  return -amax_;
}

}  // namespace omnitwin::controller
