// The thesis slave's firmware and board, emulated (seed 002, §4-3; DESIGN §5).
//
// One wheel of the thesis platform is driven by an 8051 slave: it reads an HCTL-2032
// quadrature counter, runs a velocity PI in counts per sample and writes a 12-bit DA (AD7541,
// eq. 4-8). This is the node's side of the line between node and physics, and it ends at the
// DA's output voltage: the analog amplifier that takes that voltage (physics/amplifier.hpp),
// the motor and the wheel are physics (PlatformSim::set_wheel_amplifier_input). It lives in
// physics/ beside the parameters it shares with the plant, and because bus `direct` runs it
// without a network; bus `can` runs it inside the emulated node (bus_emulators/omni/). Pure
// computation (no MuJoCo): every piece takes its fixed configuration from platform_params.hpp
// and keeps only changing state; nothing allocates.
#pragma once

#include <cstdint>

#include "physics/platform_params.hpp"

namespace omnitwin::physics {

// ---- DA converter -----------------------------------------------------------------------------

// Largest DA code, 2^bits − 1 (4095 for 12 bits). Real-time safe.
int dac_max_code(const DacParams& dac);

// Clamps a (possibly fractional) code to [0, 2^bits − 1], rounding to nearest. Real-time safe.
int dac_clamp_code(const DacParams& dac, double code);

// DA output voltage for a code, eq. 4-8: V = D/2^bits · vref [V]; code clamped first.
// Real-time safe.
double dac_volts(const DacParams& dac, int code);

// ---- HCTL-2032 style quadrature counter ----------------------------------------------------

// Wrap-safe difference now − before of two 32-bit counter readings [counts]: correct as long
// as the true change fits in int32 (it is the modular difference). Real-time safe.
inline int32_t counter_delta(int32_t now, int32_t before) {
  return static_cast<int32_t>(static_cast<uint32_t>(now) - static_cast<uint32_t>(before));
}

// Follows the wheel shaft angle and counts like an HCTL-2032 in 4x mode with a 32-bit
// up/down counter. Edges sit at fixed shaft angles k·2π/cpr, so
//   count = floor(θ·cpr/2π) − floor(θ_reset·cpr/2π) + preset   (mod 2^32, two's complement)
// which is floor(θ·cpr/2π) when reset at θ = 0. Index pulses sit at shaft angles
// k·2π/index_per_rev; each crossing (either direction) counts one index event and latches
// the count of the index position itself, floor(θ_k·cpr/2π) on the same scale, so the
// latch does not depend on the direction of travel (homing reference).
// update() may be called at any rate; all methods are real-time safe.
class QuadratureCounter {
 public:
  // cpr = 4·lines. Starts with count 0 at shaft angle `angle` [rad].
  explicit QuadratureCounter(const EncoderParams& encoder, double angle = 0.0);

  // Samples the shaft angle [rad] (the A/B/index lines at this instant).
  void update(double angle);
  // The chip's RST: count becomes 0 at the current shaft position; index latch cleared.
  void reset();
  // Simulation aid (not on the chip): make the current count read `count` (e.g. near the wrap).
  void preset(int32_t count);

  int32_t count() const;                          // the 32-bit counter [counts]
  int counts_per_rev() const { return cpr_; }     // 4·lines
  int64_t index_events() const { return index_events_; }  // index crossings since reset
  bool index_latched() const { return index_latched_; }   // any index seen since reset
  int32_t index_count() const { return index_count_; }    // count at the last index [counts]
  double angle() const { return angle_; }         // last sampled shaft angle [rad]

 private:
  int64_t edge_of(double angle) const;   // floor(θ·cpr/2π)
  int64_t index_of(double angle) const;  // floor(θ·index_per_rev/2π)
  int32_t wrap(int64_t edge) const;      // edge index → counter reading

  int cpr_;
  int index_per_rev_;
  double angle_;
  int64_t edge_;            // edge index of the last sampled angle
  int64_t edge_ref_;        // edge index that reads as `preset_`
  uint32_t preset_ = 0;     // reading at edge_ref_
  int64_t index_region_;    // index_of(angle_)
  int64_t index_events_ = 0;
  bool index_latched_ = false;
  int32_t index_count_ = 0;
};

// ---- the 8051's velocity PI ----------------------------------------------------------------

// Velocity PI of the thesis slave at its own sample period, in counts per sample.
// Units: command c and measured delta [counts/sample]; error e = c − delta [counts/sample];
// output a DA code [0, 2^bits − 1]:
//   code = zero_code + kff·(ideal_code(c) − zero_code) + kp·e + I,   I += ki·e each sample
// where zero_code is the code for the driver's zero_volts and ideal_code(c) the (fractional)
// code whose driver setpoint equals c·2π/cpr/period [rad/s]. (With kff = 1 this is
// ideal_code(c) + kp·e + I; the offset is kept out of the kff scaling so kff ≠ 1 scales the
// speed, not the standstill voltage.) Anti-windup by conditional integration: the integral is
// not advanced when the output is saturated and the error pushes further into the limit.
// With arithmetic = int16 the firmware's integer version runs instead (step_int16).
class VelocityLoop {
 public:
  VelocityLoop(const VelocityLoopParams& loop, const DacParams& dac, const DriverParams& driver,
               int counts_per_rev);

  // One sample: command and measured delta [counts/sample] → DA code. Real-time safe.
  int step(double command_counts_per_sample, double measured_counts_per_sample);
  // Clears the integral. Real-time safe.
  void reset();

  // Fractional DA code whose driver setpoint is c [counts/sample] as a speed. Real-time safe.
  double ideal_code(double command_counts_per_sample) const;
  double zero_code() const { return zero_code_; }   // code for zero speed (unclamped)
  double integral() const { return integral_; }     // I [codes]
  bool saturated() const { return saturated_; }     // last output hit a DA limit

 private:
  // The same law in the 8051's 16-bit integers (LoopArithmetic::int16): whole counts, whole
  // codes, every sum wrapping at ±32768, no anti-windup; the DA clamps. Real-time safe.
  int step_int16(double command_counts_per_sample, double measured_counts_per_sample);

  VelocityLoopParams loop_;
  DacParams dac_;
  double codes_per_count_per_sample_;  // d(code)/d(c) of the ideal mapping
  double zero_code_;
  double integral_ = 0.0;
  bool saturated_ = false;
};

// ---- one wheel's node: counter + loop + DA ------------------------------------------------------

// What one slave sample produced, kept for logging.
struct WheelDriveSample {
  int32_t count = 0;           // counter reading at this sample [counts]
  int32_t delta_counts = 0;    // measured speed [counts/sample]
  double command = 0.0;        // velocity command [counts/sample]
  int code = 0;                // DA code written
  double volts = 0.0;          // DA output [V]: the amplifier's input
};

// The thesis slave of one wheel, from the encoder's lines to the DA's pin. The twin calls
// observe() whenever it likes (e.g. every physics step, so index crossings are seen) and
// sample() at the slave's period, and hands the DA voltage to physics.
class WheelDriveChain {
 public:
  // Counter starts at 0 at `shaft_angle` [rad]; the DA starts at its zero code.
  explicit WheelDriveChain(const PlatformParams& params, double shaft_angle = 0.0);

  // Feeds the shaft angle [rad] to the counter between samples. Real-time safe.
  void observe(double shaft_angle);
  // One slave sample at shaft angle [rad] with a command [counts/sample]; returns the new DA
  // output [V] (held until the next sample). Real-time safe.
  double sample(double shaft_angle, double command_counts_per_sample);
  // Counter RST at the current angle, PI cleared, output back to the zero code.
  void reset();

  const WheelDriveSample& last() const { return last_; }
  double volts() const { return last_.volts; }  // DA output [V]
  const QuadratureCounter& counter() const { return counter_; }
  QuadratureCounter& counter() { return counter_; }
  const VelocityLoop& loop() const { return loop_; }

 private:
  void write_code(int code);  // DA code → volts into last_

  DacParams dac_;
  QuadratureCounter counter_;
  VelocityLoop loop_;
  int32_t previous_count_ = 0;
  WheelDriveSample last_;
};

}  // namespace omnitwin::physics
