// controller layer — the thesis's Omni master program (seed 002, fig. 4-15; 4-4-1) as a
// protocol core (docs/protocols/omni-master.md).
//
// The DSP master of the platform, cut at its two interrupts so that any clock and any
// transport can drive it: on_tick() is the timer interrupt (motion planning, the broadcast of
// the four axis commands, node detection between two samples, the watchdogs), on_frame() is
// the eCAN receive interrupt (PC commands and parameters, detection answers, speed feedback:
// it only stores and sets flags, the timer interrupt acts on them, as in fig. 4-15 (b)).
// No sockets, no clock, no globals: time comes in as integer nanoseconds, frames go out
// through a callback, and frames are built and read only through the Omni codec. The
// configuration is fixed at construction; the state machine, the platform loop and the
// counters are the changing state. Nothing allocates after construction (the send callback
// is the caller's); bad input is counted, never thrown.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <optional>

#include "bus_emulators/can/can_frame.hpp"
#include "bus_emulators/omni/omni_codec.hpp"
#include "controller/master_bounds.hpp"
#include "controller/master_config.hpp"
#include "controller/odometry.hpp"
#include "controller/path.hpp"
#include "controller/platform_loop.hpp"
#include "controller/sim_clock.hpp"

namespace omnitwin::controller {

using MasterState = simclock::MasterState;
using StopReason = simclock::StopReason;

// kStartupTicks (controller/master_bounds.hpp): the ticks from the first detecting tick to path
// time 0 when the four slaves answer the first detection request.

// The named transitions of the master (states: simclock::MasterState). Legal in each state:
//  waiting   — wait_for_pc only, before the PC's start. Ticks send nothing. Legal:
//              begin_detection (NMT start to the master or to all), shutdown.
//  detecting — each tick: all_found if the four slaves have answered, else startup_timeout
//              once startup_timeout has passed since the first detecting tick, else one
//              detection request. Legal: all_found, startup_timeout, nmt_stop_*, bus_error,
//              shutdown.
//  running   — each tick: watchdogs (feedback, detection round), path_done, else one 0x102
//              command and, every detect_every ticks, one detection request. Legal:
//              node_missing, feedback_missing, nmt_stop_*, bus_error, path_done, shutdown.
//  stopped   — holds; ticks send nothing. Legal: begin_detection (NMT start from the PC);
//              shutdown is a no-op.
//  finished  — as stopped, after the normal end of the path.
// Parameter set-up from the PC is forwarded in every state but running (refused there);
// detection requests are answered in every state.
enum class MasterTransition : std::uint8_t {
  begin_detection,   // waiting|stopped|finished → detecting: answers cleared, reason cleared
  all_found,         // detecting → running: slave setting (if any) to the four slaves, then
                     // NMT start all; loop reset; the NEXT tick is path time 0
  startup_timeout,   // detecting → stopped: NMT stop all; node = first slave not found
  node_missing,      // running → stopped: NMT stop all; a slave missed detect_misses rounds
  feedback_missing,  // running → stopped: NMT stop all; no feedback for feedback_timeout ticks
  nmt_stop_all,      // detecting|running → stopped: NMT stop to all heard (slaves heard it too)
  nmt_stop_master,   // detecting|running → stopped: NMT stop to the master: NMT stop all
  bus_error,         // detecting|running → stopped: the transport refused a frame; NMT stop all
  path_done,         // running → finished: path end + settle passed; NMT stop all
  shutdown,          // waiting|detecting|running → stopped (reason none): NMT stop all
};
const char* to_string(MasterTransition t);  // stable lowercase name, never nullptr

// What on_frame() did with a frame.
enum class FrameOutcome : std::uint8_t {
  handled,       // acted upon or stored
  ignored,       // a valid Omni frame not for the master, or not meaningful in this state
  refused,       // a parameter set-up the master will not forward (running, type, value)
  decode_error,  // not a valid Omni frame (codec error)
};
const char* to_string(FrameOutcome o);

// Counters since construction.
struct OmniMasterStats {
  // received = handled + ignored + refused + decode_errors
  std::uint64_t frames_received = 0;
  std::uint64_t frames_handled = 0;
  std::uint64_t frames_ignored = 0;
  std::uint64_t frames_refused = 0;
  std::uint64_t decode_errors = 0;
  omni::OmniError last_decode_error = omni::OmniError::not_omni;  // valid when decode_errors > 0
  std::uint64_t frames_sent = 0;      // accepted by the send callback
  std::uint64_t send_failures = 0;    // refused by the send callback
  std::uint64_t ticks = 0;            // on_tick() calls, every state
  std::uint64_t commands_sent = 0;    // 0x102 speed commands
  std::uint64_t saturated_commands = 0;    // commands with an axis clamped to the int8 range
  std::array<std::uint64_t, 4> feedback{};  // speed feedback frames, axis 1..4 at [0..3]
  std::uint64_t feedback_other_type = 0;   // feedback frames with a data type other than speed
  std::uint64_t detection_requests = 0;    // detection requests sent (start-up and running)
  std::uint64_t detection_rounds = 0;      // running rounds whose answers were checked
  std::uint64_t detection_misses = 0;      // slave-rounds without an answer
  std::uint64_t late_ticks = 0;            // running ticks the loop ran half a period late or more (no watchdog judged them)
  std::uint64_t detection_answers = 0;     // slave answers received
  std::uint64_t pc_detections_answered = 0;  // our answers (0x002 remote) to requests heard
  std::uint64_t parameters_forwarded = 0;  // PC 0x702 type 0x0C fanned out to the four slaves
  std::uint64_t parameters_refused = 0;    // = frames_refused
  std::uint64_t slave_settings_sent = 0;   // slave-setting fan-outs sent before an NMT start
  std::uint64_t nmt_received = 0;          // NMT commands to the master or to all
  std::uint64_t starts = 0;                // all_found transitions
  std::uint64_t illegal_transitions = 0;   // never expected: a transition asked in a wrong state
};

class OmniMaster {
 public:
  // Sends one frame now; false = the transport refused it.
  using SendFn = std::function<bool(const can::Frame&)>;

  // Checks the configuration (throws MasterConfigError, set-up only) and builds the path and
  // the platform loop (odometry at the path's start pose, all counts zero). Starts in
  // detecting, or in waiting when config.wait_for_pc. Sends nothing. Not real-time safe.
  OmniMaster(const MasterConfig& config, SendFn send);

  // The CAN receive interrupt: one frame received at now_ns [ns, the caller's timeline].
  //  - NMT start to the master or to all: begin_detection (waiting/stopped/finished);
  //  - NMT stop to all: nmt_stop_all; to the master: nmt_stop_master (detecting/running);
  //  - detection request (from the PC): answers DetectionAnswer{master} (0x002 remote);
  //  - detection answer of a slave: sets its flag (checked by the next tick);
  //  - speed feedback (type speed): adds the value [counts in that slave sample] to the axis's
  //    cumulative count and marks it fresh; in every state;
  //  - parameter set-up 0x702 type 0x0C from the PC: forwarded to the four slaves as type
  //    0x01 (fan_out_to_slaves) and kept as the slave setting, unless running (refused);
  //  - anything else: counted (ignored / refused / decode_error), never thrown.
  // Real-time safe (apart from the send callback).
  FrameOutcome on_frame(const can::Frame& frame, std::int64_t now_ns);

  // The timer interrupt at now_ns [ns], once per period. What it sends in each state is in
  // MasterTransition's comment; per running tick, in this order: (stop transitions instead,
  // if a watchdog fired or the path and settle time are over) the 0x102 command from
  // PlatformLoop::step(t − origin, counts), then the detection request when due. A frame
  // refused by the transport during detecting/running ends the tick with bus_error.
  // `late`: the loop runs this tick half a period or more after its deadline (the master's
  // own process did not run in time); such a tick judges no slave: no watchdog counts it and
  // an open detection round stays open, since the slaves had no fair period to answer.
  // Real-time safe.
  void on_tick(std::int64_t now_ns, bool late = false);

  // Process exit: NMT stop all unless already stopped or finished (see shutdown). RT-safe.
  void shutdown();

  // For a shell that batches its sends (the send callback queues and returns true, the
  // transport gets the batch after on_tick()): `n` of the frames the callback accepted were
  // refused by the transport after all. They are counted as send failures instead of sent,
  // and an active master stops with bus_error, as on_tick() does for a refusal it saw itself
  // (its NMT stop all goes through the callback). Real-time safe.
  void note_send_failures(std::uint64_t n);

  MasterState state() const { return state_; }
  // State, reason, node, path origin [ns, -1 before the first running tick], reference and
  // odometry poses [m, m, rad]. Real-time safe.
  simclock::MasterReport report() const;
  const OmniMasterStats& stats() const { return stats_; }
  const MasterConfig& config() const { return config_; }
  const PlatformLoop& loop() const { return loop_; }
  const PlatformLoopOutput& last_output() const { return out_; }  // last running tick's
  // Cumulative counts per axis [counts]: the sum of the speed feedback values received.
  const WheelCounts& counts() const { return counts_; }
  // The slave controller setting sent before every NMT start (config's slave_kp, replaced
  // by the last value forwarded from the PC); nullopt: none.
  std::optional<std::uint16_t> slave_setting() const { return slave_setting_; }
  // Running ticks since the last all_found (0 on the origin tick).
  std::uint64_t run_ticks() const { return run_ticks_; }
  // Slaves that missed detect_misses rounds or feedback_timeout ticks of feedback as of the
  // last running tick; 4 after a node_missing/feedback_missing stop: the whole bus went silent.
  int missing_slaves() const;

 private:
  void transition(MasterTransition t, std::uint8_t node = 0);
  void set_state(MasterState s, StopReason r, std::uint8_t node);
  void start_slaves();
  void stop_slaves(MasterState to, StopReason r, std::uint8_t node);

  FrameOutcome handle(const omni::Message& m);
  FrameOutcome handle_nmt(const omni::NmtCommand& c);
  FrameOutcome handle_feedback(const omni::SpeedFeedback& f);
  FrameOutcome handle_parameter(const omni::ParameterSetup& p);

  void detecting_tick(std::int64_t now_ns);
  void running_tick(std::int64_t now_ns, bool late);
  bool feedback_ok();            // false: feedback_missing ran
  bool detection_round_ok();     // false: node_missing ran
  bool detection_due() const;
  void send_command(double t);
  void send_detection_request();

  bool send(const omni::Message& m);

  MasterConfig config_;
  SendFn send_;
  PlatformLoop loop_;
  std::int64_t startup_timeout_ns_;

  MasterState state_ = MasterState::waiting;
  StopReason reason_ = StopReason::none;
  std::uint8_t reason_node_ = 0;
  std::optional<std::uint16_t> slave_setting_;

  std::int64_t detect_start_ns_ = -1;  // first detecting tick [ns]; -1 = not yet
  std::int64_t origin_ns_ = -1;        // path time 0 [ns]; -1 = not yet
  std::uint64_t run_ticks_ = 0;
  bool round_open_ = false;                 // a running detection request awaits its check
  std::array<bool, 4> answered_{};          // slave answered since the last request / reset
  std::array<int, 4> missed_rounds_{};      // consecutive rounds without an answer
  std::array<bool, 4> fresh_feedback_{};    // feedback arrived since the last tick
  std::array<int, 4> ticks_without_feedback_{};
  WheelCounts counts_{};                    // cumulative feedback [counts]
  WheelCounts counts_at_step_{};            // counts_ at the last loop step
  PlatformLoopOutput out_{};
  bool send_failed_ = false;                // a send was refused since the last check
  OmniMasterStats stats_;
};

}  // namespace omnitwin::controller
