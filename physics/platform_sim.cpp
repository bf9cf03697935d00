// physics layer — the steppable MuJoCo platform; see platform_sim.hpp.
#include "physics/platform_sim.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <numbers>
#include <stdexcept>

#include "physics/amplifier.hpp"
#include "physics/mujoco_message.hpp"
#include "physics/platform_mjcf.hpp"
#include "physics/wheel_contact.hpp"

namespace omnitwin::physics {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr int kErrLen = 1024;

// Frees a heap mjVFS and its files (mjVFS is ~2 MB, too big for the stack).
struct VfsDeleter {
  void operator()(mjVFS* v) const {
    mj_deleteVFS(v);
    delete v;
  }
};

// Compiles MJCF text through MuJoCo's virtual file system; throws with MuJoCo's message.
mjModel* load_from_text(const std::string& xml) {
  install_wheel_contact();  // the fast model's marked capsules need it; others are unchanged
  const char* name = "omni4_generated.xml";
  std::unique_ptr<mjVFS, VfsDeleter> vfs(new mjVFS);
  mj_defaultVFS(vfs.get());
  if (mj_makeEmptyFileVFS(vfs.get(), name, static_cast<int>(xml.size())) != 0) {
    throw std::runtime_error("PlatformSim: cannot create the in-memory MJCF file");
  }
  const int idx = mj_findFileVFS(vfs.get(), name);
  std::memcpy(vfs->filedata[idx], xml.data(), xml.size());
  std::array<char, kErrLen> err{};
  mjModel* m = mj_loadXML(name, vfs.get(), err.data(), kErrLen);
  if (!m) throw std::runtime_error("PlatformSim: generated MJCF failed to load: " +
                                   one_line(err.data()));
  return m;
}

// Wraps an angle into (-pi, pi].
double wrap(double a) {
  a = std::remainder(a, 2 * kPi);
  return a <= -kPi ? a + 2 * kPi : a;
}

// Id of a named object, or -1 with its kind and name ("joint wheel1") appended to `missing`:
// a wheel's body and joint share a name, so the name alone listed "wheel1, wheel1".
int require(const mjModel* m, mjtObj type, const std::string& name, std::string& missing) {
  const int id = mj_name2id(m, type, name.c_str());
  if (id < 0) missing += (missing.empty() ? "" : ", ") + std::string(mju_type2Str(type)) + " " + name;
  return id;
}

bool valid_wheel(int wheel0) { return wheel0 >= 0 && wheel0 < 4; }

// True if body b is `root` or lies in its subtree.
bool in_subtree(const mjModel* m, int b, int root) {
  for (; b > 0; b = m->body_parentid[b]) {
    if (b == root) return true;
  }
  return b == root;
}

// Lowest z of a geom from its world pose (exact for primitives, bounding sphere otherwise).
double geom_bottom(const mjModel* m, const mjData* d, int g) {
  const mjtNum* mat = d->geom_xmat + 9 * g;  // row-major: mat[6..8] = z of the local axes
  const mjtNum* s = m->geom_size + 3 * g;
  const double z = d->geom_xpos[3 * g + 2];
  switch (m->geom_type[g]) {
    case mjGEOM_SPHERE: return z - s[0];
    case mjGEOM_CAPSULE: return z - std::abs(mat[8]) * s[1] - s[0];
    case mjGEOM_CYLINDER:
      return z - std::abs(mat[8]) * s[1] - s[0] * std::sqrt(std::max(0.0, 1 - mat[8] * mat[8]));
    case mjGEOM_BOX:
      return z - std::abs(mat[6]) * s[0] - std::abs(mat[7]) * s[1] - std::abs(mat[8]) * s[2];
    case mjGEOM_ELLIPSOID:
      return z - std::hypot(mat[6] * s[0], mat[7] * s[1], mat[8] * s[2]);
    default: return z - m->geom_rbound[g];
  }
}

// True if geom g can touch anything: it has collision bits or sits in an explicit pair.
bool collides(const mjModel* m, int g) {
  if (m->geom_contype[g] || m->geom_conaffinity[g]) return true;
  for (int p = 0; p < m->npair; ++p) {
    if (m->pair_geom1[p] == g || m->pair_geom2[p] == g) return true;
  }
  return false;
}

}  // namespace

namespace {

mjModel* load_from_file(const std::string& mjcf_path) {
  install_wheel_contact();
  std::array<char, kErrLen> err{};
  mjModel* m = mj_loadXML(mjcf_path.c_str(), nullptr, err.data(), kErrLen);
  if (!m) {
    throw std::runtime_error("PlatformSim: cannot load MJCF '" + mjcf_path +
                             "': " + one_line(err.data()));
  }
  return m;
}

}  // namespace

PlatformSim::PlatformSim(const PlatformParams& p)
    : PlatformSim(ModelPtr(p.sim.mjcf.empty() ? load_from_text(platform_mjcf(p)) : load_from_file(p.sim.mjcf)),
                  p) {}

PlatformSim PlatformSim::from_file(const std::string& mjcf_path, const PlatformParams& p) {
  return PlatformSim(ModelPtr(load_from_file(mjcf_path)), p);
}

PlatformSim::PlatformSim(ModelPtr model, const PlatformParams& p)
    : model_(std::move(model)),
      driver_(p.driver),
      motor_params_(p.motor),
      nominal_height_(p.geometry.r) {
  // Names first (throws on a broken contract), then data, then the initial placement.
  resolve_ids();
  collect_friction();
  data_.reset(mj_makeData(model_.get()));
  if (!data_) throw std::runtime_error("PlatformSim: mj_makeData failed");
  reset(0, 0, 0);
}

void PlatformSim::resolve_ids() {
  const mjModel* m = model_.get();
  std::string missing, mistyped;
  require(m, mjOBJ_BODY, "chassis", missing);
  const int root = require(m, mjOBJ_JOINT, "root", missing);
  if (root >= 0 && m->jnt_type[root] != mjJNT_FREE) mistyped += " root(not a free joint)";
  for (int i = 0; i < 4; ++i) {
    const std::string n = std::to_string(i + 1);
    require(m, mjOBJ_BODY, "wheel" + n, missing);
    const int j = require(m, mjOBJ_JOINT, "wheel" + n, missing);
    const int a = require(m, mjOBJ_ACTUATOR, "motor" + n, missing);
    if (j >= 0 && m->jnt_type[j] != mjJNT_HINGE) mistyped += " wheel" + n + "(not a hinge)";
    // The motor drives the wheel, or (a gearbox with backlash) its own rotor hinge "rotorN".
    const int rotor = mj_name2id(m, mjOBJ_JOINT, ("rotor" + n).c_str());
    const bool on_rotor = rotor >= 0 && m->jnt_type[rotor] == mjJNT_HINGE && a >= 0 && m->actuator_trnid[2 * a] == rotor;
    if (a >= 0 && (m->actuator_trntype[a] != mjTRN_JOINT || (m->actuator_trnid[2 * a] != j && !on_rotor))) {
      mistyped += " motor" + n + "(does not drive joint wheel" + n + " or rotor" + n + ")";
    }
    if (j >= 0) wheel_qpos_[i] = m->jnt_qposadr[j], wheel_dof_[i] = m->jnt_dofadr[j];
    motor_[i] = a;
  }
  if (!missing.empty() || !mistyped.empty()) {
    throw std::runtime_error("PlatformSim: model breaks the naming contract; missing: [" +
                             missing + "] wrong:" + (mistyped.empty() ? " none" : mistyped));
  }
  root_qpos_ = m->jnt_qposadr[root];
  root_dof_ = m->jnt_dofadr[root];
}

void PlatformSim::collect_friction() {
  mjModel* m = model_.get();
  for (int i = 0; i < 4; ++i) {
    const int wheel_body = mj_name2id(m, mjOBJ_BODY, ("wheel" + std::to_string(i + 1)).c_str());
    auto in_wheel = [&](int g) { return g >= 0 && in_subtree(m, m->geom_bodyid[g], wheel_body); };
    // Sliding friction of every colliding geom on the wheel (rollers or tyre).
    for (int g = 0; g < m->ngeom; ++g) {
      if (in_wheel(g) && (m->geom_contype[g] || m->geom_conaffinity[g])) {
        friction_[i].push_back({m->geom_friction + 3 * g, m->geom_friction[3 * g]});
      }
    }
    // Both tangential coefficients of explicit pairs with a wheel geom.
    for (int p = 0; p < m->npair; ++p) {
      if (!in_wheel(m->pair_geom1[p]) && !in_wheel(m->pair_geom2[p])) continue;
      for (int k = 0; k < 2; ++k) {
        friction_[i].push_back({m->pair_friction + 5 * p + k, m->pair_friction[5 * p + k]});
      }
    }
  }
}

double PlatformSim::lowest_collision_z() const {
  const mjModel* m = model_.get();
  double lowest = std::numeric_limits<double>::infinity();
  // Everything that can touch the floor and moves with the platform (not the world body).
  for (int g = 0; g < m->ngeom; ++g) {
    if (m->geom_bodyid[g] == 0 || m->geom_type[g] == mjGEOM_PLANE || !collides(m, g)) continue;
    lowest = std::min(lowest, geom_bottom(m, data_.get(), g));
  }
  return std::isfinite(lowest) ? lowest : 0.0;
}

void PlatformSim::reset(double x, double y, double phi) {
  mjModel* m = model_.get();
  mjData* d = data_.get();
  mj_resetData(m, d);
  setpoint_.fill(0.0);
  // Pose at the nominal hub height, level, yawed by phi.
  mjtNum* q = d->qpos + root_qpos_;
  q[0] = x, q[1] = y, q[2] = nominal_height_;
  q[3] = std::cos(phi / 2), q[4] = 0, q[5] = 0, q[6] = std::sin(phi / 2);
  // Lower (or raise) it so the lowest colliding geom just touches z = 0.
  mj_kinematics(m, d);
  q[2] -= lowest_collision_z();
  mj_forward(m, d);
  phi_ref_ = phi;
  yaw_ref_ = raw_yaw();
}

bool PlatformSim::set_wheel_speed_setpoint(int wheel0, double rad_s) {
  if (!valid_wheel(wheel0) || std::isnan(rad_s)) return false;
  setpoint_[static_cast<std::size_t>(wheel0)] = rad_s;
  // The amplifier's own gain error scales what it makes of the setpoint, then its limit.
  const double actual = rad_s * (1.0 + driver_.gain_error[static_cast<std::size_t>(wheel0)]);
  const double limit = motor_params_.speed_limit;
  data_->ctrl[motor_[wheel0]] = std::clamp(actual, -limit, limit);
  return true;
}

bool PlatformSim::set_wheel_amplifier_input(int wheel0, double volts) {
  if (std::isnan(volts)) return false;
  return set_wheel_speed_setpoint(wheel0, driver_setpoint(driver_, motor_params_, volts));
}

void PlatformSim::step() {
  mj_step(model_.get(), data_.get());
  // Unwrap: add the wrapped change of the raw yaw since the last step.
  const double yaw = raw_yaw();
  phi_ref_ += wrap(yaw - yaw_ref_);
  yaw_ref_ = yaw;
}

double PlatformSim::raw_yaw() const {
  const mjtNum* q = data_->qpos + root_qpos_ + 3;  // w, x, y, z
  return std::atan2(2 * (q[0] * q[3] + q[1] * q[2]), 1 - 2 * (q[2] * q[2] + q[3] * q[3]));
}

Pose PlatformSim::pose() const {
  const mjtNum* q = data_->qpos + root_qpos_;
  // Robust also if someone moved qpos since the last step (less than half a turn).
  return {q[0], q[1], phi_ref_ + wrap(raw_yaw() - yaw_ref_)};
}

Eigen::Vector3d PlatformSim::twist_world() const {
  // Free joint: linear velocity in world, angular velocity in the body frame.
  const mjtNum* v = data_->qvel + root_dof_;
  mjtNum w_world[3];
  mju_rotVecQuat(w_world, v + 3, data_->qpos + root_qpos_ + 3);
  return {v[0], v[1], w_world[2]};
}

double PlatformSim::wheel_angle(int wheel0) const {
  return valid_wheel(wheel0) ? data_->qpos[wheel_qpos_[wheel0]] : kNaN;
}

double PlatformSim::wheel_angle_at(int wheel0, double t) const {
  const double gap = t - time();
  if (std::abs(gap) > timestep() * (1.0 + 1e-9)) return wheel_angle(wheel0);  // not between two steps
  return wheel_angle(wheel0) + wheel_speed(wheel0) * gap;
}

double PlatformSim::wheel_speed(int wheel0) const {
  return valid_wheel(wheel0) ? data_->qvel[wheel_dof_[wheel0]] : kNaN;
}

double PlatformSim::wheel_torque(int wheel0) const {
  return valid_wheel(wheel0) ? data_->actuator_force[motor_[wheel0]] : kNaN;
}

bool PlatformSim::set_wheel_friction_scale(int wheel0, double scale) {
  if (!valid_wheel(wheel0) || !std::isfinite(scale) || scale < 0) return false;
  for (FrictionEntry& e : friction_[wheel0]) *e.value = e.nominal * scale;
  return true;
}

int PlatformSim::warning_count() const {
  int n = 0;
  for (int i = 0; i < mjNWARNING; ++i) n += data_->warning[i].number;
  return n;
}

}  // namespace omnitwin::physics
