// bus_emulators/drive — profile generators of the CiA 402 profile modes: an online
// trapezoidal position profile (PP, homing moves, stops), the PP set-point handshake and
// buffer, and the velocity (PV) and torque (TQ) ramps. Pure computation in double precision on
// the drive's internal position units [counts], [counts/s], [counts/s²]; no I/O, no clock:
// each call advances one drive period dt [s]. RT-safe: no allocation, no throw.
#pragma once

#include <cstdint>

namespace omnitwin::drive {

// Online trapezoid: from the current (pos, vel) toward a target with velocity limit vmax,
// acceleration acc and deceleration dec (> 0). Re-planned every period, so a changed target
// (change immediately) starts from the current state; a target closer than the braking
// distance is overshot and approached back, as a real trapezoid does. `end_vel` >= 0 is the
// speed with which to pass the target (change on set-point), 0 = stop exactly on it.
struct Trapezoid {
  double pos = 0;     // [counts]
  double vel = 0;     // [counts/s]
  bool done = true;   // at the target (with end_vel 0: standing on it)

  void reset(double p, double v = 0) noexcept { pos = p; vel = v; done = v == 0; }
  // One period; returns done.
  bool step(double target, double vmax, double acc, double dec, double dt, double end_vel = 0) noexcept;
  // One period of braking to standstill at dec; returns true once stopped.
  bool stop(double dec, double dt) noexcept;
};

// PV: the velocity one period later on the way from `current` to `target`: |v| grows at acc,
// shrinks at dec (a sign change shrinks to 0 first).
double ramp_velocity(double current, double target, double acc, double dec, double dt) noexcept;
// TQ: the torque one period later on the way to `target` at `slope` [units/s] (0 = step).
double ramp_torque(double current, double target, double slope, double dt) noexcept;

// PP: the set-point handshake (controlword bit 4 new set-point → statusword bit 12
// set-point acknowledge), change immediately (bit 5), relative (bit 6: relative to the last
// accepted target), change on set-point (bit 9: pass the current target at the next one's
// speed instead of stopping), a one-deep set-point buffer, halt (bit 8).
// Set-point states: idle (no move), moving (one target), moving+buffered (buffer full: a new
// set-point is not taken and the acknowledge stays set until the buffer empties).
struct PpInput {
  std::uint16_t controlword = 0;
  double target = 0;                     // 0x607A after limits/polarity [counts]
  double vmax = 0, acc = 0, dec = 0;      // profile velocity, acceleration, deceleration
  double halt_dec = 0;                   // deceleration for halt per 0x605D
  bool limits = false;                   // software position limits active
  double min_pos = 0, max_pos = 0;       // 0x607D in the same units as target
};
struct PpOutput {
  double demand_pos = 0, demand_vel = 0;
  bool set_point_ack = false;
  bool at_target = false;     // generator standing on the final target, nothing buffered
  bool halted = false;        // halt active and stopped
  bool limited = false;       // the active target was clipped to the software limits
};
class ProfilePosition {
 public:
  void reset(double pos) noexcept;          // hold pos, no set-points, handshake idle
  PpOutput step(const PpInput& in, double dt) noexcept;
  double current_target() const noexcept { return target_; }
  bool moving() const noexcept { return active_; }

 private:
  Trapezoid traj_;
  double target_ = 0, buffered_ = 0, last_accepted_ = 0;
  bool active_ = false, has_buffer_ = false, prev_bit4_ = false, ack_ = false;
  bool limited_ = false, buffered_limited_ = false;
};

}  // namespace omnitwin::drive
