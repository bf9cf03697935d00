// bus_emulators/omni — one 8051 wheel node (fig. 4-16) with the 3-2-2 synchronisation; see
// omni_slave.hpp for the model, the states and the units.
#include "bus_emulators/omni/omni_slave.hpp"

#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

namespace omnitwin::omni {
namespace {

constexpr std::uint16_t kCommandId = omni_id(FunctionCode::broadcast_8x1byte, node::master);  // 0x102

}  // namespace

can::Sja1000Config slave_filter(std::uint8_t node_id) {
  // Dual-filter mode, standard frames (SJA1000 data sheet §6.4.15, see sja1000.hpp):
  //  filter 1 = ACR0 (ID.10..3), ACR1.7..5 (ID.2..0), ACR1.4 (RTR), ACR1.3..0 + ACR3.3..0
  //  (data byte 1); filter 2 = ACR2 (ID.10..3), ACR3.7..5 (ID.2..0), ACR3.4 (RTR).
  can::Sja1000Config c;
  c.mode = can::Sja1000FilterMode::dual;
  // Filter 1: 0x000 / 0x102. They differ in ID bit 8 (ACR0 bit 5) and ID bit 1 (ACR1 bit 6);
  // RTR and data byte 1 are don't-care.
  c.acr[0] = 0x00;
  c.amr[0] = 0x20;
  c.acr[1] = 0x00;
  c.amr[1] = 0x40 | 0x10 | 0x0F;
  // Filter 2: exactly 0x700 | node_id, data frame (RTR = 0). ACR3.3..0 belongs to filter 1
  // (data byte 1, low nibble): don't care.
  const std::uint16_t param_id = omni_id(FunctionCode::parameter_setup, node_id);
  c.acr[2] = static_cast<std::uint8_t>(param_id >> 3);
  c.amr[2] = 0x00;
  c.acr[3] = static_cast<std::uint8_t>((param_id & 0x7) << 5);
  c.amr[3] = 0x0F;
  return c;
}

OmniSlaveConfig make_slave_config(std::uint8_t node_id, const physics::PlatformParams& params) {
  OmniSlaveConfig c;
  c.node_id = node_id;
  c.axis = axis_of_slave(node_id);
  c.params = params;
  c.filter = slave_filter(node_id);
  c.timer_period_ns = std::llround(params.velocity_loop.period * 1e9);
  return c;
}

const char* to_string(SlaveConfigError e) {
  switch (e) {
    case SlaveConfigError::ok: return "ok";
    case SlaveConfigError::bad_node: return "bad_node";
    case SlaveConfigError::axis_mismatch: return "axis_mismatch";
    case SlaveConfigError::bad_period: return "bad_period";
    case SlaveConfigError::bad_drift: return "bad_drift";
    case SlaveConfigError::bad_sync: return "bad_sync";
    case SlaveConfigError::bad_t_post: return "bad_t_post";
    case SlaveConfigError::bad_isr: return "bad_isr";
    case SlaveConfigError::bad_start_phase: return "bad_start_phase";
  }
  return "unknown";
}

namespace {
// An oscillator drift a timer can run on: finite, and the period stays positive.
bool valid_drift(double drift) { return std::isfinite(drift) && drift > -1.0; }
}  // namespace

SlaveConfigError validate_slave_config(const OmniSlaveConfig& c) {
  if (axis_of_slave(c.node_id) == 0) return SlaveConfigError::bad_node;
  if (c.axis != axis_of_slave(c.node_id)) return SlaveConfigError::axis_mismatch;
  if (c.timer_period_ns <= 0) return SlaveConfigError::bad_period;
  if (!valid_drift(c.drift)) return SlaveConfigError::bad_drift;
  if (c.sync_enabled && c.sync_interval < 1) return SlaveConfigError::bad_sync;
  if (c.t_post_ns < 0) return SlaveConfigError::bad_t_post;
  if (c.isr_ns < 0 || c.isr_ns >= c.timer_period_ns) return SlaveConfigError::bad_isr;
  if (c.start_phase_ns < 0) return SlaveConfigError::bad_start_phase;
  return SlaveConfigError::ok;
}

const char* to_string(MissingCommand m) {
  switch (m) {
    case MissingCommand::skip: return "skip";
    case MissingCommand::hold: return "hold";
  }
  return "?";
}

const char* to_string(SlaveState s) {
  switch (s) {
    case SlaveState::stopped: return "stopped";
    case SlaveState::running: return "running";
    case SlaveState::sync_pending: return "sync_pending";
    case SlaveState::awaiting_sync: return "awaiting_sync";
  }
  return "unknown";
}

const char* to_string(SlaveTransition t) {
  switch (t) {
    case SlaveTransition::start: return "start";
    case SlaveTransition::stop: return "stop";
    case SlaveTransition::timer_sample: return "timer_sample";
    case SlaveTransition::enter_sync: return "enter_sync";
    case SlaveTransition::routine_end: return "routine_end";
    case SlaveTransition::event_sample: return "event_sample";
  }
  return "unknown";
}

namespace {
const OmniSlaveConfig& checked(const OmniSlaveConfig& c) {
  const SlaveConfigError e = validate_slave_config(c);
  if (e != SlaveConfigError::ok) {
    throw std::invalid_argument(std::string("OmniSlave config: ") + to_string(e));
  }
  return c;
}
}  // namespace

OmniSlave::OmniSlave(const OmniSlaveConfig& config, SendFn send, double shaft_angle)
    : config_(checked(config)),
      drift_(config.drift),
      actual_period_ns_(std::llround(static_cast<double>(config.timer_period_ns) * (1.0 + config.drift))),
      send_(std::move(send)),
      sja_(config.filter),
      params_(config.params),
      chain_(params_, shaft_angle) {}

bool OmniSlave::set_drift(double drift) {
  if (!valid_drift(drift)) return false;
  drift_ = drift;
  actual_period_ns_ = std::llround(static_cast<double>(config_.timer_period_ns) * (1.0 + drift));
  return true;
}

// ---- inputs --------------------------------------------------------------------------------

TimerAction OmniSlave::on_frame(const can::Frame& frame, std::int64_t now_ns) {
  ++stats_.frames_received;
  const auto rx_time = static_cast<std::uint64_t>(now_ns < 0 ? 0 : now_ns);
  switch (sja_.receive(frame, rx_time)) {
    case can::Sja1000::RxStatus::accepted: break;
    case can::Sja1000::RxStatus::filtered: ++stats_.frames_filtered; return {};
    case can::Sja1000::RxStatus::overrun: ++stats_.frames_overrun; break;  // older ones still served
    case can::Sja1000::RxStatus::invalid:
      ++stats_.frames_invalid;
      ++stats_.bad_frames;
      return {};
  }
  if (!sja_.interrupt_line()) return {};

  // The receive (external) interrupt: read IR, clear an overrun, drain the FIFO.
  const std::uint8_t ir = sja_.read_interrupt_register();
  if ((ir & can::Sja1000::kIrDataOverrun) != 0) sja_.clear_data_overrun();
  TimerAction action;
  while (const can::Sja1000::Message* msg = sja_.read()) {
    ++stats_.frames_accepted;
    const DecodeResult r = decode(msg->frame);
    if (const auto* err = std::get_if<DecodeError>(&r)) {
      ++stats_.decode_errors;
      ++stats_.bad_frames;
      stats_.last_decode_error = *err;
    } else {
      const TimerAction a = handle(std::get<Message>(r), now_ns);
      if (a.request != TimerRequest::none) action = a;  // the latest request wins
    }
    sja_.release();
  }
  return action;
}

TimerAction OmniSlave::handle(const Message& m, std::int64_t now_ns) {
  if (const auto* nmt = std::get_if<NmtCommand>(&m)) {
    if (nmt->target != node::all && nmt->target != config_.node_id) {
      ++stats_.frames_ignored;
      return {};
    }
    ++stats_.frames_handled;
    if (nmt->state == NmtState::start) {
      return state_ == SlaveState::stopped ? transition(SlaveTransition::start, now_ns, 0.0) : TimerAction{};
    }
    return state_ != SlaveState::stopped ? transition(SlaveTransition::stop, now_ns, 0.0) : TimerAction{};
  }
  if (std::holds_alternative<DetectionRequest>(m)) {
    ++stats_.frames_handled;
    const EncodeResult e = encode(DetectionAnswer{config_.node_id});
    if (const auto* f = std::get_if<can::Frame>(&e)) {
      send(*f, now_ns);
      ++stats_.detection_answers;
    }
    return {};
  }
  if (const auto* cmd = std::get_if<SpeedCommand>(&m)) {
    if (state_ == SlaveState::stopped) {
      ++stats_.frames_ignored;
      return {};
    }
    ++stats_.frames_handled;
    ++stats_.commands;
    if (command_new_) ++stats_.commands_overwritten;
    command_ = cmd->axis[static_cast<std::size_t>(config_.axis - 1)];
    command_new_ = true;
    ++run_commands_;
    if (state_ == SlaveState::awaiting_sync) {
      return transition(SlaveTransition::event_sample, now_ns, chain_.counter().angle());
    }
    return {};
  }
  if (const auto* p = std::get_if<ParameterSetup>(&m)) {
    if (p->receiver != config_.node_id) {  // only with a filter wider than slave_filter()
      ++stats_.frames_ignored;
      return {};
    }
    if (state_ != SlaveState::stopped) {  // 4-4-1: parameters are set in the stopped state
      ++stats_.frames_ignored;
      ++stats_.parameters_refused;
      return {};
    }
    if (p->data_type != data_type::axis_controller_setting) {
      ++stats_.frames_ignored;
      ++stats_.parameters_unknown;
      return {};
    }
    // The 8051's integer PI holds whole gains: a fractional one is refused, not rounded.
    if (params_.velocity_loop.arithmetic == physics::LoopArithmetic::int16 && p->value % 100 != 0) {
      ++stats_.frames_ignored;
      ++stats_.parameters_refused;
      return {};
    }
    ++stats_.frames_handled;
    ++stats_.parameters_set;
    params_.velocity_loop.kp = static_cast<double>(p->value) / 100.0;
    rebuild_chain();
    return {};
  }
  // Detection answers of other nodes (0x002 passes slave_filter()), feedback frames.
  ++stats_.frames_ignored;
  return {};
}

TimerAction OmniSlave::on_timer(std::int64_t now_ns, double shaft_angle_rad) {
  if (state_ == SlaveState::sync_pending) return transition(SlaveTransition::routine_end, now_ns, shaft_angle_rad);
  if (state_ != SlaveState::running) {
    ++stats_.spurious_timer_interrupts;
    return {TimerRequest::stop, 0};
  }
  ++timer_since_restart_;
  const bool resync_due = config_.sync_enabled && timer_since_restart_ >= config_.sync_interval;
  return transition(resync_due ? SlaveTransition::enter_sync : SlaveTransition::timer_sample, now_ns,
                    shaft_angle_rad);
}

// ---- the state machine ---------------------------------------------------------------------

TimerAction OmniSlave::transition(SlaveTransition t, std::int64_t now_ns, double shaft_angle_rad) {
  switch (t) {
    case SlaveTransition::start:
      if (state_ != SlaveState::stopped) break;
      chain_.reset();
      command_ = 0;
      command_new_ = false;
      run_commands_ = 0;
      run_samples_ = 0;
      timer_since_restart_ = 0;
      state_ = SlaveState::running;
      return {TimerRequest::restart, now_ns + config_.t_post_ns + config_.start_phase_ns + actual_period_ns_};

    case SlaveTransition::stop:
      if (state_ == SlaveState::stopped) break;
      chain_.reset();  // DA back to the zero code: the wheel is commanded to stand still
      command_new_ = false;
      state_ = SlaveState::stopped;
      return {TimerRequest::stop, 0};

    case SlaveTransition::timer_sample: {
      if (state_ != SlaveState::running) break;
      ++stats_.timer_samples;
      const bool ran = control_step(now_ns, shaft_angle_rad);
      if (config_.isr_ns == 0) return {};
      // Reloaded at the routine's end: the next interrupt a period after that.
      return {TimerRequest::restart, now_ns + (ran ? config_.isr_ns : config_.t_post_ns) + actual_period_ns_};
    }

    case SlaveTransition::enter_sync: {
      if (state_ != SlaveState::running) break;
      ++stats_.timer_samples;
      const bool ran = control_step(now_ns, shaft_angle_rad);
      if (ran && config_.isr_ns > 0) {  // the receive interrupt is switched on at the routine's end
        state_ = SlaveState::sync_pending;
        return {TimerRequest::restart, now_ns + config_.isr_ns};
      }
      state_ = SlaveState::awaiting_sync;
      return {TimerRequest::stop, 0};
    }

    case SlaveTransition::routine_end:
      if (state_ != SlaveState::sync_pending) break;
      state_ = SlaveState::awaiting_sync;
      // A command stored during the routine holds the receive interrupt pending: it runs now.
      if (command_new_) return transition(SlaveTransition::event_sample, now_ns, shaft_angle_rad);
      return {TimerRequest::stop, 0};

    case SlaveTransition::event_sample:
      if (state_ != SlaveState::awaiting_sync) break;
      // The step runs on the arrival of this command, so by construction it is this
      // command's sample: the run's sample number realigns to the command count.
      run_samples_ = run_commands_ - 1;  // control_step() advances it to run_commands_
      ++stats_.event_samples;
      ++stats_.resyncs;
      control_step(now_ns, shaft_angle_rad);
      timer_since_restart_ = 0;
      state_ = SlaveState::running;
      // The count was zeroed as the frame was taken (l.962), T_post in, whatever the routine's length.
      return {TimerRequest::restart, now_ns + config_.t_post_ns + actual_period_ns_};
  }
  ++stats_.illegal_transitions;
  return {};
}

bool OmniSlave::control_step(std::int64_t now_ns, double shaft_angle_rad) {
  ++run_samples_;
  if (run_commands_ != run_samples_) {  // the held command is not this sample's (2-2-1)
    if (stats_.first_dropout_sample < 0) {
      stats_.first_dropout_sample = static_cast<std::int64_t>(stats_.samples);
    }
    ++stats_.dropouts;
  }
  ++stats_.samples;
  if (!command_new_) {  // no new command since the last step
    // fig. 4-16: no velocity loop and no feedback; hold: run on with the old command.
    if (config_.missing_command == MissingCommand::skip) {
      ++stats_.stale_samples;
      return false;
    }
    ++stats_.held_samples;
  }
  command_new_ = false;

  chain_.sample(shaft_angle_rad, static_cast<double>(command_));

  const EncodeResult e =
      encode(SpeedFeedback{config_.node_id, data_type::speed, chain_.last().delta_counts});
  if (const auto* f = std::get_if<can::Frame>(&e)) {
    ++stats_.frames_sent;
    ++stats_.feedback_sent;
    if (send_) send_(*f, now_ns + step_delay_ns());  // at the end of the routine
  }
  return true;
}

std::int64_t OmniSlave::step_delay_ns() const { return config_.isr_ns > 0 ? config_.isr_ns : config_.t_post_ns; }

void OmniSlave::send(const can::Frame& f, std::int64_t now_ns) {
  ++stats_.frames_sent;
  if (send_) send_(f, now_ns + config_.t_post_ns);
}

void OmniSlave::rebuild_chain() {
  // The VelocityLoop takes its gains at construction: a new chain at the current shaft angle
  // (only in the stopped state, where the counter and PI are reset at start anyway).
  chain_ = physics::WheelDriveChain(params_, chain_.counter().angle());
}

}  // namespace omnitwin::omni
