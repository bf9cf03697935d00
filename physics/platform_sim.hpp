// physics layer — the MuJoCo platform as a steppable object: fixed mjModel + changing mjData.
//
// PlatformSim owns one mjModel (built from PlatformParams through platform_mjcf, or loaded
// from a hand-written file with the same naming contract) and one mjData. The model is the
// fixed description; the data is the state that step() advances. The one deliberate write
// into the model is the wheel-slip fault (set_wheel_friction_scale), which rescales stored
// friction coefficients from remembered nominal values so that 1.0 restores them exactly.
// Ids are resolved by name once at construction; everything on the cyclic path (setpoints,
// step, accessors) is real-time safe: no allocation, no exceptions, no locks.
//
// Units: SI. Wheel indices are 0-based (wheel0 = 0..3 is W1..W4 of seed 002). Angles in rad.
#pragma once

#include <mujoco/mujoco.h>

#include <Eigen/Core>
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "physics/platform_params.hpp"

namespace omnitwin::physics {

// Planar pose of the platform centre O_m in the world: x, y [m], phi [rad] (unwrapped).
struct Pose {
  double x, y, phi;
};

// Owning handles of MuJoCo's model and data (mj_deleteModel / mj_deleteData on release).
struct ModelDeleter {
  void operator()(mjModel* m) const { mj_deleteModel(m); }
};
struct DataDeleter {
  void operator()(mjData* d) const { mj_deleteData(d); }
};
using ModelPtr = std::unique_ptr<mjModel, ModelDeleter>;
using DataPtr = std::unique_ptr<mjData, DataDeleter>;

class PlatformSim {
 public:
  // Generates the MJCF for p (p.sim.variant) and loads it from memory. Throws
  // std::runtime_error with MuJoCo's message if the model does not compile. Not real-time.
  explicit PlatformSim(const PlatformParams& p);

  // Loads a hand-written MJCF that follows the naming contract of platform_mjcf.hpp; p gives
  // the speed limit and the nominal wheel radius. Throws std::runtime_error naming the file
  // and MuJoCo's message, or the missing/mistyped names. Not real-time.
  static PlatformSim from_file(const std::string& mjcf_path, const PlatformParams& p);

  PlatformSim(PlatformSim&&) noexcept = default;
  PlatformSim& operator=(PlatformSim&&) noexcept = default;
  PlatformSim(const PlatformSim&) = delete;
  PlatformSim& operator=(const PlatformSim&) = delete;
  ~PlatformSim() = default;

  // Resets the whole state (time 0, joints 0, setpoints 0, warnings 0) and places the
  // chassis at (x [m], y [m], phi [rad]) with its lowest colliding geom on the floor z = 0,
  // at rest, then runs mj_forward. Not real-time safe in spirit (meant between runs), but
  // does not allocate.
  void reset(double x, double y, double phi);

  // Speed setpoint of one amplifier [rad/s]: the amplifier makes rad_s·(1 + gain error) of
  // it, clamped to ±speed_limit, and that is written to ctrl. Returns false (and changes
  // nothing) for a wheel index outside 0..3 or a NaN. Real-time safe.
  bool set_wheel_speed_setpoint(int wheel0, double rad_s);
  // Input voltage of one analog amplifier [V] (the thesis node's DA output): its input stage
  // (zero volts, dead band, gain, limit: physics/amplifier.hpp) makes the speed setpoint,
  // then as set_wheel_speed_setpoint. The node's firmware ends at this voltage; the amplifier,
  // motor and wheel are physics. Same returns. Real-time safe.
  bool set_wheel_amplifier_input(int wheel0, double volts);
  // The speed setpoint last given to wheel 0..3 [rad/s], before the amplifier's gain error
  // (what trajectory.csv records and replay gives back). Real-time safe.
  double wheel_setpoint(int wheel0) const { return setpoint_[static_cast<std::size_t>(wheel0)]; }

  // Advances one MuJoCo step (timestep() seconds) and tracks the unwrapped yaw.
  // Real-time safe.
  void step();

  // Simulated time [s]. Real-time safe.
  double time() const { return data_->time; }
  // MuJoCo step [s]. Real-time safe.
  double timestep() const { return model_->opt.timestep; }
  // Pose of O_m; phi continuous across ±pi (counts whole turns). Real-time safe.
  Pose pose() const;
  // World twist (xdot [m/s], ydot [m/s], phidot [rad/s]) of O_m. Real-time safe.
  Eigen::Vector3d twist_world() const;
  // Wheel hinge angle [rad] (continuous), speed [rad/s], and the actuator torque [N·m]
  // applied during the last step. NaN for a wheel index outside 0..3. Real-time safe.
  double wheel_angle(int wheel0) const;
  double wheel_speed(int wheel0) const;
  double wheel_torque(int wheel0) const;
  // Wheel hinge angle [rad] at time t [s] within one step of time(): the state's angle moved
  // on linearly with the wheel's speed (so an event between two steps reads its own instant);
  // farther away, the state's angle as it stands. NaN for a bad wheel index. Real-time safe.
  double wheel_angle_at(int wheel0, double t) const;

  // Wheel-slip fault: that wheel's floor friction = nominal · scale (scale >= 0; 1 restores
  // the nominal values bit for bit). Scales the wheel's colliding geoms and any explicit
  // floor pair. Geom friction only counts if the wheel geoms win MuJoCo's mixing (the
  // generated rollers carry priority 1; without it MuJoCo takes the max with the floor).
  // The scale is a model property: it survives reset(). Returns false for a bad wheel
  // index or a negative/non-finite scale. Real-time safe (writes a few model entries).
  bool set_wheel_friction_scale(int wheel0, double scale);

  // Sum of MuJoCo's per-data warning counters since the last reset. Real-time safe.
  int warning_count() const;

  const mjModel* model() const { return model_.get(); }
  const mjData* data() const { return data_.get(); }
  mjData* data() { return data_.get(); }

 private:

  // One friction coefficient the slip fault scales: its address in the model and its
  // nominal value.
  struct FrictionEntry {
    mjtNum* value;
    mjtNum nominal;
  };

  PlatformSim(ModelPtr model, const PlatformParams& p);
  void resolve_ids();
  void collect_friction();
  double lowest_collision_z() const;
  double raw_yaw() const;

  ModelPtr model_;
  DataPtr data_;
  DriverParams driver_;       // the amplifiers: input stage, gain_error (speed = setpoint·(1 + e))
  MotorParams motor_params_;  // speed_limit: |setpoint| limit [rad/s]
  std::array<double, 4> setpoint_{};     // last speed setpoint asked of each wheel [rad/s]
  double nominal_height_ = 0;  // first guess for the chassis height [m] (wheel radius)
  int root_qpos_ = 0, root_dof_ = 0;
  std::array<int, 4> wheel_qpos_{}, wheel_dof_{}, motor_{};
  std::array<std::vector<FrictionEntry>, 4> friction_;
  double phi_ref_ = 0;  // unwrapped yaw at the last step [rad]
  double yaw_ref_ = 0;  // raw yaw (in (-pi, pi]) at the last step [rad]
};

}  // namespace omnitwin::physics
