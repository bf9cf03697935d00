// bus_emulators/drive — one CiA 402 servo axis (DESIGN §5 "servo drives"; facts/cia402.md):
// the objects of the drive profile, the power drive state machine (cia402_fsa), the modes
// PP/PV/TQ/HM (cia402_profile, cia402_homing) and CSP/CSV/CST, the drive's position loop →
// velocity loop (PI) → torque limit, following-error supervision, software position limits,
// polarity, digital inputs (limit/home switches), outputs and brake. Shared by every servo
// bus (EtherCAT CoE binds its object dictionary to Objects; CANopen, M-III map onto it).
//
// Pure computation: no sockets, no clock, no physics. Time comes in as SimTime [ns]; the
// load shaft's state comes in as Feedback (MuJoCo wheel joint or AxisModel); the drive's
// output to the physics is a Command: a velocity set-point in every mode except TQ/CST (the
// twin's wheel actuators are velocity servos), a torque in TQ/CST.
//
// Units: positions [counts] = motor revolutions × counts_per_rev (motor angle = load angle ×
// gear_ratio); velocities [counts/s], accelerations [counts/s²] (0x6080 max motor speed
// included); torques [0.1 % of rated_torque_nm] (motor side; Command/Feedback torques are on
// the load shaft: × gear_ratio). Polarity 0x607E: bit 7 negates position values (targets,
// actuals, limits), bit 6 velocity values (target/offset/actual velocity) and torques.
// Homing runs on the physical axis (the switches are wired to it) and sets the position
// offset so that position actual = home offset at the home position.
//
// Model choices (documented simplifications): transitions 5, 6/8 and 9 switch the power stage
// off at once (0x605B/0x605C "disable drive function"); the brake is released while the power
// stage is on (operation enabled, quick stop active, fault reaction active) so that stops
// decelerate on their ramp; "voltage limit" options act as "current limit"; the velocity PI
// yields the torque demand 0x6074 (and the torque limit sent with Command), the physics'
// velocity servo realises the velocity set-point; halt (controlword bit 8) acts in PP, PV, TQ
// and HM, the cyclic modes follow the master's set-points; homing starts on the rising edge
// of bit 4 and is not interrupted when bit 4 falls (seed 004: the master clears bit 4 as soon
// as the drive answered), halt interrupts it; software limits act on targets (PP, CSP) and as
// a braking curve at the quick stop deceleration on velocity set-points (PV, CSV) — homing and
// stops ignore them; modelled switch and index edges are latched exactly (touch-probe model),
// scenario inputs at the position of the period in which they change.
#pragma once

#include <cstdint>
#include <optional>

#include "bus_emulators/drive/cia402_fsa.hpp"
#include "bus_emulators/drive/cia402_homing.hpp"
#include "bus_emulators/drive/cia402_profile.hpp"

namespace omnitwin::drive {

using SimTime = std::int64_t;  // ns on the simulated timeline

enum class Mode : std::int8_t { none = 0, pp = 1, pv = 3, tq = 4, hm = 6, csp = 8, csv = 9, cst = 10 };
const char* to_string(Mode);

// 0x6502 bits (bit = mode − 1).
inline constexpr std::uint32_t mode_bit(Mode m) { return 1u << (static_cast<int>(m) - 1); }
inline constexpr std::uint32_t kAllModes = mode_bit(Mode::pp) | mode_bit(Mode::pv) |
                                           mode_bit(Mode::tq) | mode_bit(Mode::hm) |
                                           mode_bit(Mode::csp) | mode_bit(Mode::csv) |
                                           mode_bit(Mode::cst);

// Error codes 0x603F used by the drive.
inline constexpr std::uint16_t kErrorFollowing = 0x8611;   // following error
inline constexpr std::uint16_t kErrorExternal = 0x6320;    // raise_fault default (parameter/other)
// The CiA 301 error register (0x1001) class bit of an error code: current 0x02 (2xxx), voltage
// 0x04 (3xxx), temperature 0x08 (4xxx), device profile 0x20 (85xx/86xx), communication 0x10
// (other 8xxx), manufacturer 0x80 (FFxx), else 0 (the generic bit 0x01 is the caller's). Shared
// by the CANopen EMCY producer and the EtherCAT CoE emergency.
std::uint8_t error_class_bit(std::uint16_t code);

// The option codes this drive implements (the dictionaries refuse the others, cia402_od):
// quick stop 0x605A 0..8, halt 0x605D 1 and 2 (the two ramps: current and voltage limit are not
// modelled for halt), fault reaction 0x605E 0..4; no manufacturer-specific (negative) codes.
bool quick_stop_option_supported(int code) noexcept;
bool halt_option_supported(int code) noexcept;
bool fault_reaction_option_supported(int code) noexcept;

// The CiA 402 objects of one axis in their OD types and units (B binds the OD to these).
struct Objects {
  std::uint16_t controlword = 0;             // 0x6040
  std::uint16_t statusword = 0;              // 0x6041
  std::uint16_t error_code = 0;              // 0x603F
  std::int16_t quick_stop_option = 2, halt_option = 1, fault_reaction_option = 2;  // 0x605A 0x605D 0x605E
  std::int8_t mode = 0, mode_display = 0;    // 0x6060 0x6061
  std::int32_t position_demand = 0, position_actual = 0;  // 0x6062 0x6064 [counts]
  std::uint32_t following_error_window = 10000;  // 0x6065 [counts] (0xFFFFFFFF = off)
  std::uint16_t following_error_timeout = 10;    // 0x6066 [ms]
  std::uint32_t position_window = 10;            // 0x6067 [counts]
  std::uint16_t position_window_time = 0;        // 0x6068 [ms]
  std::int32_t velocity_demand = 0, velocity_actual = 0;  // 0x606B 0x606C [counts/s]
  std::uint16_t velocity_window = 100, velocity_window_time = 0, velocity_threshold = 10;  // 0x606D 0x606E 0x606F
  std::int16_t target_torque = 0;            // 0x6071 [0.1 %]
  std::uint16_t max_torque = 3000;           // 0x6072 [0.1 %]
  std::int16_t torque_demand = 0, torque_actual = 0;  // 0x6074 0x6077 [0.1 %]
  std::int32_t target_position = 0, home_offset = 0;  // 0x607A 0x607C [counts]
  std::int32_t sw_limit_min = 0, sw_limit_max = 0;    // 0x607D:1/:2 (both 0 = off)
  std::uint8_t polarity = 0;                 // 0x607E (bit 7 position, bit 6 velocity)
  std::uint32_t max_profile_velocity = 2000000;   // 0x607F [counts/s]
  std::uint32_t max_motor_speed = 2000000;        // 0x6080 [counts/s] (set from DriveConfig)
  std::uint32_t profile_velocity = 100000;        // 0x6081 [counts/s]
  std::uint32_t end_velocity = 0;                 // 0x6082 [counts/s]
  std::uint32_t profile_acceleration = 1000000;   // 0x6083 [counts/s²]
  std::uint32_t profile_deceleration = 1000000;   // 0x6084 [counts/s²]
  std::uint32_t quick_stop_deceleration = 4000000;  // 0x6085 [counts/s²]
  std::uint32_t torque_slope = 10000;             // 0x6087 [0.1 %/s]
  std::int8_t homing_method = 35;                 // 0x6098
  std::uint32_t homing_speed_switch = 20000, homing_speed_zero = 2000;  // 0x6099:1 :2 [counts/s]
  std::uint32_t homing_acceleration = 200000;     // 0x609A [counts/s²]
  std::int32_t velocity_offset = 0;               // 0x60B1 [counts/s]
  std::int16_t torque_offset = 0;                 // 0x60B2 [0.1 %]
  std::int32_t following_error_actual = 0;        // 0x60F4 [counts]
  std::uint32_t digital_inputs = 0;               // 0x60FD (bit 0 NL, 1 PL, 2 home)
  std::uint32_t digital_outputs = 0, digital_outputs_mask = 0;  // 0x60FE:1 :2 (bit 0 set brake)
  std::int32_t target_velocity = 0;               // 0x60FF [counts/s]
  std::uint32_t supported_modes = 0;              // 0x6502 (set from DriveConfig)
};

// Modelled switches on the load axis [rad]. Limit switches: NL active for position <=
// negative_limit, PL for position >= positive_limit. Home switch: active for position >= home
// (home_active_below: for position <= home); with home_end it is a cam, active for
// home <= position <= home_end.
struct Switches {
  std::optional<double> negative_limit, positive_limit, home;
  std::optional<double> home_end;
  bool home_active_below = false;
};

struct DriveConfig {
  double counts_per_rev = 10000;   // position units per motor revolution
  double gear_ratio = 1;           // motor revolutions per load revolution
  double rated_torque_nm = 1;      // motor, 100 % of 0x6071/0x6077 (1000 = 100 %)
  double max_speed_rad_s = 100;    // motor; initial 0x6080
  double period_s = 0.001;         // drive period (used for the first step)
  double pos_kp = 50;              // position loop [1/s]
  double vel_kp = 0.05, vel_ki = 1.0;  // velocity PI [Nm per motor rad/s], [Nm per motor rad]
  std::uint32_t supported_modes = kAllModes;
  Switches switches;
  double index_offset_rad = 0;     // index pulse phase on the motor shaft [rad]
  bool brake = true;               // a holding brake is fitted
  double homing_max_search_rev = 100;  // search travel before homing error [motor rev]
};

// The load shaft's state from the physics.
struct Feedback { double position_rad = 0, velocity_rad_s = 0, torque_nm = 0; };

// The drive's output to the physics (load shaft).
struct Command {
  double velocity_rad_s = 0;   // velocity set-point (torque_mode false)
  double torque_nm = 0;        // torque to apply (torque_mode); else the velocity PI's demand
  bool torque_mode = false;
  bool power = false;          // power stage on (no torque when false)
  bool brake_engaged = true;
  double torque_limit_nm = 0;  // 0x6072 on the load shaft: the servo must not exceed it
};

class Cia402Drive {
 public:
  explicit Cia402Drive(const DriveConfig& config);

  // The axis' objects: the bus writes set-points/parameters and reads actual values here.
  Objects& objects() { return obj_; }
  const Objects& objects() const { return obj_; }
  const DriveConfig& config() const { return cfg_; }

  // One drive period at t [ns]: FSA from the controlword, the active mode (profile
  // generators, homing, cyclic set-points), loops; statusword and actual values written back.
  // dt = t − previous t (config.period_s on the first step or when t does not advance).
  // RT-safe: no allocation, no throw.
  Command step(SimTime t, const Feedback& fb);

  State state() const { return fsa_.state(); }
  Mode mode() const { return active_mode_; }
  bool homed() const { return homed_; }

  // Scenario-driven inputs (bit 0 NL, 1 PL, 2 home), ORed with the modelled switches.
  void set_external_inputs(std::uint32_t bits) { external_inputs_ = bits; }
  void set_switches(const Switches& s) { cfg_.switches = s; }
  // A fault detected outside the drive core (bus watchdog, sync loss): transition 13 on the
  // next step with error code `code`.
  void raise_fault(std::uint16_t code = kErrorExternal) { pending_fault_ = code; }
  // Back to power-on: objects to their defaults, not ready to switch on, not homed.
  void power_cycle();

  // Diagnostics: transitions of the last step (fact sheet numbers), physical outputs 0x60FE
  // after masking (bit 0 = brake engaged), position offset from homing [counts].
  const std::uint8_t* last_transitions(int& count) const { return fsa_.last_transitions(count); }
  std::uint32_t physical_outputs() const { return physical_outputs_; }
  double position_offset() const { return offset_; }
  double counts_per_load_rad() const { return k_pos_; }

 private:
  void enter_mode(Mode m, double pos_phys, double vel_phys);
  std::uint16_t mode_bits(double dt);

  DriveConfig cfg_;
  Objects obj_;
  Fsa fsa_;
  Mode active_mode_ = Mode::none;
  ProfilePosition pp_;
  Homing homing_;
  Trapezoid hold_;           // stops, halts, holds (physical counts)
  double k_pos_ = 1;         // counts per load rad
  double offset_ = 0;        // user position = sign_p × physical + offset
  double prev_pos_ = 0;      // physical counts of the last step
  double pv_vel_ = 0;        // PV ramp state (physical counts/s)
  double tq_demand_ = 0;     // TQ ramp state (user 0.1 %)
  double vel_integral_ = 0;  // velocity PI integrator [Nm]
  double fe_time_ = 0, pos_window_time_ = 0, vel_window_time_ = 0;  // [s]
  double demand_pos_ = 0;    // physical position demand of the last period
  bool position_controlled_ = false;
  bool fe_exceeded_ = false, internal_limit_ = false, warning_ = false;
  bool stop_done_ = false;   // the quick stop / fault reaction stop finished (FSA event)
  bool hm_prev_start_ = false, homed_ = false;
  bool first_step_ = true, prev_nl_ = false, prev_pl_ = false, prev_home_ = false;
  bool prev_m_nl_ = false, prev_m_pl_ = false, prev_m_home_ = false;  // modelled switches
  bool demand_pos_valid_ = false, csp_first_ = true, stop_hold_ = false;
  double csp_prev_target_ = 0;   // the last CSP set-point [counts, physical]
  double csp_from_ = 0;          // where the interpolation towards it started
  double csp_demand_ = 0;        // the interpolated demand
  double csp_interval_ = 0;      // set-point interval being interpolated over [s]
  SimTime csp_change_t_ = 0;     // when the last set-point arrived
  double nl_edge_ = 0, pl_edge_ = 0, home_edge_ = 0;
  SimTime last_t_ = 0;
  std::uint32_t external_inputs_ = 0, physical_outputs_ = 0;
  std::uint16_t pending_fault_ = 0;
};

}  // namespace omnitwin::drive
