// bus_emulators/omni — one 8051 wheel node of the thesis platform (seed 002, fig. 4-16,
// sections 2-2-1/2-2-3 dropout experiments, 3-2-2 synchronisation, 4-4-1 protocol).
//
// The slave program as the twin sees it: frames arrive from the bus through an SJA1000
// receive model (acceptance filter, 64-byte FIFO, INT line → the receive interrupt), the
// timer interrupt on the node's own drifting oscillator runs the velocity loop of the wheel
// node (counter + PI + DA, physics/drive_chain.hpp: the DA's voltage is where physics takes
// over, PlatformSim::set_wheel_amplifier_input) and sends the speed
// feedback when a new command has arrived since the last step (fig. 4-16; an interrupt that
// finds none skips the loop: the DA holds its output, no feedback goes out, and the next step's
// counter reading spans both periods), and the optional synchronisation of 3-2-2 switches every
// N timer interrupts to event-driven reception (timer off, next command's receive interrupt
// zeroes the timer count as it takes the frame, T_post after the arrival — seed 002 l.962, the
// timing the can-dropout experiment's TestSlave uses — and runs the step). Frames are
// decoded/encoded only through the Omni codec.
//
// Protocol core: no sockets, no wall clock, no globals. Time comes in as integer ns; frames
// go out through a callback with their send time (now + T_post); the timer is owned by the
// caller (the twin's scheduler), to which every input returns a TimerAction. Fixed
// configuration (OmniSlaveConfig) is kept apart from changing state. Nothing allocates after
// construction (the send callback is the caller's); bad input is counted, never thrown.
#pragma once

#include <cstdint>
#include <functional>
#include <utility>

#include "bus_emulators/can/can_frame.hpp"
#include "bus_emulators/can/sja1000.hpp"
#include "bus_emulators/omni/omni_codec.hpp"
#include "physics/drive_chain.hpp"
#include "physics/platform_params.hpp"

namespace omnitwin::omni {

// The SJA1000 acceptance filter a slave needs (dual-filter mode, standard frames):
//  filter 1: identifiers 0x000 and 0x102, data or remote (NMT, detection request, the speed
//            command); its don't-care bits (ID bits 8 and 1) also pass 0x002 and 0x100,
//            which the slave then ignores (the master's detection answer is 0x002 remote);
//  filter 2: 0x700 | node_id, data frames only (parameter set-up to this node).
// Everything else (feedback of the other axes, parameters of other nodes, 0x702) is dropped
// by the chip. Real-time safe.
can::Sja1000Config slave_filter(std::uint8_t node_id);

// A timer interrupt without a new command since the previous step:
//  skip — fig. 4-16: no velocity loop, no feedback; the DA holds its last output;
//  hold — the loop runs again with the held command and the feedback goes out.
enum class MissingCommand : std::uint8_t { skip, hold };
const char* to_string(MissingCommand m);  // "skip" / "hold"

// Fixed configuration of one slave. Build it with make_slave_config() or fill it by hand;
// OmniSlave's constructor checks it (validate_slave_config()).
struct OmniSlaveConfig {
  std::uint8_t node_id = node::axis1;  // 0x04 / 0x08 / 0x10 / 0x20
  int axis = 1;                        // 1..4, must be axis_of_slave(node_id)
  // Drive chain of this wheel. velocity_loop.period is the period the PI's speed scaling
  // assumes; it should equal timer_period_ns (make_slave_config() keeps them equal).
  physics::PlatformParams params;
  can::Sja1000Config filter = slave_filter(node::axis1);
  std::int64_t timer_period_ns = 10'000'000;  // nominal sample period of the timer [ns], > 0
  // Oscillator drift of this node [-]: its timer really fires every
  // timer_period_ns·(1 + drift). Default: the thesis's measured 0.362 % (fig. 2-13 … 2-16).
  // The twin schedules the timer with it (Scheduler::add_periodic(…, drift)). > -1.
  double drift = 3.62e-3;
  // What a timer interrupt that finds no new command does (fig. 4-16 skips; the other is the
  // common firmware that keeps using the last command). Either way the next step's counter
  // reading spans every period since the last step, so a skipped loop sees a doubled count.
  MissingCommand missing_command = MissingCommand::skip;
  bool sync_enabled = false;  // synchronisation of 3-2-2
  int sync_interval = 20;     // timer interrupts between forced resyncs, >= 1 when enabled
  std::int64_t t_post_ns = 88'800;  // processing delay before a frame is sent [ns], table 2-1, >= 0
  // Run time of the interrupt routine that runs the control step [ns], >= 0 and below the
  // timer period. 0: the timer reloads in hardware, so its period does not depend on the
  // routine, and the feedback leaves T_post after the interrupt. > 0: the firmware reloads
  // the timer in software at the routine's end (an 8051 in 16-bit timer mode has no
  // auto-reload), so a sample that ran the control step is followed by the next interrupt
  // this much more than a period later, and the feedback leaves at the routine's end; an
  // interrupt that skips the step ends after T_post. The resync's receive interrupt zeroes the
  // count as it takes the command, T_post after the arrival, before its routine (l.962: "zeroes
  // the timer count on reception"), so the next interrupt comes a period after that, not after
  // the routine. Seed 002 gives no value: fig. 4-20 shows the four feedback frames 3.1 … 3.5 ms
  // after the command.
  std::int64_t isr_ns = 0;
  // Where the node's timer stands when NMT start enables it [ns], >= 0: the first interrupt
  // comes start_phase_ns later than one period after the start frame's receive interrupt.
  // The thesis's slave handles NMT in its main loop (fig. 4-16), so each node's phase against
  // the master's ticks is its own; 0 puts every node at the same phase.
  std::int64_t start_phase_ns = 0;
};

// A config for slave `node_id` driving a wheel with `params`: axis from the node, the
// slave_filter(), timer period from params.velocity_loop.period (rounded to ns), default
// drift/T_post, sync off. Not real-time safe (copies strings).
OmniSlaveConfig make_slave_config(std::uint8_t node_id, const physics::PlatformParams& params);

enum class SlaveConfigError : std::uint8_t {
  ok,
  bad_node,      // node_id is not one of the four slaves
  axis_mismatch, // axis != axis_of_slave(node_id)
  bad_period,    // timer_period_ns <= 0
  bad_drift,     // drift <= -1 or not finite
  bad_sync,      // sync_enabled with sync_interval < 1
  bad_t_post,    // t_post_ns < 0
  bad_start_phase,  // start_phase_ns < 0
  bad_isr,       // isr_ns < 0 or not below timer_period_ns
};
const char* to_string(SlaveConfigError e);  // stable lowercase name, never nullptr
SlaveConfigError validate_slave_config(const OmniSlaveConfig& c);

// What the caller must do with the slave's timer after an input (the twin maps it onto its
// Scheduler): stop → cancel(timer); restart → restart(timer, first_ns), i.e. the timer count
// starts from zero and its next interrupt is at first_ns, then every period·(1 + drift).
enum class TimerRequest : std::uint8_t { none, stop, restart };
struct TimerAction {
  TimerRequest request = TimerRequest::none;
  std::int64_t first_ns = 0;  // restart only: time of the next timer interrupt [ns]
  bool operator==(const TimerAction&) const = default;
};

// Node states (4-4-1 "started / stopped", plus the event-driven phase of 3-2-2) and what is
// legal in each:
//  stopped       — after construction and after NMT stop. Answers detection requests; accepts
//                  parameter set-up; ignores speed commands; the timer is off (a timer
//                  interrupt is answered with stop); sends no feedback; setpoint = zero code.
//  running       — after NMT start. Timer-driven: each timer interrupt that finds a new
//                  command runs one control step with it and sends the feedback (one that
//                  finds none skips the step); commands are stored for the next interrupt;
//                  parameter frames are refused (counted); detection answered.
//  sync_pending  — isr_ns > 0 only: the sync_interval-th timer interrupt's routine is still
//                  running; the firmware switches to the receive interrupt when it ends (l.1366:
//                  "after the control flow"), so a speed command arriving now is only stored;
//                  the timer fires once more at the routine's end (routine_end). Detection
//                  answered, parameters refused.
//  awaiting_sync — sync enabled, after the sync_interval-th timer interrupt (and its routine):
//                  the timer is off; the next speed command zeroes the timer count T_post after
//                  its arrival and runs the control step in the receive interrupt (→ running).
//                  Detection answered, parameters refused.
// NMT stop is legal in running, sync_pending and awaiting_sync; NMT start only in stopped (a
// start to a started node changes nothing).
enum class SlaveState : std::uint8_t { stopped, running, sync_pending, awaiting_sync };
const char* to_string(SlaveState s);

// The named transitions of the state machine (see SlaveState). One flat switch executes them.
enum class SlaveTransition : std::uint8_t {
  start,         // stopped → running: chain reset, run indices cleared, timer restart when the
                 // receive interrupt ends, at its start phase: now + T_post + phase + period
  stop,          // running | sync_pending | awaiting_sync → stopped: timer stop, chain reset (zero setpoint)
  timer_sample,  // running → running: control step + feedback in the timer interrupt (skipped
                 // without a new command)
  enter_sync,    // running → awaiting_sync: as timer_sample, then timer stop; with isr_ns > 0
                 // and a step that ran: → sync_pending, the timer restarted for the routine's
                 // end (now + isr_ns)
  routine_end,   // sync_pending → awaiting_sync (timer stop), or, when a command arrived
                 // during the routine, its pending receive interrupt runs event_sample at once
  event_sample,  // awaiting_sync → running: control step + feedback in the receive interrupt,
                 // timer restart when it ends: now + T_post (isr_ns when > 0) + period (resync)
};
const char* to_string(SlaveTransition t);

// Counters since construction (or reset_statistics()). "Run" = since the last NMT start.
struct OmniSlaveStats {
  // Frames handed to on_frame() and what became of them. received = accepted + filtered +
  // overrun + invalid; accepted = handled + ignored + decode_errors.
  std::uint64_t frames_received = 0;
  std::uint64_t frames_accepted = 0;  // stored by the SJA1000 and read by the receive interrupt
  std::uint64_t frames_filtered = 0;  // dropped by the acceptance filter
  std::uint64_t frames_overrun = 0;   // lost in the SJA1000 FIFO (data overrun)
  std::uint64_t frames_invalid = 0;   // error frames / out-of-range id or DLC (never stored)
  std::uint64_t decode_errors = 0;    // accepted but not a valid Omni frame (codec error)
  std::uint64_t bad_frames = 0;       // frames_invalid + decode_errors
  std::uint64_t frames_handled = 0;   // valid and acted upon
  std::uint64_t frames_ignored = 0;   // valid Omni but not for this node / this state
  OmniError last_decode_error = OmniError::not_omni;  // meaningful when decode_errors > 0

  std::uint64_t commands = 0;             // speed commands taken (running/awaiting_sync)
  std::uint64_t commands_overwritten = 0; // replaced by the next before any sample used them
  std::uint64_t parameters_set = 0;       // parameter frames applied
  std::uint64_t parameters_refused = 0;   // parameter frames while started (also in ignored)
  std::uint64_t parameters_unknown = 0;   // unknown data type (also in ignored)

  // Control steps. samples = timer_samples + event_samples = N of eq. 2-2/2-3.
  std::uint64_t samples = 0;
  std::uint64_t timer_samples = 0;
  std::uint64_t event_samples = 0;  // = resyncs
  std::uint64_t resyncs = 0;
  // Dropout (2-2-1): the command held at a sample does not belong to that sample, i.e. the
  // number of commands received in this run differs from the sample's number in this run.
  std::uint64_t dropouts = 0;
  // Timer interrupts that found no new command since the previous step: the velocity loop and
  // the feedback were skipped (fig. 4-16). They still count as samples for the dropout rule.
  std::uint64_t stale_samples = 0;
  // With MissingCommand::hold: timer interrupts that found no new command and ran the loop
  // again with the held one (they send feedback; not in stale_samples).
  std::uint64_t held_samples = 0;
  // 0-based index (in `samples`) of the first dropout, i.e. the number of samples run before
  // it; -1 while there has been none. With pure clock drift every later sample is a dropout
  // too, and then this equals n_drift_eq23().
  std::int64_t first_dropout_sample = -1;
  // Timer interrupts that arrived while the timer should have been off (stopped or
  // awaiting_sync); answered with stop, no sample.
  std::uint64_t spurious_timer_interrupts = 0;
  std::uint64_t illegal_transitions = 0;  // never expected; a transition asked in a wrong state

  std::uint64_t frames_sent = 0;
  std::uint64_t feedback_sent = 0;
  std::uint64_t detection_answers = 0;

  // Control steps that ran (velocity loop + feedback) [-].
  std::uint64_t steps() const { return samples - stale_samples; }
  // eq. 2-3 as the thesis writes it: N_drift = N − N_dropout [samples].
  std::int64_t n_drift_eq23() const {
    return static_cast<std::int64_t>(samples) - static_cast<std::int64_t>(dropouts);
  }
  // eq. 2-2: p = N_dropout / N · 100 [%]; 0 when no sample ran.
  double dropout_percent() const {
    return samples == 0 ? 0.0 : 100.0 * static_cast<double>(dropouts) / static_cast<double>(samples);
  }
};

class OmniSlave {
 public:
  // The frame and the time it leaves the controller [ns] (= the input's now + T_post).
  using SendFn = std::function<void(const can::Frame&, std::int64_t send_time_ns)>;

  // Throws std::invalid_argument when validate_slave_config() fails (set-up code only).
  // The counter starts at 0 at `shaft_angle` [rad]. Not real-time safe.
  explicit OmniSlave(const OmniSlaveConfig& config, SendFn send = {}, double shaft_angle = 0.0);

  // Set-up only (not real-time safe).
  void set_send(SendFn send) { send_ = std::move(send); }

  // A frame completed on the bus at now_ns [ns]: SJA1000 filter + FIFO, then (INT line active)
  // the receive interrupt drains the FIFO and handles each message:
  //  - NMT (0x000 data) with target 0 or this node: start / stop (see SlaveTransition);
  //  - detection request (0x000 remote): answers a remote frame with ID = node_id, DLC 0;
  //  - speed command (0x102): takes axis[axis-1] [counts/sample] (in awaiting_sync: runs the
  //    event-driven step now, using the last observe()d shaft angle, and asks for a restart; in
  //    sync_pending: stored, its step runs at the routine's end);
  //  - parameter set-up to this node, stopped only: type 0x01 (axis_controller_setting) sets
  //    the velocity PI's kp = value / 100 [DA codes per count/sample] (fig. 4-19's 100 →
  //    kp 1.00); the drive chain is rebuilt with it (counter restarts at 0);
  //  - anything else is counted (ignored / decode_errors / invalid), never thrown.
  // Real-time safe (apart from what the send callback does).
  TimerAction on_frame(const can::Frame& frame, std::int64_t now_ns);

  // The timer interrupt at now_ns [ns] with the wheel shaft angle [rad] at that instant.
  // running: one sample (timer_sample, or enter_sync on every sync_interval-th interrupt
  // since the last (re)start when sync is on → stop). It is a dropout when the command count
  // of the run differs from the sample's number in the run. With a new command since the last
  // step it runs the control step and sends the speed feedback (counts since the last step) at
  // now + T_post; without one it skips both (stale_samples), the DA holding its output.
  // sync_pending: the routine's end (routine_end). stopped / awaiting_sync: no step, returns
  // stop. Real-time safe.
  TimerAction on_timer(std::int64_t now_ns, double shaft_angle_rad);

  // Feeds the shaft angle [rad] to the quadrature counter between samples (call it every
  // physics step; the event-driven step uses the last angle seen here). Real-time safe.
  void observe(double shaft_angle_rad) { chain_.observe(shaft_angle_rad); }

  // The DA's output [V], the amplifier's input, held between samples. Real-time safe.
  double da_volts() const { return chain_.volts(); }

  SlaveState state() const { return state_; }
  bool started() const { return state_ != SlaveState::stopped; }
  bool waiting_for_sync() const { return state_ == SlaveState::awaiting_sync; }
  // The command held [counts/sample] and whether it arrived since the last step.
  std::int8_t command() const { return command_; }
  bool command_is_new() const { return command_new_; }
  // The velocity-loop parameters in force (config's, changed by parameter frames).
  const physics::VelocityLoopParams& velocity_loop() const { return params_.velocity_loop; }
  const physics::WheelDriveChain& drive_chain() const { return chain_; }
  const can::Sja1000& controller() const { return sja_; }
  const OmniSlaveConfig& config() const { return config_; }
  const OmniSlaveStats& stats() const { return stats_; }
  void reset_statistics() { stats_ = OmniSlaveStats{}; }
  // A power-on reset that keeps the node's counts (the twin's power_loss fault): the counters
  // go on from these.
  void carry_statistics(const OmniSlaveStats& s) { stats_ = s; }

  // The real timer period of this node, round(timer_period_ns·(1 + drift)) [ns].
  std::int64_t actual_period_ns() const { return actual_period_ns_; }
  // The oscillator's drift [-] in force: config().drift until set_drift() changes it.
  double drift() const { return drift_; }
  // The oscillator drifts differently from now on (a drift fault): later timer restarts ask
  // for periods of timer_period_ns·(1 + drift). The caller's timer must change with it.
  // Returns false and changes nothing unless drift is finite and > -1. Real-time safe.
  bool set_drift(double drift);

 private:
  TimerAction transition(SlaveTransition t, std::int64_t now_ns, double shaft_angle_rad);
  TimerAction handle(const Message& m, std::int64_t now_ns);
  // One sample; false when it was skipped (no new command, MissingCommand::skip).
  bool control_step(std::int64_t now_ns, double shaft_angle_rad);
  // From the interrupt to the end of a control step's routine [ns]: isr_ns, else T_post.
  std::int64_t step_delay_ns() const;
  void send(const can::Frame& f, std::int64_t now_ns);
  void rebuild_chain();

  OmniSlaveConfig config_;
  double drift_;                  // oscillator drift in force [-]
  std::int64_t actual_period_ns_;  // round(timer_period_ns·(1 + drift_)) [ns]
  SendFn send_;
  can::Sja1000 sja_;
  physics::PlatformParams params_;  // config's, with parameter frames applied
  physics::WheelDriveChain chain_;

  SlaveState state_ = SlaveState::stopped;
  std::int8_t command_ = 0;      // held command [counts/sample]
  bool command_new_ = false;     // arrived since the last step
  std::int64_t run_commands_ = 0;  // commands received since NMT start
  std::int64_t run_samples_ = 0;   // the number of the current sample in the run (1-based)
  int timer_since_restart_ = 0;    // timer interrupts since the timer was (re)started
  OmniSlaveStats stats_;
};

}  // namespace omnitwin::omni
