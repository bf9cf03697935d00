// controller layer — the trapezoidal velocity profile of seed 002 (eq. 4-9 … 4-13).
//
// The master plans x, y and phi each with one of these: accelerate over Ta = T/3, cruise at
// Vmax = D/(T − Ta), decelerate to rest at T (Amax = Vmax/Ta). A value type with the profile's
// fixed numbers only, so a path can hold many and sample them every control tick.
#pragma once

namespace omnitwin::controller {

class Trapezoid {
 public:
  // A zero move lasting 1 s.
  Trapezoid() : Trapezoid(0.0, 1.0) {}
  // Distance D [m or rad] (any sign, may be 0) over duration T > 0 [s]; throws
  // std::invalid_argument for T <= 0 (construction is not on the real-time path).
  Trapezoid(double distance, double duration);

  // Position [m or rad] at t [s], t clamped to [0, T]; position(T) == D exactly. RT-safe.
  double position(double t) const;
  // Velocity [unit/s] at t, clamped to [0, T] (0 at both ends). RT-safe.
  double velocity(double t) const;
  // Acceleration [unit/s²] at t: +Amax, 0, −Amax by phase; 0 outside (0, T). RT-safe.
  double acceleration(double t) const;

  double distance() const { return d_; }     // D
  double duration() const { return t_; }     // T [s]
  double accel_time() const { return ta_; }  // Ta = T/3 [s]
  double vmax() const { return vmax_; }      // D/(T − Ta), signed
  double amax() const { return amax_; }      // Vmax/Ta, signed

 private:
  double d_, t_, ta_, vmax_, amax_;
};

}  // namespace omnitwin::controller
