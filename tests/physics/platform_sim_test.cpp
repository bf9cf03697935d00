// Tests physics/platform_sim: open-loop omni motion from contact physics on both variants
// (acceptance: wheel speeds from D_e give the commanded twist within 0.5 %), odometry D_i
// against the physics, determinism, yaw unwrapping, the wheel-slip fault, reset placement,
// setpoint clamping, the wheel torque limit, the naming contract of from_file, and the motor
// model options: the electrical lag's step response, gearbox friction, a payload, and a
// platform held still by its four drive chains that does not walk away (standstill creep).
#include "physics/platform_sim.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <iostream>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

#include "physics/drive_chain.hpp"
#include "physics/kinematics.hpp"
#include "physics/platform_mjcf.hpp"
#include "tests/support/mujoco_fixture.hpp"
#include "tests/support/temp_dir.hpp"

namespace omnitwin::physics {
namespace {

using omnitwin::testing::source_path;
constexpr double kPi = std::numbers::pi;
constexpr double kRamp = 0.5;                    // setpoint ramp [s]
constexpr double kWindow0 = 1.0, kWindow1 = 5.0;  // steady window [s]

PlatformParams params(ModelVariant v) {
  PlatformParams p;
  p.sim.variant = v;
  return p;
}

// Steps until time t_end with every wheel at `ramp(t)·w`.
void drive(PlatformSim& s, const WheelVector& w, double t_end) {
  while (s.time() < t_end - 1e-9) {
    const double k = std::min(1.0, s.time() / kRamp);
    for (int i = 0; i < 4; ++i) s.set_wheel_speed_setpoint(i, k * w(i));
    s.step();
  }
}

// Open loop: setpoints from D_e at the start heading, ramped; mean twist over the window.
Twist mean_open_loop_twist(PlatformSim& s, const PlatformParams& p, const Twist& cmd) {
  const WheelVector w = wheel_speeds(cmd, s.pose().phi, p.geometry.L, p.geometry.r);
  drive(s, w, kWindow0);
  const Pose a = s.pose();
  drive(s, w, kWindow1);
  const Pose b = s.pose();
  const double dt = kWindow1 - kWindow0;
  return Twist((b.x - a.x) / dt, (b.y - a.y) / dt, (b.phi - a.phi) / dt);
}

struct OpenLoopCase {
  const char* name;
  ModelVariant variant;
  Twist cmd;
  double bound;  // relative error bound
};

void PrintTo(const OpenLoopCase& c, std::ostream* os) { *os << c.name; }

class OpenLoop : public omnitwin::testing::MujocoTest,
                 public ::testing::WithParamInterface<OpenLoopCase> {};

TEST_P(OpenLoop, CommandedTwistWithinBound) {
  const OpenLoopCase& c = GetParam();
  // The contact kinematics, not the motor: a stiff servo without lag follows its setpoint
  // (the default kv 2 loses about 1 % of speed open loop, which the slave's PI takes back).
  PlatformParams p = params(c.variant);
  p.motor.kv = 20.0;
  p.motor.electrical_tau = 0.0;
  PlatformSim s(p);
  const Twist m = mean_open_loop_twist(s, p, c.cmd);
  if (c.cmd.head<2>().norm() > 0) {
    // Translation: planar speed error relative to the commanded speed; heading stays put.
    const double err = (m.head<2>() - c.cmd.head<2>()).norm() / c.cmd.head<2>().norm();
    RecordProperty("twist_error_percent", std::to_string(100 * err));
    std::cout << "[ measured ] " << c.name << ": planar speed error " << 100 * err << " %, heading drift "
              << s.pose().phi * 180 / kPi << " deg\n";
    EXPECT_LT(err, c.bound) << "measured " << m.transpose();
    EXPECT_LT(std::abs(s.pose().phi), 0.3 * kPi / 180) << "heading drift over 5 s";
  } else {
    // Rotation: rate error; the centre stays within a few mm.
    std::cout << "[ measured ] " << c.name << ": rate error " << 100 * (m(2) / c.cmd(2) - 1) << " %\n";
    EXPECT_LT(std::abs(m(2) / c.cmd(2) - 1), c.bound) << "measured " << m.transpose();
    EXPECT_LT(std::hypot(s.pose().x, s.pose().y), 0.005);
  }
  EXPECT_EQ(s.warning_count(), 0);
}

const double kDiag = 0.15 / std::sqrt(2.0);
INSTANTIATE_TEST_SUITE_P(
    Rollers, OpenLoop,
    ::testing::Values(OpenLoopCase{"PlusX", ModelVariant::rollers, Twist(0.15, 0, 0), 0.005},
                      OpenLoopCase{"PlusY", ModelVariant::rollers, Twist(0, 0.15, 0), 0.005},
                      OpenLoopCase{"Diagonal", ModelVariant::rollers, Twist(kDiag, kDiag, 0), 0.005},
                      OpenLoopCase{"Rotation", ModelVariant::rollers, Twist(0, 0, 0.5), 0.005}),
    [](const auto& info) { return std::string(info.param.name); });
// Capsule variant (the fast model): measured +0.11 % in translation and +0.36 % in rotation
// (the reference: +0.04 %, +0.37 %); same 0.5 % bound.
INSTANTIATE_TEST_SUITE_P(
    Capsule, OpenLoop,
    ::testing::Values(OpenLoopCase{"PlusX", ModelVariant::capsule, Twist(0.15, 0, 0), 0.005},
                      OpenLoopCase{"PlusY", ModelVariant::capsule, Twist(0, 0.15, 0), 0.005},
                      OpenLoopCase{"Diagonal", ModelVariant::capsule, Twist(kDiag, kDiag, 0), 0.005},
                      OpenLoopCase{"Rotation", ModelVariant::capsule, Twist(0, 0, 0.5), 0.005}),
    [](const auto& info) { return std::string(info.param.name); });

using PlatformSimTest = omnitwin::testing::MujocoTest;

TEST_F(PlatformSimTest, OdometryFromWheelSpeedsTracksThePhysics) {
  // Constant wheel speeds (a body-frame twist) drive an arc; integrating D_i·r·omega from
  // the measured wheel speeds must land where the physics went.
  const PlatformParams p = params(ModelVariant::rollers);
  PlatformSim s(p);
  const WheelVector w = wheel_speeds(Twist(0.1, 0.05, 0.3), 0.0, p.geometry.L, p.geometry.r);
  drive(s, w, kWindow0);
  Pose odo = s.pose();
  const Pose start = odo;
  double path = 0;
  while (s.time() < 4.0 - 1e-9) {
    s.step();
    const WheelVector omega(s.wheel_speed(0), s.wheel_speed(1), s.wheel_speed(2),
                            s.wheel_speed(3));
    const Twist t = platform_twist(omega, odo.phi, p.geometry.L, p.geometry.r);
    odo = {odo.x + t(0) * s.timestep(), odo.y + t(1) * s.timestep(),
           odo.phi + t(2) * s.timestep()};
    path += s.twist_world().head<2>().norm() * s.timestep();
  }
  const Pose end = s.pose();
  ASSERT_GT(path, 0.25);
  EXPECT_LT(std::hypot(odo.x - end.x, odo.y - end.y), 0.005 * path);
  EXPECT_NEAR(odo.phi - start.phi, end.phi - start.phi, 0.005 * (end.phi - start.phi));
}

TEST_F(PlatformSimTest, InstantaneousTwistMatchesInverseKinematicsOnAverage) {
  // twist_world() against D_i(phi)·r·omega, sample by sample, averaged over steady motion.
  const PlatformParams p = params(ModelVariant::rollers);
  PlatformSim s(p);
  const Twist cmd(0.1, -0.08, 0);
  drive(s, wheel_speeds(cmd, 0, p.geometry.L, p.geometry.r), kWindow0);
  Twist sum_err = Twist::Zero();
  int n = 0;
  for (; s.time() < 3.0; ++n) {
    s.step();
    const WheelVector omega(s.wheel_speed(0), s.wheel_speed(1), s.wheel_speed(2),
                            s.wheel_speed(3));
    sum_err += platform_twist(omega, s.pose().phi, p.geometry.L, p.geometry.r) -
               s.twist_world();
  }
  EXPECT_LT((sum_err / n).head<2>().norm(), 0.005 * cmd.norm());
  EXPECT_LT(std::abs(sum_err(2) / n), 1e-3);
}

TEST_F(PlatformSimTest, WheelAngleBetweenStepsFollowsTheWheelSpeed) {
  // A device event between two steps reads the angle of its own instant.
  PlatformSim s(params(ModelVariant::rollers));
  for (int i = 0; i < 4; ++i) s.set_wheel_speed_setpoint(i, 5.0);
  for (int k = 0; k < 300; ++k) s.step();
  const double dt = s.timestep(), t = s.time();
  for (int i = 0; i < 4; ++i) {
    const double a = s.wheel_angle(i), w = s.wheel_speed(i);
    ASSERT_GT(w, 1.0);
    EXPECT_DOUBLE_EQ(s.wheel_angle_at(i, t), a);
    EXPECT_DOUBLE_EQ(s.wheel_angle_at(i, t - 0.25 * dt), a - 0.25 * dt * w);
    EXPECT_DOUBLE_EQ(s.wheel_angle_at(i, t - dt), a - dt * w);
    // Beyond one step: no extrapolation.
    EXPECT_DOUBLE_EQ(s.wheel_angle_at(i, t - 3 * dt), a);
  }
  // One step back is, to first order, the angle the previous step ended with.
  const double before = s.wheel_angle(0);
  const double t0 = s.time();
  s.step();
  EXPECT_NEAR(s.wheel_angle_at(0, t0), before, 1e-3 * dt * 5.0 + 1e-9);
  EXPECT_TRUE(std::isnan(s.wheel_angle_at(4, t0)));
}

TEST_F(PlatformSimTest, IdenticalInputsGiveBitIdenticalState) {
  PlatformSim a(params(ModelVariant::rollers)), b(params(ModelVariant::rollers));
  for (int k = 0; k < 1500; ++k) {
    // A varying command on every wheel exercises contact changes.
    for (int i = 0; i < 4; ++i) {
      const double sp = 3.0 * std::sin(0.004 * k + i);
      a.set_wheel_speed_setpoint(i, sp);
      b.set_wheel_speed_setpoint(i, sp);
    }
    a.step();
    b.step();
  }
  const mjModel* m = a.model();
  EXPECT_EQ(std::memcmp(a.data()->qpos, b.data()->qpos, sizeof(mjtNum) * m->nq), 0);
  EXPECT_EQ(std::memcmp(a.data()->qvel, b.data()->qvel, sizeof(mjtNum) * m->nv), 0);
  EXPECT_NE(a.data()->qpos[0], 0.0);  // it did move
}

TEST_F(PlatformSimTest, YawIsContinuousThroughSeveralHalfTurns) {
  const PlatformParams p = params(ModelVariant::rollers);
  PlatformSim s(p);
  s.reset(0.3, -0.2, 3.0);  // start near +pi so the raw yaw wraps early
  const WheelVector w = wheel_speeds(Twist(0, 0, 2.0), 0, p.geometry.L, p.geometry.r);
  double prev = s.pose().phi, max_jump = 0;
  while (s.time() < 4.5) {
    const double k = std::min(1.0, s.time() / kRamp);
    for (int i = 0; i < 4; ++i) s.set_wheel_speed_setpoint(i, k * w(i));
    s.step();
    max_jump = std::max(max_jump, std::abs(s.pose().phi - prev));
    prev = s.pose().phi;
  }
  EXPECT_GT(prev - 3.0, 2 * kPi + 0.5);  // turned well past a full turn
  EXPECT_LT(max_jump, 0.01);             // 2 rad/s · 1 ms plus ripple; never a 2·pi jump
  // The unwrapped angle still names the true orientation (chassis is body 1).
  mj_forward(s.model(), s.data());
  const double yaw = std::atan2(s.data()->xmat[9 + 3], s.data()->xmat[9 + 0]);
  EXPECT_NEAR(std::remainder(prev - yaw, 2 * kPi), 0.0, 1e-9);
}

// Runs +X open loop for 4 s with wheel 1's friction scaled; returns the final pose.
Pose plus_x_with_slip(double scale) {
  const PlatformParams p = params(ModelVariant::rollers);
  PlatformSim s(p);
  EXPECT_TRUE(s.set_wheel_friction_scale(0, scale));
  drive(s, wheel_speeds(Twist(0.15, 0, 0), 0, p.geometry.L, p.geometry.r), 4.0);
  EXPECT_EQ(s.warning_count(), 0);
  return s.pose();
}

TEST_F(PlatformSimTest, FrictionlessWheelMakesThePlatformDeviate) {
  // Three wheels carry the platform alone (the kinematics is then exactly determined, so the
  // effect is modest): it ends up measurably elsewhere and turned.
  const Pose nominal = plus_x_with_slip(1.0), slip = plus_x_with_slip(0.0);
  // Measured: 5.8 mm and 0.31 deg after 4 s at 0.15 m/s.
  EXPECT_GT(std::hypot(slip.x - nominal.x, slip.y - nominal.y), 2e-3);
  EXPECT_GT(std::abs(slip.phi - nominal.phi), 0.1 * kPi / 180);
}

TEST_F(PlatformSimTest, FrictionScaleOneRestoresTheModelExactly) {
  for (auto v : {ModelVariant::rollers, ModelVariant::capsule}) {
    PlatformSim fresh(params(v)), s(params(v));
    const mjModel* m = s.model();
    ASSERT_TRUE(s.set_wheel_friction_scale(2, 0.0));
    const bool unchanged =
        std::memcmp(m->geom_friction, fresh.model()->geom_friction,
                    sizeof(mjtNum) * 3 * m->ngeom) == 0 &&
        std::memcmp(m->pair_friction, fresh.model()->pair_friction,
                    sizeof(mjtNum) * 5 * m->npair) == 0;
    EXPECT_FALSE(unchanged) << "scale 0 changed nothing";
    ASSERT_TRUE(s.set_wheel_friction_scale(2, 1.0));
    EXPECT_EQ(std::memcmp(m->geom_friction, fresh.model()->geom_friction,
                          sizeof(mjtNum) * 3 * m->ngeom), 0);
    EXPECT_EQ(std::memcmp(m->pair_friction, fresh.model()->pair_friction,
                          sizeof(mjtNum) * 5 * m->npair), 0);
  }
}

TEST_F(PlatformSimTest, BadArgumentsAreRejectedWithoutSideEffects) {
  PlatformSim s(params(ModelVariant::capsule));
  EXPECT_FALSE(s.set_wheel_speed_setpoint(4, 1.0));
  EXPECT_FALSE(s.set_wheel_speed_setpoint(-1, 1.0));
  EXPECT_FALSE(s.set_wheel_friction_scale(0, -0.5));
  EXPECT_TRUE(std::isnan(s.wheel_speed(7)));
  // Setpoints clamp to the amplifier's ±speed_limit.
  ASSERT_TRUE(s.set_wheel_speed_setpoint(1, 100.0));
  EXPECT_DOUBLE_EQ(s.data()->ctrl[1], 20.0);
  ASSERT_TRUE(s.set_wheel_speed_setpoint(1, -100.0));
  EXPECT_DOUBLE_EQ(s.data()->ctrl[1], -20.0);
}

TEST_F(PlatformSimTest, TheAmplifierInputStageMakesTheSpeedSetpointOfTheDaVolts) {
  // Where the node ends and physics begins: the DA's voltage goes in, and the amplifier's
  // input stage (dead band, gain), then its gain error and limit, make the servo's setpoint.
  PlatformParams p = params(ModelVariant::capsule);
  p.driver.dead_band = 0.05;
  p.driver.gain_error = {0.0, 0.1, 0.0, 0.0};
  PlatformSim s(p);
  const double zero = p.driver.zero_volts;
  ASSERT_TRUE(s.set_wheel_amplifier_input(1, zero + 0.04));  // inside the dead band
  EXPECT_EQ(s.wheel_setpoint(1), 0.0);
  EXPECT_EQ(s.data()->ctrl[1], 0.0);
  ASSERT_TRUE(s.set_wheel_amplifier_input(1, zero - 0.5));  // 0.45 V past the band, reversed
  const double want = -0.45 * p.driver.gain;
  EXPECT_NEAR(s.wheel_setpoint(1), want, 1e-12);          // as asked (what the records keep)
  EXPECT_NEAR(s.data()->ctrl[1], 1.1 * want, 1e-12);      // as this amplifier makes it
  EXPECT_FALSE(s.set_wheel_amplifier_input(4, zero + 1.0));
  EXPECT_FALSE(s.set_wheel_amplifier_input(1, std::nan("")));
  EXPECT_NEAR(s.wheel_setpoint(1), want, 1e-12);
  s.reset(0, 0, 0);
  EXPECT_EQ(s.wheel_setpoint(1), 0.0);
}

TEST_F(PlatformSimTest, WheelTorqueStaysWithinTheMotorLimitAndSaturates) {
  // The amplifier's torque limit holds: a full-scale step from rest (+speed_limit on every
  // wheel, kv·speed_limit far beyond torque_limit) and then a full reversal (-speed_limit)
  // never push |wheel_torque| past motor.torque_limit, and both steps start on the rail
  // (the limit is reached, so the check is not vacuous). Also the setpoint clamp: 1e3 rad/s
  // lands in ctrl as exactly +speed_limit, -1e3 as -speed_limit. Both variants: the capsule
  // variant's elliptic cone (before issue 17) made MuJoCo 2.2.2's Newton solver warn
  // "Linesearch objective is not convex" on this step, which the fixture turns into a failure;
  // its pyramidal cone does not.
  for (const ModelVariant v : {ModelVariant::rollers, ModelVariant::capsule}) {
    SCOPED_TRACE(to_string(v));
    PlatformParams p = params(v);
    p.motor.kv = 20.0;  // a stiff servo without electrical lag: the first step hits the rail
    p.motor.electrical_tau = 0.0;
    ASSERT_GT(p.motor.kv * p.motor.speed_limit, 10 * p.motor.torque_limit) << "step must saturate";
    PlatformSim s(p);
    const double limit = p.motor.torque_limit;
    for (int i = 0; i < 4; ++i) {
      const int act = mj_name2id(s.model(), mjOBJ_ACTUATOR, ("motor" + std::to_string(i + 1)).c_str());
      ASSERT_GE(act, 0);
      ASSERT_TRUE(s.set_wheel_speed_setpoint(i, -1e3));
      EXPECT_EQ(s.data()->ctrl[act], -p.motor.speed_limit) << "wheel " << i;
      ASSERT_TRUE(s.set_wheel_speed_setpoint(i, 1e3));
      EXPECT_EQ(s.data()->ctrl[act], p.motor.speed_limit) << "wheel " << i;
    }
    for (const double sign : {+1.0, -1.0}) {
      for (int i = 0; i < 4; ++i) s.set_wheel_speed_setpoint(i, sign * 1e3);
      double peak = 0;
      int saturated_steps = 0;
      for (int k = 0; k < 300; ++k) {
        s.step();
        for (int i = 0; i < 4; ++i) {
          const double tau = s.wheel_torque(i);
          ASSERT_LE(std::abs(tau), limit + 1e-9) << "wheel " << i << " step " << k << " sign " << sign;
          peak = std::max(peak, std::abs(tau));
          if (k == 0) {
            EXPECT_NEAR(tau, sign * limit, 1e-9) << "wheel " << i << " not on the rail at once";
          }
          if (std::abs(tau) >= limit - 1e-9) ++saturated_steps;
        }
      }
      EXPECT_NEAR(peak, limit, 1e-9);
      EXPECT_GE(saturated_steps, 4 * 10) << "saturation should last more than a few steps";
    }
  }
}

TEST_F(PlatformSimTest, ResetPlacesThePlatformOnTheFloorAtRest) {
  for (auto v : {ModelVariant::rollers, ModelVariant::capsule}) {
    PlatformSim s(params(v));
    for (int k = 0; k < 200; ++k) s.step();  // some history to forget
    s.reset(1.0, -2.0, 0.7);
    EXPECT_EQ(s.time(), 0.0);
    EXPECT_DOUBLE_EQ(s.pose().x, 1.0);
    EXPECT_DOUBLE_EQ(s.pose().y, -2.0);
    EXPECT_NEAR(s.pose().phi, 0.7, 1e-12);
    EXPECT_NEAR(s.data()->qpos[2], 0.05, 5e-4) << "hub height ~ r";
    // Standing with zero setpoints and nothing holding the wheels (the servo alone is a
    // damper): the capsule variant stays put; the roller variant rolls into its roller
    // polygon's valley, a millimetre or so in 0.5 s and up to ~3 mm over 20 s
    // (APlatformHeldStillByItsDrivesDoesNotWalkAway covers a platform held by its slaves).
    const bool rollers = v == ModelVariant::rollers;
    for (int k = 0; k < 500; ++k) s.step();
    EXPECT_NEAR(s.pose().x, 1.0, rollers ? 2e-3 : 2e-4) << to_string(v);
    EXPECT_NEAR(s.pose().y, -2.0, rollers ? 2e-3 : 2e-4) << to_string(v);
    EXPECT_NEAR(s.pose().phi, 0.7, 1e-3);
    EXPECT_LT(s.twist_world().norm(), rollers ? 5e-3 : 1e-3);
  }
}

TEST_F(PlatformSimTest, CommittedModelFileBehavesLikeTheGeneratedOne) {
  const PlatformParams p = params(ModelVariant::rollers);
  PlatformSim gen(p);
  PlatformSim file = PlatformSim::from_file(source_path("models/platform/omni4_rollers.xml"), p);
  // The same file named through the parameters (a scenario's platform.mjcf).
  PlatformParams named = p;
  named.sim.mjcf = source_path("models/platform/omni4_rollers.xml");
  PlatformSim by_param(named);
  for (int k = 0; k < 300; ++k) {
    for (int i = 0; i < 4; ++i) by_param.set_wheel_speed_setpoint(i, 2.0 - i);
    by_param.step();
    for (int i = 0; i < 4; ++i) {
      gen.set_wheel_speed_setpoint(i, 2.0 - i);
      file.set_wheel_speed_setpoint(i, 2.0 - i);
    }
    gen.step();
    file.step();
  }
  EXPECT_EQ(std::memcmp(gen.data()->qpos, file.data()->qpos, sizeof(mjtNum) * gen.model()->nq),
            0);
  EXPECT_EQ(std::memcmp(gen.data()->qpos, by_param.data()->qpos, sizeof(mjtNum) * gen.model()->nq),
            0);
}

TEST_F(PlatformSimTest, FromFileRejectsUnloadableFiles) {
  const omnitwin::testing::TempDir dir("omnitwin-physics");  // removed even when the test fails
  const std::string path = dir / "omni4_broken.xml";
  std::ofstream(path) << "<mujoco><worldbody><body name=\"chassis\"></worldbody></mujoco>\n";
  try {
    PlatformSim::from_file(path, PlatformParams{});
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
  EXPECT_THROW(PlatformSim::from_file("/nonexistent/omni4.xml", PlatformParams{}),
               std::runtime_error);
}

TEST_F(PlatformSimTest, FromFileNamesWhatBreaksTheNamingContract) {
  // The generated model with motor3 renamed and wheel2's hinge turned into a slide.
  std::string xml = platform_mjcf(PlatformParams{});
  const std::string motor3 = "name=\"motor3\"", hinge2 = "name=\"wheel2\" type=\"hinge\"";
  xml.replace(xml.find(motor3), motor3.size(), "name=\"drive3\"");
  xml.replace(xml.find(hinge2), hinge2.size(), "name=\"wheel2\" type=\"slide\"");
  const omnitwin::testing::TempDir dir("omnitwin-physics");
  const std::string path = dir / "omni4_misnamed.xml";
  std::ofstream(path) << xml;
  try {
    PlatformSim::from_file(path, PlatformParams{});
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("missing: [actuator motor3]"), std::string::npos) << what;
    EXPECT_NE(what.find("wheel2"), std::string::npos) << what;
  }
}

// A wheel's body and joint share a name: a missing pair is told apart by its kind.
TEST_F(PlatformSimTest, FromFileNamesTheKindOfEachMissingObject) {
  const omnitwin::testing::TempDir dir("omnitwin-physics");
  const std::string path = dir / "omni4_bare.xml";
  std::ofstream(path) << "<mujoco><worldbody><body name=\"chassis\"><freejoint name=\"root\"/>"
                         "<geom size=\"0.1\" mass=\"1\"/></body></worldbody></mujoco>\n";
  try {
    PlatformSim::from_file(path, PlatformParams{});
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("body wheel1, joint wheel1, actuator motor1"), std::string::npos) << what;
  }
}

TEST_F(PlatformSimTest, MovedSimKeepsWorking) {
  PlatformSim a(params(ModelVariant::capsule));
  a.set_wheel_speed_setpoint(0, 1.0);
  PlatformSim b = std::move(a);
  for (int k = 0; k < 100; ++k) b.step();
  EXPECT_GT(b.wheel_angle(0), 0.0);
  EXPECT_TRUE(b.set_wheel_friction_scale(0, 0.5));
  EXPECT_EQ(b.warning_count(), 0);
}

// The platform at rest on the floor with each wheel closed by its own slave chain (counter,
// PI, DA; the amplifier is the sim's) at zero command, sampled every 10 ms; returns how far O_m moved [m] between
// t = 1 s and t = 1 + seconds.
double standstill_walk(const PlatformParams& p, double seconds) {
  PlatformSim s(p);
  std::vector<WheelDriveChain> chains;
  for (int i = 0; i < 4; ++i) chains.emplace_back(p, s.wheel_angle(i));
  const int per_sample = static_cast<int>(std::lround(p.velocity_loop.period / p.sim.timestep));
  Pose a{};
  const int steps = static_cast<int>(std::lround((1.0 + seconds) / p.sim.timestep));
  for (int k = 0; k < steps; ++k) {
    if (k % per_sample == 0)
      for (int i = 0; i < 4; ++i) s.set_wheel_amplifier_input(i, chains[i].sample(s.wheel_angle(i), 0.0));
    s.step();
    if (k + 1 == static_cast<int>(std::lround(1.0 / p.sim.timestep))) a = s.pose();
  }
  const Pose b = s.pose();
  return std::hypot(b.x - a.x, b.y - a.y);
}

TEST_F(PlatformSimTest, APlatformHeldStillByItsDrivesDoesNotWalkAway) {
  // Issue 15's standstill: 40 s at zero command must move O_m less than 0.05 cm. The cause
  // it had: a 1 ms velocity servo (kv 20, no electrical lag) turned each one-code PI step
  // around zero speed into a torque kick beyond what the roller contact holds, so the
  // wheels slipped back and forth and the platform walked millimetres (checked here too, so
  // the test shows what it guards against).
  const PlatformParams p = params(ModelVariant::rollers);
  EXPECT_LT(standstill_walk(p, 40.0), 0.0005);
  PlatformParams stiff = p;
  stiff.motor.kv = 20.0;
  stiff.motor.electrical_tau = 0.0;
  EXPECT_GT(standstill_walk(stiff, 40.0), 0.001);
}

TEST_F(PlatformSimTest, ElectricalLagShapesTheTorqueStepResponse) {
  // A setpoint step on a wheel at rest: without lag the first step's torque is kv·setpoint;
  // with electrical_tau = 10 ms it starts at 0 and the filtered setpoint reaches dt/τ = 10 %
  // of the step after one step and 1 − 0.9^k after k (MuJoCo's Euler filter).
  const double sp = 0.5;
  for (const double tau : {0.0, 0.010}) {
    PlatformParams p = params(ModelVariant::rollers);
    p.motor.electrical_tau = tau;
    PlatformSim s(p);
    s.set_wheel_speed_setpoint(0, sp);
    // A step's torque is computed from the filter state before the step integrates it.
    s.step();
    const double first = s.wheel_torque(0);
    s.step();
    const double second = s.wheel_torque(0);
    for (int k = 2; k < 10; ++k) s.step();
    const double tenth = s.wheel_torque(0);
    if (tau == 0.0) {
      EXPECT_NEAR(first, p.motor.kv * sp, 1e-9);
    } else {
      EXPECT_NEAR(first, 0.0, 1e-9);
      EXPECT_NEAR(second, 0.1 * p.motor.kv * sp, 0.01 * p.motor.kv * sp);
      // After 10 steps: a = (1 − 0.9^9)·sp ≈ 0.61·sp, less the little speed gained.
      EXPECT_GT(tenth, 0.40 * p.motor.kv * sp);
      EXPECT_LT(tenth, 0.66 * p.motor.kv * sp);
    }
  }
}

TEST_F(PlatformSimTest, GearFrictionAndPayloadReachTheModel) {
  // friction_torque becomes the wheel hinge's frictionloss; load_mass a box on the deck.
  PlatformParams p = params(ModelVariant::rollers);
  p.motor.friction_torque = 0.3;
  p.geometry.load_mass = 20.0;
  PlatformSim s(p);
  const int j = mj_name2id(s.model(), mjOBJ_JOINT, "wheel1");
  ASSERT_GE(j, 0);
  EXPECT_DOUBLE_EQ(s.model()->dof_frictionloss[s.model()->jnt_dofadr[j]], 0.3);
  const int load = mj_name2id(s.model(), mjOBJ_GEOM, "load");
  ASSERT_GE(load, 0);
  PlatformSim bare(params(ModelVariant::rollers));
  double m = 0, m0 = 0;
  for (int b = 0; b < s.model()->nbody; ++b) m += s.model()->body_mass[b];
  for (int b = 0; b < bare.model()->nbody; ++b) m0 += bare.model()->body_mass[b];
  EXPECT_NEAR(m - m0, 20.0, 1e-9);
  EXPECT_EQ(mj_name2id(bare.model(), mjOBJ_GEOM, "load"), -1);
}

// Found in review: MuJoCo's frictionloss is a soft row (impedance 0.9 by default), so a
// torque below the gearbox friction let the wheel slip at a speed in proportion to it: the
// fitted thesis drives (friction 0.68 N·m, a slave PI whose weak integral leaves a setpoint
// inside the band) crept 37 mm in 40 s. Dry friction now holds.
TEST_F(PlatformSimTest, ATorqueBelowTheGearFrictionDoesNotTurnTheWheel) {
  for (const double backlash : {0.0, 0.02772}) {
    SCOPED_TRACE(backlash);
    PlatformParams p = params(ModelVariant::rollers);
    p.motor.friction_torque = 0.6845;
    p.motor.backlash = backlash;
    PlatformSim s(p);
    // Setpoints of ±0.2 rad/s ask kv·0.2 = 0.4 N·m of a stalled motor, below the friction.
    const double before = s.wheel_angle(0);
    while (s.time() < 10.0) {
      for (int w = 0; w < 4; ++w) s.set_wheel_speed_setpoint(w, w % 2 == 0 ? (w < 2 ? 0.2 : -0.2) : 0.0);
      s.step();
    }
    EXPECT_LT(std::abs(s.wheel_angle(0) - before), 0.002);  // it crept 0.19 rad in 10 s
  }
}

// Found in review: with any backlash the wheel's hinge kept no armature, and the light wheel
// slipped on its rollers: the platform travelled 0.64 % less than its wheels' odometry said,
// whatever the gap (a rigid gearbox: +0.15 %), an error the master cannot see.
TEST_F(PlatformSimTest, BacklashDoesNotChangeHowFarTheWheelsCarryThePlatform) {
  const auto travel_ratio = [](double backlash) {
    PlatformParams p = params(ModelVariant::rollers);
    p.motor.backlash = backlash;
    PlatformSim s(p);
    const WheelVector w = wheel_speeds(Twist(0.15, 0, 0), 0.0, p.geometry.L, p.geometry.r);
    drive(s, w, 1.0);
    const double x0 = s.pose().x;
    WheelVector a0;
    for (int i = 0; i < 4; ++i) a0(i) = s.wheel_angle(i);
    drive(s, w, 4.0);
    WheelVector dq;
    for (int i = 0; i < 4; ++i) dq(i) = s.wheel_angle(i) - a0(i);
    return (s.pose().x - x0) / platform_twist(dq, 0.0, p.geometry.L, p.geometry.r).x();
  };
  const double rigid = travel_ratio(0.0);
  EXPECT_NEAR(travel_ratio(0.02772), rigid, 0.001);  // it was 0.008 short
  EXPECT_NEAR(travel_ratio(0.002), rigid, 0.001);
}

TEST_F(PlatformSimTest, EachDriversGainErrorScalesWhatItMakesOfItsSetpoint) {
  // driver.gain_error: wheel i's amplifier turns setpoint s into s·(1 + e_i); without the
  // electrical lag the first step's torque is kv times that, wheel by wheel.
  PlatformParams p = params(ModelVariant::rollers);
  p.motor.electrical_tau = 0.0;
  p.driver.gain_error = {0.1, 0.0, -0.2, 0.05};
  PlatformSim s(p);
  const double sp = 0.5;
  for (int w = 0; w < 4; ++w) ASSERT_TRUE(s.set_wheel_speed_setpoint(w, sp));
  s.step();
  for (int w = 0; w < 4; ++w)
    EXPECT_NEAR(s.wheel_torque(w), p.motor.kv * sp * (1.0 + p.driver.gain_error[static_cast<std::size_t>(w)]), 1e-9)
        << "wheel " << w + 1;
}

// Angle of a named hinge [rad].
double hinge_angle(const PlatformSim& s, const char* joint) {
  const int j = mj_name2id(s.model(), mjOBJ_JOINT, joint);
  EXPECT_GE(j, 0) << joint;
  return j >= 0 ? s.data()->qpos[s.model()->jnt_qposadr[j]] : 0.0;
}

TEST_F(PlatformSimTest, GearBacklashLetsTheRotorCrossTheGapBeforeTheWheelTurnsBack) {
  // motor.backlash 0.1 rad: the motor drives its own rotor, which pushes the wheel at one
  // flank of the gap (rotor − wheel = +0.05 rad driving forwards) and crosses to the other
  // flank (−0.05) when the setpoint reverses, while the wheel lags the reversal.
  PlatformParams p = params(ModelVariant::rollers);
  p.motor.backlash = 0.1;
  PlatformSim s(p);
  const int motor = mj_name2id(s.model(), mjOBJ_ACTUATOR, "motor1");
  ASSERT_GE(motor, 0);
  EXPECT_EQ(s.model()->actuator_trnid[2 * motor], mj_name2id(s.model(), mjOBJ_JOINT, "rotor1"));
  // The motor's armature has moved from the wheel's hinge to the rotor's, but for the
  // gearbox output stage's quarter, on the wheel's side of the play.
  const int wheel = mj_name2id(s.model(), mjOBJ_JOINT, "wheel1");
  const int rotor = mj_name2id(s.model(), mjOBJ_JOINT, "rotor1");
  EXPECT_DOUBLE_EQ(s.model()->dof_armature[s.model()->jnt_dofadr[wheel]], 0.25 * p.motor.armature);
  EXPECT_DOUBLE_EQ(s.model()->dof_armature[s.model()->jnt_dofadr[rotor]], 0.75 * p.motor.armature);
  const auto gap = [&] { return hinge_angle(s, "rotor1") - hinge_angle(s, "wheel1"); };
  while (s.time() < 0.5) {
    for (int w = 0; w < 4; ++w) s.set_wheel_speed_setpoint(w, w < 2 ? 2.0 : -2.0);
    s.step();
  }
  EXPECT_NEAR(gap(), 0.05, 0.01);
  EXPECT_GT(s.wheel_speed(0), 1.5);
  // Reverse: within a few steps the rotor is on its way back while the wheel still turns on.
  double wheel_at_flip = hinge_angle(s, "wheel1");
  for (int k = 0; k < 10; ++k) {
    for (int w = 0; w < 4; ++w) s.set_wheel_speed_setpoint(w, w < 2 ? -2.0 : 2.0);
    s.step();
  }
  EXPECT_LT(gap(), 0.04);
  EXPECT_GT(hinge_angle(s, "wheel1"), wheel_at_flip);  // the wheel has not turned back yet
  while (s.time() < 1.0) {
    for (int w = 0; w < 4; ++w) s.set_wheel_speed_setpoint(w, w < 2 ? -2.0 : 2.0);
    s.step();
  }
  EXPECT_NEAR(gap(), -0.05, 0.01);
  EXPECT_LT(s.wheel_speed(0), -1.5);
}

TEST_F(PlatformSimTest, ARigidGearboxHasNoRotorAndRollerFrictionReachesEveryRoller) {
  // backlash 0 (default): no rotor joints, the motor on the wheel; rollers.friction_torque
  // becomes every roller hinge's frictionloss.
  PlatformParams p = params(ModelVariant::rollers);
  p.rollers.friction_torque = 0.002;
  PlatformSim s(p);
  EXPECT_EQ(mj_name2id(s.model(), mjOBJ_JOINT, "rotor1"), -1);
  EXPECT_EQ(s.model()->ntendon, 0);
  const int motor = mj_name2id(s.model(), mjOBJ_ACTUATOR, "motor1");
  EXPECT_EQ(s.model()->actuator_trnid[2 * motor], mj_name2id(s.model(), mjOBJ_JOINT, "wheel1"));
  int rollers = 0;
  for (int j = 0; j < s.model()->njnt; ++j) {
    const char* name = mj_id2name(s.model(), mjOBJ_JOINT, j);
    if (name == nullptr || std::string(name).rfind("roller", 0) != 0) continue;
    EXPECT_DOUBLE_EQ(s.model()->dof_frictionloss[s.model()->jnt_dofadr[j]], 0.002) << name;
    ++rollers;
  }
  EXPECT_EQ(rollers, 4 * p.rollers.rows * p.rollers.per_row);
}

}  // namespace
}  // namespace omnitwin::physics
