// twin layer — the twin's side of a CANopen network; see canopen_network.hpp.
#include "twin/canopen_network.hpp"

#include <fmt/format.h>

#include "bus_emulators/can/can_bits.hpp"

#include <cmath>
#include <filesystem>
#include <numbers>
#include <stdexcept>

namespace omnitwin::twin {

namespace {

constexpr int kBusNodes = 5;
constexpr std::size_t kPendingCapacity = 256;
constexpr double kTwoPi = 2 * std::numbers::pi;

double timer_drift(double d) { return 1.0 / (1.0 + d) - 1.0; }

can::BusConfig bus_config(const Scenario& s) {
  can::BusConfig c;
  c.bit_rate_bps = s.bus.can.bit_rate;
  c.queue_capacity = 64;
  c.max_nodes = kBusNodes;
  return c;
}

const char* error_state_name(can::ErrorState e) {
  switch (e) {
    case can::ErrorState::error_active: return "error_active";
    case can::ErrorState::error_passive: return "error_passive";
    case can::ErrorState::bus_off: return "bus_off";
  }
  return "?";
}

// NMT to all nodes: 0x000 [cs 00].
bool is_nmt_all(const can::Frame& f, std::uint8_t cs) {
  return f.id == 0 && !f.extended && f.kind == can::FrameKind::data && f.dlc == 2 && f.data[0] == cs && f.data[1] == 0;
}

std::string node_name(int fault_node) {
  if (fault_node == FaultSpec::kMaster) return "master";
  if (fault_node == FaultSpec::kAllNodes) return "all nodes";
  return fmt::format("axis {} (node {})", fault_node + 1, fault_node + 1);
}

}  // namespace

LoadBudget canopen_load_budget(const Scenario& s) {
  const CanopenSpec& c = s.bus.canopen;
  LoadBudget out;
  for (const bool worst : {false, true}) {
    // A frame's bits: all-zero data (the stuffing a run mostly sees) or the worst case.
    auto bits = [worst](std::uint32_t id, int bytes) {
      if (worst) return static_cast<double>(can::worst_case_frame_bits(false, bytes));
      return static_cast<double>(can::frame_bits_with_intermission(canopen::frame11(id, static_cast<std::uint8_t>(bytes))));
    };
    const double per_s = 1.0 / c.cycle;
    double b = per_s * (bits(0x80, 0) + 4 * bits(0x201, 6) + 4 * bits(0x181, 6));  // SYNC, RPDO1, TPDO1
    b += 4 * bits(0x281, 6) * per_s / 10;                                          // TPDO2, inhibit 10 SYNCs
    b += 5 * bits(0x701, 1) * 1000.0 / c.heartbeat_ms;                             // four drives and the master
    (worst ? out.worst : out.nominal) = b / static_cast<double>(s.bus.can.bit_rate);
  }
  return out;
}

std::string canopen_eds_path(const CanopenSpec& c) {
  if (!c.eds.empty()) return std::filesystem::absolute(c.eds).lexically_normal().string();
  return std::string(OMNITWIN_SOURCE_DIR) + "/models/canopen/omnitwin_drive.eds";
}

CanopenNetwork::CanopenNetwork(const Scenario& s, Scheduler& sched, Hooks hooks)
    : s_(s),
      spec_(s.bus.canopen),
      sched_(sched),
      hooks_(std::move(hooks)),
      eds_(canopen::load_eds(canopen_eds_path(s.bus.canopen))),
      bus_(bus_config(s)),
      rng_(s.bus.can.seed) {
  for (int i = 0; i < kBusNodes; ++i) bus_.attach();
  bus_.on_deliver([this](can::BusNode r, const can::Frame& f, const can::FrameTiming& t) { on_deliver(r, f, t); });
  bus_.on_tx_done([this](can::BusNode n, const can::Frame& f, const can::FrameTiming& t) { on_tx_done(n, f, t); });
  bus_.on_event([this](const can::BusEvent& e) { on_bus_event(e); });
  const SimTime period = std::llround(spec_.drive_period * 1e9);
  for (int i = 0; i < 4; ++i) {
    const auto k = static_cast<std::size_t>(i);
    drive::DriveConfig dc;
    dc.counts_per_rev = spec_.counts_per_rev;
    dc.gear_ratio = 1.0;
    dc.period_s = spec_.drive_period;
    dc.max_speed_rad_s = s.platform.motor.speed_limit;
    dc.rated_torque_nm = s.platform.motor.torque_limit;
    auto send = [this, i](const can::Frame& f, SimTime at) {
      return bus_.submit(bus_node(i), f, at + extra_delay(i)) == can::SubmitStatus::queued;
    };
    drives_[k] = std::make_unique<canopen::DriveNode>(eds_, static_cast<std::uint8_t>(i + 1), dc, send);
    // Each drive's firmware cycle on its own oscillator, the four starting at different instants.
    timers_[k] = sched_.add_periodic(fmt::format("canopen-node{}", i + 1), Phase::device, period / (i + 2), period,
                                     [this, i](SimTime t) { on_drive_timer(i, t); }, timer_drift(spec_.drift[k]));
    last_nmt_[k] = canopen::NmtState::initialising;
    last_fsa_[k] = drive::State::not_ready_to_switch_on;
  }
  transport_ = can::open_transport(s.bus.can.transport);
  batch_ = s.clock == ClockMode::lockstep;
  pending_.reserve(kPendingCapacity);
  // Power on at t = 0: each node's boot-up message goes onto the wire.
  for (auto& d : drives_) d->power_on(0);
  budget_ = canopen_load_budget(s);
}

CanopenNetwork::~CanopenNetwork() { flush_transport(); }

void CanopenNetwork::open_pcap(const std::string& path) {
  // The run's records are open now: the configuration's budget goes into events.log.
  hooks_.log(0, "bus", fmt::format("load budget {:.1f} % of {} bit/s at a {} ms SYNC ({:.1f} % with worst-case bit "
                                   "stuffing){}",
                                   100 * budget_.nominal, s_.bus.can.bit_rate, spec_.cycle * 1e3, 100 * budget_.worst,
                                   budget_.nominal > 1 ? ": the configuration does not fit the wire" : ""));
  can::PcapWriter::Options o;
  o.flush_each_packet = false;
  pcap_ = std::make_unique<can::PcapWriter>(path, o);
}

std::string CanopenNetwork::close_pcap() { return close_capture(pcap_.get()); }
std::string CanopenNetwork::pcap_error() const { return capture_error(pcap_.get()); }

// ---------------------------------------------------------------------------------------
// The transport side

void CanopenNetwork::submit_from_far(const can::Frame& f, SimTime t) {
  const SimTime stamp = t + std::llround(s_.bus.can.t_pre_us * 1e3) + extra_delay(FaultSpec::kMaster);
  if (bus_.submit(kFar, f, stamp) != can::SubmitStatus::queued) ++refused_from_far_;
}

void CanopenNetwork::flush_transport() {
  if (pending_.empty()) return;
  const std::size_t sent = transport_->send_many(pending_);
  to_transport_ += sent;
  send_failures_ += pending_.size() - sent;
  pending_.clear();
}

bool CanopenNetwork::drain_transport(std::uint64_t count, SimTime t, std::chrono::milliseconds timeout) {
  flush_transport();
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

int CanopenNetwork::poll_transport(SimTime t) {
  int n = 0;
  while (auto r = transport_->receive()) {
    ++from_transport_;
    ++n;
    submit_from_far(r->frame, t);
  }
  return n;
}

// ---------------------------------------------------------------------------------------
// Wire callbacks

void CanopenNetwork::on_deliver(can::BusNode receiver, const can::Frame& f, const can::FrameTiming& timing) {
  if (receiver == kFar) return;  // the far side hears it through the transport (on_tx_done)
  const int i = receiver - 1;
  if (lose(i)) {
    ++lost_frames_;
    return;
  }
  drives_[static_cast<std::size_t>(i)]->on_frame(f, timing.end_ns);
  watch(i, timing.end_ns);
}

void CanopenNetwork::on_tx_done(can::BusNode sender, const can::Frame& f, const can::FrameTiming& timing) {
  if (pcap_) pcap_->write(f, timing.end_ns, sender == kFar ? can::Direction::rx : can::Direction::tx);
  if (sender == kFar) {
    if (is_nmt_all(f, 0x01)) {
      if (master_start_ns_ < 0) master_start_ns_ = timing.end_ns;
      bus_stopped_ = false;
    }
    if (is_nmt_all(f, 0x02)) bus_stopped_ = true;
    return;
  }
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

void CanopenNetwork::on_bus_event(const can::BusEvent& e) {
  if (e.kind == can::BusEventKind::error_frame || e.node == kFar) return;
  const int i = e.node - 1;
  const std::string who = node_name(i);
  if (e.kind == can::BusEventKind::state_changed) {
    if (e.state == can::ErrorState::bus_off) ++bus_off_events_;
    hooks_.log(e.t_ns, "can", fmt::format("{} is {}", who, error_state_name(e.state)));
  } else {
    hooks_.log(e.t_ns, "can", fmt::format("{} recovered from bus-off", who));
    drives_[static_cast<std::size_t>(i)]->on_bus_off_recovered(e.t_ns);  // EMCY 0x8140, error behaviour
  }
}

// ---------------------------------------------------------------------------------------
// Drives

void CanopenNetwork::on_drive_timer(int i, SimTime t) {
  const auto k = static_cast<std::size_t>(i);
  if (!powered_[k]) return;
  bus_.advance(t);
  drive::Feedback fb;
  fb.position_rad = hooks_.wheel_angle(i);
  fb.velocity_rad_s = hooks_.wheel_speed(i);
  canopen::DriveNode& d = *drives_[k];
  const drive::Command c = d.step(t, fb);
  hooks_.set_setpoint(i, (c.power && !c.brake_engaged) ? c.velocity_rad_s : 0.0);
  const drive::Objects& o = d.drive().objects();
  if (o.velocity_demand != 0 || o.velocity_actual != 0)
    hooks_.axis_sample(i, static_cast<double>(o.velocity_demand - o.velocity_actual) * spec_.drive_period);
  watch(i, t);
}

// NMT and drive state changes go to the event log.
void CanopenNetwork::watch(int i, SimTime t) {
  const auto k = static_cast<std::size_t>(i);
  const canopen::DriveNode& d = *drives_[k];
  const canopen::NmtState nmt = d.node().state();
  const drive::State fsa = d.drive().state();
  if (nmt == last_nmt_[k] && fsa == last_fsa_[k]) return;
  std::string text = fmt::format("node {} NMT {}, drive {}", i + 1, canopen::to_string(nmt), drive::to_string(fsa));
  if (fsa == drive::State::fault) text += fmt::format(" (error 0x{:04X})", d.drive().objects().error_code);
  if (hooks_.log) hooks_.log(t, "bus", text);
  last_nmt_[k] = nmt;
  last_fsa_[k] = fsa;
}

// ---------------------------------------------------------------------------------------
// Faults

bool CanopenNetwork::lose(int target) {
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

std::int64_t CanopenNetwork::extra_delay(int node) {
  const DelayState& d = delay_[static_cast<std::size_t>(node)];
  if (!d.active) return 0;
  const double jitter = d.jitter_ns > 0 ? std::uniform_real_distribution<double>(0.0, d.jitter_ns)(rng_) : 0.0;
  return std::llround(d.extra_ns + jitter);
}

void CanopenNetwork::apply_fault(const FaultSpec& f, bool begin, SimTime t) {
  const bool slave = f.wheel >= 0 && f.wheel < 4;
  const bool ok = f.kind == FaultSpec::Kind::frame_loss ? (slave || f.wheel == FaultSpec::kMaster || f.wheel == FaultSpec::kAllNodes)
                  : f.kind == FaultSpec::Kind::delay    ? (slave || f.wheel == FaultSpec::kMaster)
                                                        : slave || f.kind == FaultSpec::Kind::wheel_slip;
  if (!ok) throw std::invalid_argument(fmt::format("CANopen fault {} cannot act on node {}", to_string(f.kind), f.wheel));
  bus_.advance(t);
  const auto n = static_cast<std::size_t>(f.wheel);
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
      const double d = begin ? f.drift : spec_.drift[n];
      sched_.set_drift(timers_[n], timer_drift(d));
      hooks_.log(t, "fault", fmt::format("drift of {} now {} ({})", who, d, edge));
      return;
    }
    case FaultSpec::Kind::power_loss:
      if (begin) {
        bus_.detach(bus_node(f.wheel), t);
        drives_[n]->power_off();
        powered_[n] = false;
        hooks_.set_setpoint(f.wheel, 0.0);
      } else {
        // Power-on: a fresh node (boot-up message) and drive in their power-on state.
        bus_.reattach(bus_node(f.wheel), t);
        powered_[n] = true;
        drives_[n]->power_on(t);
        ++power_cycles_;
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
      return;
    case FaultSpec::Kind::link_break:
    case FaultSpec::Kind::corruption:
    case FaultSpec::Kind::second_master:
      throw std::invalid_argument(fmt::format("CANopen network: {} is not a CAN fault", to_string(f.kind)));
  }
}

// ---------------------------------------------------------------------------------------
// Metrics

nlohmann::json CanopenNetwork::slave_json(int i) const {
  const auto k = static_cast<std::size_t>(i);
  const canopen::DriveNode& d = *drives_[k];
  const canopen::Node& node = d.node();
  const canopen::PdoStats& p = node.pdo().stats();
  const can::NodeStats& ns = bus_.node_stats(bus_node(i));
  return {{"node", i + 1},
          {"nmt_state", powered_[k] ? canopen::to_string(node.state()) : "off"},
          {"drive_state", drive::to_string(d.drive().state())},
          {"error_code", d.drive().objects().error_code},
          {"emcy", node.emcy().sent()},
          {"sdo_requests", node.sdo().stats().requests},
          {"sdo_aborts", node.sdo().stats().aborts_sent},
          {"rpdo_rx", p.rpdo_rx},
          {"tpdo_tx", p.tpdo_tx},
          {"pdo_length_errors", p.length_errors},
          {"syncs", node.stats().syncs},
          {"heartbeats", node.error_control().heartbeats_sent()},
          {"faults", d.stats().faults},
          {"comm_faults", d.stats().comm_faults},
          {"can_state", error_state_name(bus_.error_state(bus_node(i)))},
          {"tec", bus_.tec(bus_node(i))},
          {"tx_errors", ns.tx_errors},
          {"bus_off_events", ns.bus_off_events}};
}

nlohmann::json CanopenNetwork::slave_metrics() const {
  nlohmann::json a = nlohmann::json::array();
  for (int i = 0; i < 4; ++i) a.push_back(slave_json(i));
  return a;
}

BusSample CanopenNetwork::bus_sample() const {
  BusSample b;
  b.has_frames = true;
  b.frames_tx = to_transport_ + pending_.size();
  b.frames_rx = from_transport_;
  const can::TransportStats ts = transport_->stats();
  const std::uint64_t malformed = ts.malformed_rx + ts.wrong_dlc_rx + ts.bad_id_rx + ts.unsupported_rx;
  b.errors = bus_.stats().error_frames + malformed + send_failures_ + refused_from_far_;
  return b;
}

DriveStateCode CanopenNetwork::drive_state(int axis0) const {
  const auto k = static_cast<std::size_t>(axis0);
  if (!powered_[k]) return DriveStateCode::off;
  if (bus_.error_state(bus_node(axis0)) == can::ErrorState::bus_off) return DriveStateCode::fault;
  const canopen::DriveNode& d = *drives_[k];
  const drive::State fsa = d.drive().state();
  if (fsa == drive::State::fault || fsa == drive::State::fault_reaction_active) return DriveStateCode::fault;
  if (d.node().state() == canopen::NmtState::operational && fsa == drive::State::operation_enabled)
    return DriveStateCode::running;
  return DriveStateCode::waiting;
}

WheelRecord CanopenNetwork::wheel_record(int axis0) const {
  const canopen::DriveNode& d = *drives_[static_cast<std::size_t>(axis0)];
  const drive::Objects& o = d.drive().objects();
  const double per_rad = spec_.counts_per_rev / kTwoPi;
  WheelRecord r;
  r.command_rad_s = static_cast<double>(o.target_velocity) / per_rad;
  r.count = static_cast<double>(o.position_actual);
  r.command_counts = static_cast<double>(o.velocity_demand);
  r.measured_counts = static_cast<double>(o.velocity_actual);
  r.output = static_cast<double>(o.torque_demand);
  r.node = static_cast<std::uint16_t>(axis0 + 1);
  return r;
}

nlohmann::json CanopenNetwork::bus_metrics(SimTime now) const {
  const BusSample b = bus_sample();
  const can::TransportStats ts = transport_->stats();
  const std::uint64_t malformed = ts.malformed_rx + ts.wrong_dlc_rx + ts.bad_id_rx + ts.unsupported_rx;
  std::uint64_t emcy = 0, aborts = 0;
  for (const auto& d : drives_) emcy += d->node().emcy().sent(), aborts += d->node().sdo().stats().aborts_sent;
  return {{"name", "canopen"},
          {"bit_rate", s_.bus.can.bit_rate},
          {"transport", transport_->spec()},
          {"eds", canopen_eds_path(spec_)},
          {"frames_tx", b.frames_tx},
          {"frames_rx", b.frames_rx},
          {"frames", bus_.stats().frames},
          {"error_frames", bus_.stats().error_frames},
          {"lost_frames", lost_frames_},
          {"bus_off_events", bus_off_events_},
          {"load", bus_.bus_load(now)},
          {"load_budget", budget_.nominal},
          {"load_budget_worst", budget_.worst},
          {"dropouts", 0},
          {"errors", b.errors},
          {"emcy", emcy},
          {"sdo_aborts", aborts},
          {"power_cycles", power_cycles_},
          {"refused_from_transport", refused_from_far_},
          {"transport_rx_malformed", malformed},
          {"transport_send_failures", send_failures_},
          {"pcap_frames", pcap_ ? pcap_->written() : 0}};
}

}  // namespace omnitwin::twin
