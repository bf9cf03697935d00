// twin layer — the twin's side of the thesis CAN network; see can_network.hpp.
#include "twin/can_network.hpp"

#include <numbers>

#include <fmt/format.h>

#include <cmath>
#include <stdexcept>

namespace omnitwin::twin {

namespace {

constexpr int kBusNodes = 5;  // the transport side + four slaves

std::string node_name(int fault_node) {
  if (fault_node == FaultSpec::kMaster) return "master";
  if (fault_node == FaultSpec::kAllNodes) return "all nodes";
  return fmt::format("axis {} (node 0x{:02X})", fault_node + 1, omni::slave_of_axis(fault_node + 1));
}

const char* state_name(can::ErrorState e) {
  switch (e) {
    case can::ErrorState::error_active: return "error_active";
    case can::ErrorState::error_passive: return "error_passive";
    case can::ErrorState::bus_off: return "bus_off";
  }
  return "?";
}

// The master's NMT "start all" (0x000 [00 01]): the moment the platform's run begins.
bool is_start_all(const can::Frame& f) {
  return f.id == 0 && !f.extended && f.kind == can::FrameKind::data && f.dlc == 2 && f.data[0] == 0 &&
         f.data[1] == 1;
}

// An NMT command to all nodes (0x000 [00 cmd]; cmd 1 start, 2 stop).
constexpr std::uint8_t kNmtStop = 2;
bool is_nmt_all(const can::Frame& f) {
  return f.id == 0 && !f.extended && f.kind == can::FrameKind::data && f.dlc == 2 && f.data[0] == 0;
}

}  // namespace

OmniCanNetwork::OmniCanNetwork(const Scenario& s, Scheduler& sched, Hooks hooks)
    : s_(s),
      sched_(sched),
      hooks_(std::move(hooks)),
      // Lockstep batches the slaves' frames until omni-master's next grant; a master on the
      // virtual clock gets each when it completes (the pacer runs the bus to that instant).
      wire_(s, kBusNodes, s.clock == ClockMode::lockstep && !s.virtual_time_master()) {
  can::CanBus& bus = wire_.bus();
  bus.on_deliver([this](can::BusNode r, const can::Frame& f, const can::FrameTiming& t) { on_deliver(r, f, t); });
  bus.on_tx_done([this](can::BusNode n, const can::Frame& f, const can::FrameTiming& t) { on_tx_done(n, f, t); });
  bus.on_event([this](const can::BusEvent& e) { on_bus_event(e); });
  start_phase_ = s.bus.can.start_phase;
  if (s.bus.can.start_phase_random) {
    // Their own stream, so that the faults' random sequences do not depend on this setting.
    std::mt19937_64 phase_rng(s.bus.can.seed ^ 0x5EED'0F'5A'1A'7E'00ULL);
    for (double& p : start_phase_) p = std::uniform_real_distribution<double>(0.0, 1.0)(phase_rng);
  }
  for (int i = 0; i < 4; ++i) {
    make_slave(i);
    const omni::OmniSlaveConfig& c = slaves_[static_cast<std::size_t>(i)]->config();
    // Each node's timer runs on its own oscillator; it starts when NMT start arrives.
    timers_[static_cast<std::size_t>(i)] = sched_.add_periodic(
        fmt::format("slave{}", i + 1), Phase::device, 0, c.timer_period_ns,
        [this, i](SimTime t) { on_slave_timer(i, t); }, c.drift);
    sched_.cancel(timers_[static_cast<std::size_t>(i)]);
  }
}

OmniCanNetwork::~OmniCanNetwork() = default;

void OmniCanNetwork::make_slave(int i) {
  const std::uint8_t id = omni::slave_of_axis(i + 1);
  omni::OmniSlaveConfig c = omni::make_slave_config(id, s_.platform);
  c.drift = s_.bus.can.drift[static_cast<std::size_t>(i)];
  c.sync_enabled = s_.bus.can.sync;
  c.missing_command = s_.bus.can.hold_missing_command ? omni::MissingCommand::hold : omni::MissingCommand::skip;
  c.sync_interval = s_.bus.can.sync_interval;
  c.t_post_ns = std::llround(s_.bus.can.t_post_us * 1e3);
  c.isr_ns = std::llround(s_.bus.can.isr_us * 1e3);
  c.start_phase_ns = std::llround(start_phase_[static_cast<std::size_t>(i)] * static_cast<double>(c.timer_period_ns));
  auto send = [this, i](const can::Frame& f, std::int64_t at) {
    wire_.bus().submit(bus_node(i), f, at + wire_.extra_delay(i));
  };
  slaves_[static_cast<std::size_t>(i)] = std::make_unique<omni::OmniSlave>(c, send, hooks_.wheel_angle(i));
}

void OmniCanNetwork::advance(SimTime t) { wire_.bus().advance(t); }

void OmniCanNetwork::observe_wheels() {
  for (int i = 0; i < 4; ++i)
    if (powered_[static_cast<std::size_t>(i)]) slaves_[static_cast<std::size_t>(i)]->observe(hooks_.wheel_angle(i));
}

// ---------------------------------------------------------------------------------------
// Bus callbacks

void OmniCanNetwork::on_deliver(can::BusNode receiver, const can::Frame& f, const can::FrameTiming& timing) {
  if (receiver == CanWire::kFar) return;  // the far side heard it on the transport (on_tx_done)
  const int i = receiver - 1;
  if (!wire_.arrives(i)) return;
  omni::OmniSlave& sl = *slaves_[static_cast<std::size_t>(i)];
  const std::uint64_t before = sl.stats().steps();
  // A slave waiting for sync samples in this receive interrupt: its counter reads the angle of
  // the frame's end, not of the later instant the bus is advanced at (up to a physics step;
  // found in review).
  if (sl.waiting_for_sync() && hooks_.wheel_angle_at) sl.observe(hooks_.wheel_angle_at(i, timing.end_ns));
  const omni::TimerAction a = sl.on_frame(f, timing.end_ns);
  after_slave_input(i, before, a);
}

void OmniCanNetwork::on_tx_done(can::BusNode sender, const can::Frame& f, const can::FrameTiming& timing) {
  bool reached_master = false;
  if (!wire_.completed(sender, f, timing, &reached_master)) {  // a slave's frame: on to the master
    if (!reached_master) return;
    const omni::DecodeResult d = omni::decode(f);
    if (const auto* m = std::get_if<omni::Message>(&d))
      if (const auto* fb = std::get_if<omni::SpeedFeedback>(m)) on_feedback_at_master(*fb);
    return;
  }
  if (master_start_ns_ < 0 && is_start_all(f)) master_start_ns_ = timing.end_ns;
  if (is_nmt_all(f)) {
    bus_stopped_ = f.data[1] == kNmtStop;
    at_master_ = AtMaster{};  // a new run of the nodes: no period is open, nothing stored
  }
  const omni::DecodeResult d = omni::decode(f);
  if (const auto* m = std::get_if<omni::Message>(&d))
    if (const auto* c = std::get_if<omni::SpeedCommand>(m)) on_command_at_master(*c);
}

// A speed command on the wire ends the master's control period: each axis's error for it is
// the command sent at its start minus the feedback the master holds at its end (the master
// stores each axis's latest feedback, l.1339: a period without one keeps the one before).
void OmniCanNetwork::on_command_at_master(const omni::SpeedCommand& c) {
  if (c.sender != omni::node::master) return;
  for (std::size_t a = 0; a < 4; ++a) {
    if (at_master_.open && hooks_.axis_sample_at_master)
      hooks_.axis_sample_at_master(static_cast<int>(a), static_cast<double>(at_master_.command[a] - at_master_.feedback[a]));
    at_master_.command[a] = c.axis[a];
  }
  at_master_.open = true;
}

void OmniCanNetwork::on_feedback_at_master(const omni::SpeedFeedback& f) {
  const int axis = omni::axis_of_slave(f.sender);
  if (axis < 1 || f.data_type != omni::data_type::speed) return;
  at_master_.feedback[static_cast<std::size_t>(axis - 1)] = f.value;
}

void OmniCanNetwork::on_bus_event(const can::BusEvent& e) {
  if (e.kind == can::BusEventKind::error_frame || e.node == CanWire::kFar) return;  // counted by the bus
  const std::string who = node_name(e.node - 1);
  if (e.kind == can::BusEventKind::state_changed) {
    if (e.state == can::ErrorState::bus_off) wire_.note_bus_off();
    hooks_.log(e.t_ns, "can", fmt::format("{} is {}", who, state_name(e.state)));
  } else {
    hooks_.log(e.t_ns, "can", fmt::format("{} recovered from bus-off", who));
  }
}

// ---------------------------------------------------------------------------------------
// Slaves

void OmniCanNetwork::on_slave_timer(int i, SimTime t) {
  wire_.bus().advance(t);  // frames that complete at or before the interrupt are in its FIFO
  omni::OmniSlave& sl = *slaves_[static_cast<std::size_t>(i)];
  const std::uint64_t before = sl.stats().steps();
  const omni::TimerAction a = sl.on_timer(t, hooks_.wheel_angle(i));
  after_slave_input(i, before, a);
}

void OmniCanNetwork::after_slave_input(int i, std::uint64_t steps_before, const omni::TimerAction& a) {
  const Scheduler::TimerId id = timers_[static_cast<std::size_t>(i)];
  if (a.request == omni::TimerRequest::stop) sched_.cancel(id);
  if (a.request == omni::TimerRequest::restart) sched_.restart(id, a.first_ns);
  const omni::OmniSlave& sl = *slaves_[static_cast<std::size_t>(i)];
  // The amplifier follows the DA (the zero code after a stop).
  hooks_.set_amplifier_input(i, sl.da_volts());
  if (sl.stats().steps() > steps_before) {  // a skipped interrupt (no new command) logs nothing
    const physics::WheelDriveSample& w = sl.drive_chain().last();
    hooks_.axis_sample(i, w.command - w.delta_counts);
  }
}

// ---------------------------------------------------------------------------------------
// Faults

void OmniCanNetwork::apply_fault(const FaultSpec& f, bool begin, SimTime t) {
  // The loader only lets each kind name the nodes it can act on; a hand-built fault that
  // names another is a programmer error.
  const bool slave = f.wheel >= 0 && f.wheel < 4;
  const bool ok = f.kind == FaultSpec::Kind::frame_loss ? (slave || f.wheel == FaultSpec::kMaster || f.wheel == FaultSpec::kAllNodes)
                  : f.kind == FaultSpec::Kind::delay    ? (slave || f.wheel == FaultSpec::kMaster)
                                                        : slave;
  if (!ok) throw std::invalid_argument(fmt::format("CAN fault {} cannot act on node {}", to_string(f.kind), f.wheel));
  wire_.bus().advance(t);
  const std::size_t n = static_cast<std::size_t>(f.wheel);
  const std::string who = node_name(f.wheel);
  const char* edge = begin ? "begins" : "ends";
  switch (f.kind) {
    case FaultSpec::Kind::frame_loss:
      hooks_.log(t, "fault", wire_.apply_loss(f, begin, who));
      return;
    case FaultSpec::Kind::delay:
      hooks_.log(t, "fault", wire_.apply_delay(f, begin, who));
      return;
    case FaultSpec::Kind::drift: {
      const double d = begin ? f.drift : s_.bus.can.drift[n];
      sched_.set_drift(timers_[n], d);
      slaves_[n]->set_drift(d);  // so that an NMT start or a resync asks for the same period
      hooks_.log(t, "fault", fmt::format("drift of {} now {}, its period x{:.6f} ({})", who, d, 1.0 + d, edge));
      return;
    }
    case FaultSpec::Kind::power_loss:
      if (begin) {
        // Off the bus, timer dead, drive output gone; the node's counts so far are kept.
        wire_.bus().detach(bus_node(f.wheel), t);
        sched_.cancel(timers_[n]);
        powered_[n] = false;
        hooks_.set_setpoint(f.wheel, 0.0);
      } else {
        // Power-on reset: a fresh node, stopped, counter from zero at the shaft's angle, on the
        // oscillator it had (a drift fault still running goes on).
        const double drift = slaves_[n]->drift();
        const omni::OmniSlaveStats kept = slaves_[n]->stats();  // every counter goes on
        make_slave(f.wheel);
        slaves_[n]->carry_statistics(kept);
        slaves_[n]->set_drift(drift);
        wire_.bus().reattach(bus_node(f.wheel), t);
        powered_[n] = true;
        hooks_.set_amplifier_input(f.wheel, slaves_[n]->da_volts());
      }
      hooks_.log(t, "fault", fmt::format("power_loss of {} ({})", who, edge));
      return;
    case FaultSpec::Kind::bus_off:
      if (begin) {
        wire_.bus().corrupt_frames_of(bus_node(f.wheel), 32);  // 32 × 8 > 255: bus-off
        hooks_.log(t, "fault", fmt::format("bus_off of {} ({})", who, edge));
        return;
      }
      // The fault ends: corruptions the node did not use (it was off the bus, say) go with it.
      wire_.bus().clear_corruptions_of(bus_node(f.wheel));
      hooks_.log(t, "fault", fmt::format("bus_off of {} ({}: {})", who, edge,
                                         wire_.bus().request_recovery(bus_node(f.wheel), t) ? "recovery requested"
                                                                            : "not bus-off, no recovery needed"));
      return;
    case FaultSpec::Kind::wheel_slip:
      return;  // physics, not the bus
    case FaultSpec::Kind::link_break:  // line faults; the loader refuses them on `can`
    case FaultSpec::Kind::corruption:
    case FaultSpec::Kind::second_master:
      throw std::invalid_argument("CAN network: link_break is an EtherCAT fault");
  }
}

// ---------------------------------------------------------------------------------------
// Metrics

nlohmann::json OmniCanNetwork::slave_json(int i) const {
  const std::size_t n = static_cast<std::size_t>(i);
  const omni::OmniSlave& sl = *slaves_[n];
  const omni::OmniSlaveStats& st = sl.stats();
  const std::uint64_t samples = st.samples;
  const std::uint64_t dropouts = st.dropouts;
  const can::NodeStats& ns = wire_.bus().node_stats(bus_node(i));
  return {{"node", sl.config().node_id},
          {"state", powered_[n] ? omni::to_string(sl.state()) : "off"},
          {"samples", samples},
          {"dropouts", dropouts},
          {"dropout_percent", samples ? 100.0 * static_cast<double>(dropouts) / static_cast<double>(samples) : 0.0},
          {"first_dropout_sample", st.first_dropout_sample},
          {"resyncs", st.resyncs},
          {"commands", st.commands},
          {"commands_overwritten", st.commands_overwritten},
          {"parameters_refused", st.parameters_refused},
          {"stale_samples", st.stale_samples},
          {"held_samples", st.held_samples},
          {"missing_command", omni::to_string(sl.config().missing_command)},
          {"isr_us", static_cast<double>(sl.config().isr_ns) * 1e-3},
          {"start_phase", start_phase_[n]},
          {"frames_received", st.frames_received},
          {"frames_sent", st.frames_sent},
          {"bad_frames", st.bad_frames},
          {"fifo_overruns", st.frames_overrun},
          {"can_state", state_name(wire_.bus().error_state(bus_node(i)))},
          {"tec", wire_.bus().tec(bus_node(i))},
          {"tx_errors", ns.tx_errors},
          {"bus_off_events", ns.bus_off_events}};
}

nlohmann::json OmniCanNetwork::slave_metrics() const {
  nlohmann::json a = nlohmann::json::array();
  for (int i = 0; i < 4; ++i) a.push_back(slave_json(i));
  return a;
}

BusSample OmniCanNetwork::bus_sample() const {
  BusSample b;
  b.has_frames = true;
  b.frames_tx = wire_.frames_tx();  // (any still batched are sent at the end)
  b.frames_rx = wire_.from_transport();
  std::uint64_t bad = 0;
  for (std::size_t i = 0; i < 4; ++i) {
    b.dropouts += slaves_[i]->stats().dropouts;
    bad += slaves_[i]->stats().bad_frames;
  }
  b.errors = wire_.errors() + bad;
  return b;
}

DriveStateCode OmniCanNetwork::drive_state(int axis0) const {
  const auto i = static_cast<std::size_t>(axis0);
  if (!powered_[i]) return DriveStateCode::off;
  if (wire_.bus().error_state(bus_node(axis0)) == can::ErrorState::bus_off) return DriveStateCode::fault;
  switch (slaves_[i]->state()) {
    case omni::SlaveState::stopped: return DriveStateCode::waiting;
    case omni::SlaveState::running: return DriveStateCode::running;
    case omni::SlaveState::sync_pending:
    case omni::SlaveState::awaiting_sync: return DriveStateCode::syncing;
  }
  return DriveStateCode::waiting;
}

BusNetwork::DriveDetail OmniCanNetwork::drive_detail(int axis0) const {
  const auto i = static_cast<std::size_t>(axis0);
  if (!powered_[i]) return {"off", ""};
  if (wire_.bus().error_state(bus_node(axis0)) == can::ErrorState::bus_off) return {"bus-off", ""};
  return {omni::to_string(slaves_[i]->state()), ""};
}

WheelRecord OmniCanNetwork::wheel_record(int axis0) const {
  const omni::OmniSlave& sl = *slaves_[static_cast<std::size_t>(axis0)];
  const physics::WheelDriveSample& w = sl.drive_chain().last();
  const double per_sample = s_.platform.velocity_loop.period * s_.platform.counts_per_rev() / (2 * std::numbers::pi);
  WheelRecord r;
  r.command_rad_s = sl.command() / per_sample;
  r.count = static_cast<double>(sl.drive_chain().counter().count());
  r.command_counts = w.command;
  r.measured_counts = static_cast<double>(w.delta_counts);
  r.output = static_cast<double>(w.code);
  r.node = static_cast<std::uint16_t>(sl.config().node_id);
  return r;
}

nlohmann::json OmniCanNetwork::bus_metrics(SimTime now) const {
  const BusSample b = bus_sample();
  std::uint64_t samples = 0;
  for (std::size_t i = 0; i < 4; ++i) samples += slaves_[i]->stats().samples;
  nlohmann::json m = wire_.metrics("can", now);
  m.update({{"dropouts", b.dropouts},
            {"dropout_rate", samples ? static_cast<double>(b.dropouts) / static_cast<double>(samples) : 0.0},
            {"errors", b.errors},
            {"transport_send_waits", wire_.transport().stats().send_waits},
            {"sync", s_.bus.can.sync}});
  return m;
}

}  // namespace omnitwin::twin
