// controller layer — the Omni master protocol core; see omni_master.hpp.
//
// The receive interrupt (on_frame) decodes and stores: flags for detection answers, counts
// for feedback, and the few PC commands that change state at once (NMT) or are forwarded at
// once (parameters). The timer interrupt (on_tick) decides: every state change that a tick
// can cause goes through transition(), one flat switch over MasterTransition.
#include "controller/omni_master.hpp"

#include <algorithm>
#include <cmath>
#include <type_traits>
#include <utility>
#include <variant>

namespace omnitwin::controller {

namespace {

using omni::NmtState;
namespace node = omni::node;

// Seconds → integer nanoseconds (rounded).
std::int64_t to_ns(double s) { return static_cast<std::int64_t>(std::llround(s * 1e9)); }

// Wrap-safe 32-bit sum, as the HCTL-2032 counter the feedback values came from.
std::int32_t add_counts(std::int32_t a, std::int32_t b) {
  return static_cast<std::int32_t>(static_cast<std::uint32_t>(a) + static_cast<std::uint32_t>(b));
}

// True when axis_command_from() clamps this command [counts/sample] to the int8 range.
bool clamps(double counts_per_sample) {
  return counts_per_sample >= 127.5 || counts_per_sample <= -128.5;
}

}  // namespace

const char* to_string(MasterTransition t) {
  switch (t) {
    case MasterTransition::begin_detection: return "begin_detection";
    case MasterTransition::all_found: return "all_found";
    case MasterTransition::startup_timeout: return "startup_timeout";
    case MasterTransition::node_missing: return "node_missing";
    case MasterTransition::feedback_missing: return "feedback_missing";
    case MasterTransition::nmt_stop_all: return "nmt_stop_all";
    case MasterTransition::nmt_stop_master: return "nmt_stop_master";
    case MasterTransition::bus_error: return "bus_error";
    case MasterTransition::path_done: return "path_done";
    case MasterTransition::shutdown: return "shutdown";
  }
  return "unknown";
}

const char* to_string(FrameOutcome o) {
  switch (o) {
    case FrameOutcome::handled: return "handled";
    case FrameOutcome::ignored: return "ignored";
    case FrameOutcome::refused: return "refused";
    case FrameOutcome::decode_error: return "decode_error";
  }
  return "unknown";
}

OmniMaster::OmniMaster(const MasterConfig& config, SendFn send)
    : config_((validate_master_config(config), config)),
      send_(std::move(send)),
      loop_(config_.loop, build_path(config_.path)),
      startup_timeout_ns_(to_ns(config_.startup_timeout)),
      slave_setting_(config_.slave_kp) {
  // Odometry at the path's start, every count zero; the report shows the start pose.
  loop_.reset(loop_.path().start_pose(), counts_);
  out_.reference = loop_.path().sample(0.0);
  out_.odom_pose = loop_.path().start_pose();
  state_ = config_.wait_for_pc ? MasterState::waiting : MasterState::detecting;
}

// ---------------------------------------------------------------------------------------
// State machine

void OmniMaster::transition(MasterTransition t, std::uint8_t node) {
  using S = MasterState;
  const bool active = state_ == S::detecting || state_ == S::running;
  switch (t) {
    case MasterTransition::begin_detection:
      if (active) break;
      answered_.fill(false);
      detect_start_ns_ = -1;  // the start-up clock starts at the next tick
      set_state(S::detecting, StopReason::none, 0);
      return;
    case MasterTransition::all_found:
      if (state_ != S::detecting) break;
      start_slaves();
      set_state(S::running, StopReason::none, 0);
      return;
    case MasterTransition::startup_timeout:
      if (state_ != S::detecting) break;
      return stop_slaves(S::stopped, StopReason::startup_timeout, node);
    case MasterTransition::node_missing:
      if (state_ != S::running) break;
      return stop_slaves(S::stopped, StopReason::node_missing, node);
    case MasterTransition::feedback_missing:
      if (state_ != S::running) break;
      return stop_slaves(S::stopped, StopReason::feedback_missing, node);
    case MasterTransition::nmt_stop_all:  // the slaves heard the stop themselves
      if (!active) break;
      return set_state(S::stopped, StopReason::nmt_stop, 0);
    case MasterTransition::nmt_stop_master:
      if (!active) break;
      return stop_slaves(S::stopped, StopReason::nmt_stop, 0);
    case MasterTransition::bus_error:
      if (!active) break;
      return stop_slaves(S::stopped, StopReason::bus_error, 0);
    case MasterTransition::path_done:
      if (state_ != S::running) break;
      return stop_slaves(S::finished, StopReason::none, 0);
    case MasterTransition::shutdown:
      if (state_ == S::stopped || state_ == S::finished) return;  // nothing left to stop
      return stop_slaves(S::stopped, StopReason::none, 0);
  }
  ++stats_.illegal_transitions;
}

void OmniMaster::set_state(MasterState s, StopReason r, std::uint8_t node) {
  state_ = s;
  reason_ = r;
  reason_node_ = node;
}

void OmniMaster::start_slaves() {
  // The slave setting first: slaves take parameters only while stopped, and a node's
  // frames leave in the order they were queued.
  if (slave_setting_) {
    const omni::ParameterSetup setting{node::master, node::pc, omni::data_type::slave_controller_setting,
                                       omni::ParamWidth::four_bytes, *slave_setting_};
    if (const auto frames = omni::fan_out_to_slaves(setting)) {
      for (const omni::ParameterSetup& p : *frames) send(p);
      ++stats_.slave_settings_sent;
    }
  }
  send(omni::NmtCommand{node::all, NmtState::start});
  // Odometry keeps its pose; motion since its last step is integrated in the next one.
  loop_.reset(loop_.odometry().pose(), counts_at_step_);
  origin_ns_ = -1;
  run_ticks_ = 0;
  round_open_ = false;
  answered_.fill(false);
  missed_rounds_.fill(0);
  fresh_feedback_.fill(false);
  ticks_without_feedback_.fill(0);
  ++stats_.starts;
}

void OmniMaster::stop_slaves(MasterState to, StopReason r, std::uint8_t node) {
  send(omni::NmtCommand{node::all, NmtState::stop});
  round_open_ = false;
  set_state(to, r, node);
}

void OmniMaster::shutdown() { transition(MasterTransition::shutdown); }

void OmniMaster::note_send_failures(std::uint64_t n) {
  if (n == 0) return;
  n = std::min(n, stats_.frames_sent);
  stats_.frames_sent -= n;
  stats_.send_failures += n;
  if (state_ == MasterState::detecting || state_ == MasterState::running) transition(MasterTransition::bus_error);
  send_failed_ = false;
}

// ---------------------------------------------------------------------------------------
// Receive interrupt

FrameOutcome OmniMaster::on_frame(const can::Frame& frame, std::int64_t /*now_ns*/) {
  ++stats_.frames_received;
  const omni::DecodeResult r = omni::decode(frame);
  FrameOutcome o = FrameOutcome::decode_error;
  if (const auto* e = std::get_if<omni::DecodeError>(&r)) {
    stats_.last_decode_error = *e;
  } else {
    o = handle(std::get<omni::Message>(r));
  }
  // Every frame lands in exactly one of the four counters.
  switch (o) {
    case FrameOutcome::handled: ++stats_.frames_handled; break;
    case FrameOutcome::ignored: ++stats_.frames_ignored; break;
    case FrameOutcome::refused: ++stats_.frames_refused, ++stats_.parameters_refused; break;
    case FrameOutcome::decode_error: ++stats_.decode_errors; break;
  }
  return o;
}

FrameOutcome OmniMaster::handle(const omni::Message& m) {
  if (const auto* nmt = std::get_if<omni::NmtCommand>(&m)) return handle_nmt(*nmt);
  if (std::holds_alternative<omni::DetectionRequest>(m)) {
    // A request we hear is the PC's (our own are not delivered back): answer it.
    if (send(omni::DetectionAnswer{node::master})) ++stats_.pc_detections_answered;
    return FrameOutcome::handled;
  }
  if (const auto* a = std::get_if<omni::DetectionAnswer>(&m)) {
    const int axis = omni::axis_of_slave(a->node);
    if (axis == 0) return FrameOutcome::ignored;  // another master's answer
    answered_[axis - 1] = true;
    ++stats_.detection_answers;
    return FrameOutcome::handled;
  }
  if (const auto* f = std::get_if<omni::SpeedFeedback>(&m)) return handle_feedback(*f);
  if (const auto* p = std::get_if<omni::ParameterSetup>(&m)) return handle_parameter(*p);
  return FrameOutcome::ignored;  // a speed command: another master on the bus
}

FrameOutcome OmniMaster::handle_nmt(const omni::NmtCommand& c) {
  const bool to_master = c.target == node::master;
  if (!to_master && c.target != node::all) return FrameOutcome::ignored;  // for one slave
  ++stats_.nmt_received;
  const bool active = state_ == MasterState::detecting || state_ == MasterState::running;
  if (c.state == NmtState::start) {
    if (active) return FrameOutcome::ignored;  // already started
    transition(MasterTransition::begin_detection);
    return FrameOutcome::handled;
  }
  if (!active) return FrameOutcome::ignored;  // nothing to stop
  transition(to_master ? MasterTransition::nmt_stop_master : MasterTransition::nmt_stop_all);
  return FrameOutcome::handled;
}

FrameOutcome OmniMaster::handle_feedback(const omni::SpeedFeedback& f) {
  const int axis = omni::axis_of_slave(f.sender);  // the codec checked sender ↔ identifier
  if (f.data_type != omni::data_type::speed) {
    ++stats_.feedback_other_type;
    return FrameOutcome::ignored;
  }
  counts_[axis - 1] = add_counts(counts_[axis - 1], f.value);
  fresh_feedback_[axis - 1] = true;
  ++stats_.feedback[axis - 1];
  return FrameOutcome::handled;
}

FrameOutcome OmniMaster::handle_parameter(const omni::ParameterSetup& p) {
  if (p.receiver != node::master) return FrameOutcome::ignored;  // the PC setting one slave
  if (state_ == MasterState::running) return FrameOutcome::refused;  // slaves are started
  const auto frames = omni::fan_out_to_slaves(p);  // nullopt: not type 0x0C, or > 0xFFFF
  if (!frames) return FrameOutcome::refused;
  for (const omni::ParameterSetup& s : *frames) send(s);
  slave_setting_ = static_cast<std::uint16_t>(p.value);
  ++stats_.parameters_forwarded;
  return FrameOutcome::handled;
}

// ---------------------------------------------------------------------------------------
// Timer interrupt

void OmniMaster::on_tick(std::int64_t now_ns, bool late) {
  ++stats_.ticks;
  switch (state_) {
    case MasterState::detecting: detecting_tick(now_ns); break;
    case MasterState::running: running_tick(now_ns, late); break;
    case MasterState::waiting:
    case MasterState::stopped:
    case MasterState::finished: break;  // nothing is sent
  }
  // A refused frame (this tick's or the receive interrupt's) stops an active master.
  if (!send_failed_) return;
  if (state_ == MasterState::detecting || state_ == MasterState::running) transition(MasterTransition::bus_error);
  send_failed_ = false;  // the stop itself may be refused too: there is nothing more to do
}

void OmniMaster::detecting_tick(std::int64_t now_ns) {
  if (detect_start_ns_ < 0) detect_start_ns_ = now_ns;
  const auto missing = std::find(answered_.begin(), answered_.end(), false);
  if (missing == answered_.end()) return transition(MasterTransition::all_found);
  if (now_ns - detect_start_ns_ >= startup_timeout_ns_) {
    const int axis = static_cast<int>(missing - answered_.begin()) + 1;
    return transition(MasterTransition::startup_timeout, omni::slave_of_axis(axis));
  }
  send_detection_request();  // answers accumulate over the start-up rounds
}

void OmniMaster::running_tick(std::int64_t now_ns, bool late) {
  if (origin_ns_ < 0) {
    origin_ns_ = now_ns;  // the first running tick is path time 0
    fresh_feedback_.fill(false);
  } else if (late) {
    ++stats_.late_ticks;  // the master's own lateness: no slave is judged on it
  } else if (!feedback_ok() || !detection_round_ok()) {
    return;  // a watchdog stopped the slaves
  }
  const double t = static_cast<double>(now_ns - origin_ns_) / 1e9;  // path time [s]
  if (config_.settle >= 0 && t >= loop_.path().duration() + config_.settle) {
    return transition(MasterTransition::path_done);
  }
  send_command(t);
  // Node detection between two samples: after this sample's command.
  if (detection_due() && !(late && round_open_)) {  // a late tick leaves the open round open
    answered_.fill(false);
    round_open_ = true;
    send_detection_request();
  }
  ++run_ticks_;
}

bool OmniMaster::feedback_ok() {
  for (std::size_t i = 0; i < 4; ++i) {
    ticks_without_feedback_[i] = fresh_feedback_[i] ? 0 : ticks_without_feedback_[i] + 1;
    fresh_feedback_[i] = false;
  }
  if (config_.feedback_timeout <= 0) return true;
  for (std::size_t i = 0; i < 4; ++i) {
    if (ticks_without_feedback_[i] < config_.feedback_timeout) continue;
    transition(MasterTransition::feedback_missing, omni::slave_of_axis(static_cast<int>(i) + 1));
    return false;
  }
  return true;
}

bool OmniMaster::detection_round_ok() {
  if (!detection_due() || !round_open_) return true;
  round_open_ = false;
  ++stats_.detection_rounds;
  for (std::size_t i = 0; i < 4; ++i) {
    missed_rounds_[i] = answered_[i] ? 0 : missed_rounds_[i] + 1;
    if (!answered_[i]) ++stats_.detection_misses;
  }
  for (std::size_t i = 0; i < 4; ++i) {
    if (missed_rounds_[i] < config_.detect_misses) continue;
    transition(MasterTransition::node_missing, omni::slave_of_axis(static_cast<int>(i) + 1));
    return false;
  }
  return true;
}

int OmniMaster::missing_slaves() const {
  int n = 0;
  for (std::size_t i = 0; i < 4; ++i) {
    const bool no_answer = config_.detect_every > 0 && missed_rounds_[i] >= config_.detect_misses;
    const bool no_feedback = config_.feedback_timeout > 0 && ticks_without_feedback_[i] >= config_.feedback_timeout;
    n += no_answer || no_feedback ? 1 : 0;
  }
  return n;
}

bool OmniMaster::detection_due() const {
  return config_.detect_every > 0 && run_ticks_ % static_cast<std::uint64_t>(config_.detect_every) == 0;
}

void OmniMaster::send_command(double t) {
  out_ = loop_.step(t, counts_);
  counts_at_step_ = counts_;
  omni::SpeedCommand cmd;
  cmd.sender = node::master;
  bool clamped = false;
  for (std::size_t i = 0; i < 4; ++i) {
    const double c = out_.wheel_counts_per_sample[i];
    cmd.axis[i] = omni::axis_command_from(c);
    clamped = clamped || clamps(c);
  }
  if (clamped) ++stats_.saturated_commands;
  if (send(cmd)) ++stats_.commands_sent;
}

void OmniMaster::send_detection_request() {
  if (send(omni::DetectionRequest{})) ++stats_.detection_requests;
}

bool OmniMaster::send(const omni::Message& m) {
  const omni::EncodeResult r = omni::encode(m);
  const auto* frame = std::get_if<can::Frame>(&r);
  const bool ok = frame != nullptr && send_ && send_(*frame);
  if (ok) {
    ++stats_.frames_sent;
  } else {
    ++stats_.send_failures;
    send_failed_ = true;
  }
  return ok;
}

simclock::MasterReport OmniMaster::report() const {
  simclock::MasterReport r;
  r.state = state_;
  r.reason = reason_;
  r.node = reason_node_;
  r.path_origin_ns = origin_ns_;
  const Pose2& ref = out_.reference.pose;
  const Pose2& odo = loop_.odometry().pose();
  r.reference = {ref.x, ref.y, ref.phi};
  r.odometry = {odo.x, odo.y, odo.phi};
  return r;
}

}  // namespace omnitwin::controller
