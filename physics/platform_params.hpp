// physics layer — the fixed description of one four-omniwheel platform (seed 002, ch. 4).
//
// Plain data, the mjModel of our own stack: everything here is fixed for a run and comes
// from one parameter file (models/platform/omni4.yaml) that scenarios may override key by
// key. Nothing in this header changes while a run steps; changing state lives elsewhere
// (PlatformSim for the physics, the drive-chain structs for the electronics).
// All quantities are SI unless the field name says otherwise.
#pragma once

#include <array>
#include <string>

namespace omnitwin::physics {

// Which MJCF the generator produces from the parameters.
enum class ModelVariant {
  rollers,  // passive capsule rollers on hinges: omni motion from contact alone (reference)
  capsule,  // the fast model: one short capsule per wheel + anisotropic-friction floor pair
};

struct GeometryParams {
  double L = 0.25;                                 // wheel-to-centre distance [m]
  double r = 0.05;                                 // wheel (outer roller envelope) radius [m]
  std::array<double, 3> chassis_size{0.30, 0.30, 0.08};  // full box extents [m]
  double chassis_mass = 12.0;                      // [kg]
  double hub_mass = 0.25;                          // per wheel [kg]
  double wheel_width = 0.04;                       // hub visual width [m]
  // Payload carried on the deck, a box centred on O_m resting on the chassis top. The thesis
  // ran its platform unloaded (4-4-2 "空載測試"), hence 0 (no load body at all).
  double load_mass = 0.0;                          // [kg], >= 0
  std::array<double, 3> load_size{0.25, 0.25, 0.10};  // full box extents [m]
};

struct RollerParams {
  int rows = 2;               // roller rows per wheel
  int per_row = 6;            // rollers in one row
  double row_offset = 0.011;  // ± offset of the rows along the axle [m]
  double row_phase_deg = 30;  // second row turned by this [deg] (half the roller pitch)
  double wheel_phase_deg = 3.75;  // extra phase from wheel to wheel so bumps do not line up
  double radius = 0.015;      // capsule radius [m]; axis sits at r - radius from the hub
  double coverage_deg = 15;   // capsule half-length = (r - radius)·tan(coverage/2)
  double mass = 0.01;         // per roller [kg]
  double damping = 0.0;       // hinge damping [N·m·s/rad]
  double friction_torque = 0.0;  // dry friction of each roller's bearing [N·m]: the rollers'
                                 // rolling resistance (0 = free rollers)
};

// The fast model (variant "capsule"): one short capsule per wheel stands for the whole roller
// ring. Its contact sits on the roller model's effective contact line, so both models turn the
// same wheel rotation into the same platform twist (docs/platform.md, "The fast model").
struct CapsuleParams {
  double half_length = 0.0005;  // along the axle [m]: short, so its two contacts coincide and
                                // do not scrub against each other when the platform turns
  double contact_offset = -0.001;  // contact line along the axle, + outward [m]: the roller
                                   // model's load-weighted harmonic contact radius is
                                   // L - 1.0 mm (its inner row carries more when turning)
  double solver_tolerance = 1e-5;  // MuJoCo Newton tolerance [-] (MuJoCo's default 1e-8)
  bool centre_contact = true;  // one contact per wheel at the capsule's centre instead of
                               // MuJoCo's two at its ends (physics/wheel_contact.hpp)
};

struct FloorParams {
  double friction = 0.9;        // sliding friction floor–roller (rolling direction for capsule)
  double lateral_friction = 0.001;  // capsule variant: friction along the axle
  double slip_gain = 1.0;       // scales `friction` (wheel-slip studies: < 1 slips sooner)
};

// Motor with its analog velocity-mode servo amplifier and gearbox, as seen at the wheel
// shaft (physics, not firmware). The amplifier closes a proportional velocity loop,
// torque = kv·(setpoint − ω), whose setpoint reaches the torque through one first-order lag
// of electrical_tau (armature L/R and the amplifier's current loop); with the wheel's
// reflected inertia J the loop's mechanical time constant is τm = J/kv (J ≈ armature plus
// the platform's share, ≈ 0.03 kg·m² here, so τm ≈ 15 ms at kv = 2). The gearbox adds dry
// friction (friction_torque) and lost motion (backlash).
struct MotorParams {
  double kv = 2.0;              // velocity-servo gain of the amplifier+motor [N·m·s/rad]
  double electrical_tau = 0.002;  // setpoint → torque lag [s]; 0 = none, else >= sim.timestep
  double torque_limit = 5.0;    // |torque| at the wheel [N·m]
  double speed_limit = 20.0;    // |speed setpoint| the amplifier accepts [rad/s]
  double armature = 0.02;       // reflected rotor inertia [kg·m²]
  double damping = 0.0;         // viscous friction in the wheel bearing [N·m·s/rad]
  double friction_torque = 0.0; // dry (Coulomb) friction of gearbox and bearing [N·m]
  // Gear backlash: the total play between the motor and the wheel, at the wheel [rad]; 0 = a
  // rigid gearbox. When > 0 the motor gets its own rotor (it carries the armature and the
  // gearbox friction) and drives the wheel through a gap of this width.
  double backlash = 0.0;
};

// Analog velocity driver input: speed setpoint = gain·(V − zero_volts), clamped, with an
// input dead band: |V − zero_volts| <= dead_band gives 0, beyond it the band is subtracted
// (the amplifier's input comparator / offset trim; 0 = an ideal input).
struct DriverParams {
  double zero_volts = 2.5;      // input voltage that means standstill [V]
  double gain = 8.0;            // [rad/s per V]
  double dead_band = 0.0;       // half-width of the input dead band [V], >= 0
  // Relative gain error of each wheel's amplifier [-], wheels 1..4: the physical speed is
  // setpoint·(1 + gain_error[i]) (component tolerance; 0 = four identical drivers). Applied
  // by the physics (PlatformSim), so every bus and master meets the same mismatched wheels.
  std::array<double, 4> gain_error{0.0, 0.0, 0.0, 0.0};
};

// 12-bit DA (AD7541 behind a TLC2274 buffer): V = D/4096 · vref, eq. 4-8.
struct DacParams {
  int bits = 12;
  double vref = 5.0;            // Out1 - Out2 [V]
};

// Incremental quadrature encoder on the wheel axle, decoded 4x by an HCTL-2032.
struct EncoderParams {
  int lines = 500;              // lines per revolution; counts per rev = 4·lines
  int index_per_rev = 1;        // index pulses per revolution
};

// How the slave's PI computes (firmware, not physics).
enum class LoopArithmetic {
  real,   // exact real arithmetic (an idealised controller)
  int16,  // the 8051's 16-bit signed integers: gains and the integral in whole codes, the
          // sum wraps at ±32768 (C on an 8051 does not saturate), then the DA clamps
};

// The slave's (8051) velocity loop: PI in counts per sample, output in DA codes.
struct VelocityLoopParams {
  double period = 0.010;        // nominal sample period of the slave timer [s]
  double kp = 20.0;             // [DA codes per (count/sample)]
  double ki = 4.0;              // [DA codes per (count/sample)·sample]
  double kff = 1.0;             // feed-forward scale on the ideal code for the command [-]
  LoopArithmetic arithmetic = LoopArithmetic::real;
};

struct SimParams {
  double timestep = 0.001;      // MuJoCo step [s]
  ModelVariant variant = ModelVariant::rollers;
  // A hand-written MJCF to use instead of the generated one (it must follow the naming
  // contract of platform_mjcf.hpp); empty = generate from these parameters. The drive
  // chain, encoder and controller geometry still come from the parameters.
  std::string mjcf;
};

struct PlatformParams {
  std::string source = "built-in defaults";  // file the values came from (for messages)
  GeometryParams geometry;
  RollerParams rollers;
  CapsuleParams capsule;
  FloorParams floor;
  MotorParams motor;
  DriverParams driver;
  DacParams dac;
  EncoderParams encoder;
  VelocityLoopParams velocity_loop;
  SimParams sim;

  int counts_per_rev() const { return 4 * encoder.lines; }
};

// Alpha_i of wheel i (0-based): 45°, 135°, 225°, 315° (seed 002, fig. 4-11) [rad].
double wheel_alpha(int wheel);

const char* to_string(ModelVariant v);

}  // namespace omnitwin::physics
