// bus_emulators/ethercat — distributed clocks of one ESC: a drifting local clock, the system
// time (local + offset 0x0920), the drift control loop and the SYNC0 cyclic unit.
//
// Local clock: local(t) = anchor_local + (t − anchor_t)·(1 + drift + correction), where drift is
// the oscillator's own error (e.g. ±50 ppm) and correction the control loop's speed adjustment.
// The clock is re-anchored whenever the correction changes, so it stays continuous and
// monotonic (the loop never steps the time, as on a real ESC).
//
// Drift control: each write of the reference clock's system time to 0x0910 (the master's FRMW)
// is a sample e = system(t) − (received + delay 0x0928). 0x092C shows |e| with bit 31 set when
// the local copy is smaller. The loop is a second-order (PI) rate control:
//   correction += −(Ki·e + Kp·(e − e_prev)) / h      (h: time since the previous sample)
// with Kp = 0.1, Ki = 0.005 (closed-loop poles ≈ 0.95 per sample: a 1 ms FRMW cycle settles in
// a few hundred ms, like a real ESC with its default speed-counter start) and the correction
// limited to ±1000 ppm. Writing 0x0930 (speed counter start) resets the loop (correction 0);
// writing the offset 0x0920 makes the next sample start afresh (no proportional kick). A constant
// oscillator drift is cancelled with no residual error (integral action).
//
// SYNC0: activation 0x0981 (bit 0 cyclic unit, bit 1 SYNC0) starts pulses at the start time
// 0x0990 (system time), then every cycle 0x09A0 ns (0 = a single pulse). Model choice: a start
// time already in the past starts at the next cycle boundary after now (a real ESC would wait
// for its 32-bit compare to wrap).
// SYNC1 (activation bit 2, with SYNC0 on): its cycle 0x09A4 counts from the SYNC0 pulses. With
// c1 < c0 (or 0) SYNC1 follows every SYNC0 pulse by c1; with c1 >= c0 it follows every n-th
// SYNC0 pulse (n = c1 / c0, the first pulse included) by c1 mod c0. 0x0998 holds the next
// SYNC1 time.
// Minimum SYNC0 cycle: kMinSyncCycleNs = 10 µs. Model choice, a conservative value: no ESC
// datasheet or ETG minimum was verified when this was written (the slave stack's
// MIN_PD_CYCLE_TIME is device specific); a non-zero cycle below it is an invalid
// SYNC configuration — the cyclic unit stays off (no pulses, activation status 0) and
// sync0_invalid() says so; the firmware answers a request for SAFE-OP/OP with AL status code
// 0x0030 (invalid DC SYNC configuration).
//
// Arithmetic: local, system and sample times are 64-bit registers on the ESC and wrap modulo
// 2^64; the model computes them in unsigned arithmetic (never signed overflow) and the control
// loop's correction saturates at ±kMaxCorrection.
#pragma once

#include <cstdint>

#include "bus_emulators/ethercat/ec_frame.hpp"

namespace omnitwin::ethercat {

class DcClock {
 public:
  static constexpr double kKp = 0.1;
  static constexpr double kKi = 0.005;
  static constexpr double kMaxCorrection = 1e-3;
  static constexpr std::uint32_t kMinSyncCycleNs = 10'000;  // see the header comment
  // sim_time_of_system() answers at most ±this (a system time beyond the sim time range).
  static constexpr SimTime kSimTimeLimit = static_cast<SimTime>(1) << 61;

  DcClock(double drift = 0, std::int64_t local_at_start = 0, SimTime start = 0);

  void reset(SimTime t);                        // power on at t: local time restarts
  void set_drift(double drift, SimTime t);      // the oscillator changes at t (clock continuous)
  double drift() const { return drift_; }
  std::int64_t local(SimTime t) const;          // [ns]
  std::int64_t system(SimTime t) const;  // local + offset, modulo 2^64
  SimTime sim_time_of_system(std::int64_t system_time) const;  // inverse of system()

  void set_offset(std::uint64_t o);  // also forgets the previous sample
  std::uint64_t offset() const { return offset_; }
  void set_delay(std::uint32_t d) { delay_ = d; }
  std::uint32_t delay() const { return delay_; }

  // A reference-time sample (write to 0x0910) arriving at t; wide: 64-bit write, else the low
  // 32 bits are compared. Real-time safe.
  void sample(std::uint64_t received, bool wide, SimTime t);
  void reset_loop(SimTime t);  // speed-counter start written: correction 0, no previous sample
  std::int64_t last_difference() const { return diff_; }  // e [ns]
  std::uint32_t difference_register() const;               // 0x092C
  double correction() const { return corr_; }

  // SYNC0.
  void configure_sync(std::uint8_t activation, std::uint64_t start, std::uint32_t cycle0, SimTime t);
  bool sync0_active() const { return sync0_active_; }
  // SYNC0 was requested (activation bits 0 and 1) with a cycle below kMinSyncCycleNs: refused.
  bool sync0_invalid() const { return sync0_invalid_; }
  std::uint64_t next_sync0() const { return next_sync0_; }  // system time
  std::uint32_t sync0_cycle() const { return cycle0_; }
  // Next pulse due at or before t: its sim time; advances the schedule. false when none.
  bool pop_sync0(SimTime t, SimTime& when);
  // Drops the pulses due at or before t: the schedule moves on to the first one after t.
  void skip_sync0_to(SimTime t);

  // SYNC1 (see the header comment); configure after configure_sync. pop_sync1 gives the next
  // pulse due at or before t; next_sync1 its system time (0 when none is scheduled).
  void configure_sync1(bool active, std::uint32_t cycle1);
  bool sync1_active() const { return sync1_active_ && sync0_active_; }
  bool pop_sync1(SimTime t, SimTime& when);
  std::uint64_t next_sync1() const { return sync1_pending_ ? next_sync1_ : 0; }

 private:
  void reanchor(SimTime t);

  double drift_;
  std::int64_t local_at_start_;
  SimTime anchor_t_ = 0;
  std::int64_t anchor_local_ = 0;
  double rate_ = 1.0;
  double corr_ = 0;
  std::uint64_t offset_ = 0;
  std::uint32_t delay_ = 0;
  std::int64_t diff_ = 0;
  std::int64_t prev_diff_ = 0;
  SimTime prev_sample_t_ = 0;
  bool have_prev_ = false;
  bool sync0_active_ = false;
  bool sync0_invalid_ = false;
  std::uint64_t next_sync0_ = 0;
  std::uint32_t cycle0_ = 0;
  // SYNC1: armed by each SYNC0 pulse whose count is a multiple of every_.
  void arm_sync1(std::uint64_t sync0_time);
  bool sync1_active_ = false;
  bool sync1_pending_ = false;
  std::uint32_t cycle1_ = 0;
  std::uint64_t sync1_every_ = 1;    // SYNC0 pulses per SYNC1 pulse
  std::uint64_t sync1_shift_ = 0;    // after the SYNC0 pulse [ns]
  std::uint64_t sync0_count_ = 0;    // SYNC0 pulses since activation
  std::uint64_t next_sync1_ = 0;     // system time
};

}  // namespace omnitwin::ethercat
