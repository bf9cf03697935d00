// twin layer — the twin's side of the thesis CAN network; see can_network.hpp.
#include "twin/can_network.hpp"

#include <numbers>

#include <fmt/format.h>

#include <cmath>
#include <stdexcept>

namespace omnitwin::twin {

namespace {

constexpr int kBusNodes = 5;  // the transport side + four slaves
// Lockstep: slave frames held for one flush_transport(); more are sent at once (one master
// tick at 1 ms carries about 8; a full 1 Mbit/s bus at 10 ms about 200).
constexpr std::size_t kPendingCapacity = 256;

can::BusConfig bus_config(const Scenario& s) {
  can::BusConfig c;
  c.bit_rate_bps = s.bus.can.bit_rate;
  c.queue_capacity = 64;  // the transport side may hand over a burst (a PC script)
  c.max_nodes = kBusNodes;
  return c;
}

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
    : s_(s), sched_(sched), hooks_(std::move(hooks)), bus_(bus_config(s)), rng_(s.bus.can.seed) {
  for (int i = 0; i < kBusNodes; ++i) bus_.attach();
  bus_.on_deliver([this](can::BusNode r, const can::Frame& f, const can::FrameTiming& t) { on_deliver(r, f, t); });
  bus_.on_tx_done([this](can::BusNode n, const can::Frame& f, const can::FrameTiming& t) { on_tx_done(n, f, t); });
  bus_.on_event([this](const can::BusEvent& e) { on_bus_event(e); });
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
  transport_ = can::open_transport(s.bus.can.transport);
  // Lockstep batches the slaves' frames until omni-master's next grant; a master on the
  // virtual clock gets each when it completes (the pacer runs the bus to that instant).
  batch_ = s.clock == ClockMode::lockstep && !s.virtual_time_master();
  pending_.reserve(kPendingCapacity);
}

OmniCanNetwork::~OmniCanNetwork() { flush_transport(); }

void OmniCanNetwork::make_slave(int i) {
  const std::uint8_t id = omni::slave_of_axis(i + 1);
  omni::OmniSlaveConfig c = omni::make_slave_config(id, s_.platform);
  c.drift = s_.bus.can.drift[static_cast<std::size_t>(i)];
  c.sync_enabled = s_.bus.can.sync;
  c.sync_interval = s_.bus.can.sync_interval;
  c.t_post_ns = std::llround(s_.bus.can.t_post_us * 1e3);
  c.start_phase_ns = std::llround(start_phase_[static_cast<std::size_t>(i)] * static_cast<double>(c.timer_period_ns));
  auto send = [this, i](const can::Frame& f, std::int64_t at) { bus_.submit(bus_node(i), f, at + extra_delay(i)); };
  slaves_[static_cast<std::size_t>(i)] = std::make_unique<omni::OmniSlave>(c, send, hooks_.wheel_angle(i));
}

void OmniCanNetwork::open_pcap(const std::string& path) {
  can::PcapWriter::Options o;
  o.flush_each_packet = false;  // flushed once per master tick (flush_pcap)
  pcap_ = std::make_unique<can::PcapWriter>(path, o);
}

std::string OmniCanNetwork::close_pcap() { return close_capture(pcap_.get()); }
std::string OmniCanNetwork::pcap_error() const { return capture_error(pcap_.get()); }

void OmniCanNetwork::advance(SimTime t) { bus_.advance(t); }

void OmniCanNetwork::observe_wheels() {
  for (int i = 0; i < 4; ++i)
    if (powered_[static_cast<std::size_t>(i)]) slaves_[static_cast<std::size_t>(i)]->observe(hooks_.wheel_angle(i));
}

// ---------------------------------------------------------------------------------------
// The transport side

void OmniCanNetwork::submit_from_far(const can::Frame& f, SimTime t) {
  const SimTime stamp = t + std::llround(s_.bus.can.t_pre_us * 1e3) + extra_delay(FaultSpec::kMaster);
  // A burst beyond the transport side's queue is refused by the wire model: counted.
  if (bus_.submit(kFar, f, stamp) != can::SubmitStatus::queued) ++refused_from_far_;
}

void OmniCanNetwork::flush_transport() {
  if (pending_.empty()) return;
  const std::size_t sent = transport_->send_many(pending_);
  to_transport_ += sent;
  send_failures_ += pending_.size() - sent;
  pending_.clear();
}

bool OmniCanNetwork::drain_transport(std::uint64_t count, SimTime t, std::chrono::milliseconds timeout) {
  flush_transport();  // (the run has flushed before its grant; nothing is left here then)
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (from_transport_ < count) {
    if (auto r = transport_->receive()) {
      ++from_transport_;
      submit_from_far(r->frame, t);
      continue;
    }
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0 || !can::wait_readable(*transport_, left)) return from_transport_ >= count;
  }
  return true;
}

int OmniCanNetwork::poll_transport(SimTime t) {
  int n = 0;
  while (auto r = transport_->receive()) {
    ++from_transport_;
    ++n;
    submit_from_far(r->frame, t);
  }
  return n;
}

// ---------------------------------------------------------------------------------------
// Bus callbacks

void OmniCanNetwork::on_deliver(can::BusNode receiver, const can::Frame& f, const can::FrameTiming& timing) {
  if (receiver == kFar) return;  // the far side heard it on the transport (on_tx_done)
  const int i = receiver - 1;
  if (lose(i)) {
    ++lost_frames_;
    return;
  }
  omni::OmniSlave& sl = *slaves_[static_cast<std::size_t>(i)];
  const std::uint64_t before = sl.stats().steps();
  const omni::TimerAction a = sl.on_frame(f, timing.end_ns);
  after_slave_input(i, before, a);
}

void OmniCanNetwork::on_tx_done(can::BusNode sender, const can::Frame& f, const can::FrameTiming& timing) {
  if (pcap_) pcap_->write(f, timing.end_ns, sender == kFar ? can::Direction::rx : can::Direction::tx);
  if (sender == kFar) {
    if (master_start_ns_ < 0 && is_start_all(f)) master_start_ns_ = timing.end_ns;
    if (is_nmt_all(f)) bus_stopped_ = f.data[1] == kNmtStop;
    return;
  }
  // A slave's frame reaches the master (and anyone else on the transport) when it completes.
  if (lose(FaultSpec::kMaster)) {
    ++lost_frames_;
    return;
  }
  if (batch_) {
    pending_.push_back(can::TimedFrame{f, timing.end_ns});
    if (pending_.size() >= kPendingCapacity) flush_transport();
  } else if (transport_->send(f, timing.end_ns)) {
    ++to_transport_;
  } else {
    ++send_failures_;
  }
}

void OmniCanNetwork::on_bus_event(const can::BusEvent& e) {
  if (e.kind == can::BusEventKind::error_frame || e.node == kFar) return;  // counted by the bus
  const std::string who = node_name(e.node - 1);
  if (e.kind == can::BusEventKind::state_changed) {
    if (e.state == can::ErrorState::bus_off) ++bus_off_events_;
    hooks_.log(e.t_ns, "can", fmt::format("{} is {}", who, state_name(e.state)));
  } else {
    hooks_.log(e.t_ns, "can", fmt::format("{} recovered from bus-off", who));
  }
}

// ---------------------------------------------------------------------------------------
// Slaves

void OmniCanNetwork::on_slave_timer(int i, SimTime t) {
  bus_.advance(t);  // frames that complete at or before the interrupt are in its FIFO
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
  // The driver follows the chain's output (the zero code after a stop).
  hooks_.set_setpoint(i, sl.setpoint());
  if (sl.stats().steps() > steps_before) {  // a skipped interrupt (no new command) logs nothing
    const physics::WheelDriveSample& w = sl.drive_chain().last();
    hooks_.axis_sample(i, w.command - w.delta_counts);
  }
}

// ---------------------------------------------------------------------------------------
// Faults

bool OmniCanNetwork::lose(int target) {
  for (LossState* l : {&loss_[static_cast<std::size_t>(target)], &loss_[FaultSpec::kAllNodes]}) {
    if (!l->active) continue;
    if (l->left > 0) {
      --l->left;
      return true;
    }
    if (std::uniform_real_distribution<double>(0.0, 1.0)(rng_) < l->rate) {
      l->left = l->burst - 1;
      return true;
    }
  }
  return false;
}

std::int64_t OmniCanNetwork::extra_delay(int node) {
  const DelayState& d = delay_[static_cast<std::size_t>(node)];
  if (!d.active) return 0;
  const double jitter = d.jitter_ns > 0 ? std::uniform_real_distribution<double>(0.0, d.jitter_ns)(rng_) : 0.0;
  return std::llround(d.extra_ns + jitter);
}

void OmniCanNetwork::apply_fault(const FaultSpec& f, bool begin, SimTime t) {
  // The loader only lets each kind name the nodes it can act on; a hand-built fault that
  // names another is a programmer error.
  const bool slave = f.wheel >= 0 && f.wheel < 4;
  const bool ok = f.kind == FaultSpec::Kind::frame_loss ? (slave || f.wheel == FaultSpec::kMaster || f.wheel == FaultSpec::kAllNodes)
                  : f.kind == FaultSpec::Kind::delay    ? (slave || f.wheel == FaultSpec::kMaster)
                                                        : slave;
  if (!ok) throw std::invalid_argument(fmt::format("CAN fault {} cannot act on node {}", to_string(f.kind), f.wheel));
  bus_.advance(t);
  const std::size_t n = static_cast<std::size_t>(f.wheel);
  const std::string who = node_name(f.wheel);
  const char* edge = begin ? "begins" : "ends";
  switch (f.kind) {
    case FaultSpec::Kind::frame_loss:
      loss_[n] = LossState{f.rate, f.burst, 0, begin};
      hooks_.log(t, "fault", fmt::format("frame_loss to {} rate {} burst {} ({})", who, f.rate, f.burst, edge));
      return;
    case FaultSpec::Kind::delay:
      delay_[n] = DelayState{f.extra_ms * 1e6, f.jitter_ms * 1e6, begin};
      hooks_.log(t, "fault", fmt::format("delay of {} +{} ms jitter {} ms ({})", who, f.extra_ms, f.jitter_ms, edge));
      return;
    case FaultSpec::Kind::drift: {
      const double d = begin ? f.drift : s_.bus.can.drift[n];
      sched_.set_drift(timers_[n], d);
      slaves_[n]->set_drift(d);  // so that an NMT start or a resync asks for the same period
      hooks_.log(t, "fault", fmt::format("drift of {} now {} ({})", who, d, edge));
      return;
    }
    case FaultSpec::Kind::power_loss:
      if (begin) {
        // Off the bus, timer dead, drive output gone; the node's counts so far are kept.
        bus_.detach(bus_node(f.wheel), t);
        sched_.cancel(timers_[n]);
        powered_[n] = false;
        dropouts_before_[n] += slaves_[n]->stats().dropouts;
        samples_before_[n] += slaves_[n]->stats().samples;
        slaves_[n]->reset_statistics();  // carried over: count them once while it is off
        hooks_.set_setpoint(f.wheel, 0.0);
      } else {
        // Power-on reset: a fresh node, stopped, counter from zero at the shaft's angle, on the
        // oscillator it had (a drift fault still running goes on).
        const double drift = slaves_[n]->drift();
        make_slave(f.wheel);
        slaves_[n]->set_drift(drift);
        bus_.reattach(bus_node(f.wheel), t);
        powered_[n] = true;
        hooks_.set_setpoint(f.wheel, slaves_[n]->setpoint());
      }
      hooks_.log(t, "fault", fmt::format("power_loss of {} ({})", who, edge));
      return;
    case FaultSpec::Kind::bus_off:
      if (begin) {
        bus_.corrupt_frames_of(bus_node(f.wheel), 32);  // 32 × 8 > 255: bus-off
      } else if (!bus_.request_recovery(bus_node(f.wheel), t)) {
        hooks_.log(t, "fault", fmt::format("bus_off of {}: not bus-off, no recovery needed", who));
        return;
      }
      hooks_.log(t, "fault", fmt::format("bus_off of {} ({}{})", who, edge, begin ? "" : ": recovery requested"));
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
  const std::uint64_t samples = samples_before_[n] + st.samples;
  const std::uint64_t dropouts = dropouts_before_[n] + st.dropouts;
  const can::NodeStats& ns = bus_.node_stats(bus_node(i));
  return {{"node", sl.config().node_id},
          {"state", powered_[n] ? omni::to_string(sl.state()) : "off"},
          {"samples", samples},
          {"dropouts", dropouts},
          {"dropout_percent", samples ? 100.0 * static_cast<double>(dropouts) / static_cast<double>(samples) : 0.0},
          {"first_dropout_sample", st.first_dropout_sample},
          {"resyncs", st.resyncs},
          {"commands", st.commands},
          {"stale_samples", st.stale_samples},
          {"start_phase", start_phase_[n]},
          {"frames_received", st.frames_received},
          {"frames_sent", st.frames_sent},
          {"bad_frames", st.bad_frames},
          {"fifo_overruns", st.frames_overrun},
          {"can_state", state_name(bus_.error_state(bus_node(i)))},
          {"tec", bus_.tec(bus_node(i))},
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
  b.frames_tx = to_transport_ + pending_.size();  // (any still batched are sent at the end)
  b.frames_rx = from_transport_;
  std::uint64_t bad = 0;
  for (std::size_t i = 0; i < 4; ++i) {
    b.dropouts += dropouts_before_[i] + slaves_[i]->stats().dropouts;
    bad += slaves_[i]->stats().bad_frames;
  }
  const can::TransportStats ts = transport_->stats();
  const std::uint64_t malformed = ts.malformed_rx + ts.wrong_dlc_rx + ts.bad_id_rx + ts.unsupported_rx;
  b.errors = bus_.stats().error_frames + malformed + bad + send_failures_ + refused_from_far_;
  return b;
}

DriveStateCode OmniCanNetwork::drive_state(int axis0) const {
  const auto i = static_cast<std::size_t>(axis0);
  if (!powered_[i]) return DriveStateCode::off;
  if (bus_.error_state(bus_node(axis0)) == can::ErrorState::bus_off) return DriveStateCode::fault;
  switch (slaves_[i]->state()) {
    case omni::SlaveState::stopped: return DriveStateCode::waiting;
    case omni::SlaveState::running: return DriveStateCode::running;
    case omni::SlaveState::awaiting_sync: return DriveStateCode::syncing;
  }
  return DriveStateCode::waiting;
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
  for (std::size_t i = 0; i < 4; ++i) samples += samples_before_[i] + slaves_[i]->stats().samples;
  const std::uint64_t dropouts = b.dropouts;
  const can::TransportStats ts = transport_->stats();
  const std::uint64_t malformed = ts.malformed_rx + ts.wrong_dlc_rx + ts.bad_id_rx + ts.unsupported_rx;
  return {{"name", "can"},
          {"bit_rate", s_.bus.can.bit_rate},
          {"transport", transport_->spec()},
          {"frames_tx", b.frames_tx},
          {"frames_rx", b.frames_rx},
          {"frames", bus_.stats().frames},
          {"error_frames", bus_.stats().error_frames},
          {"lost_frames", lost_frames_},
          {"bus_off_events", bus_off_events_},
          {"load", bus_.bus_load(now)},
          {"dropouts", dropouts},
          {"dropout_rate", samples ? static_cast<double>(dropouts) / static_cast<double>(samples) : 0.0},
          {"errors", b.errors},
          {"refused_from_transport", refused_from_far_},
          {"transport_rx_malformed", malformed},
          {"transport_send_failures", send_failures_},  // already counts the OS refusals (send_errors)
          {"transport_send_waits", ts.send_waits},
          {"pcap_frames", pcap_ ? pcap_->written() : 0},
          {"sync", s_.bus.can.sync}};
}

}  // namespace omnitwin::twin
