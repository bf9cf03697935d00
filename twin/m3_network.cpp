// twin layer — the twin's side of a MECHATROLINK-III line; see m3_network.hpp.
#include "twin/m3_network.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "bus_emulators/drive/axis_model.hpp"
#include "bus_emulators/ethercat/transport/ec_veth.hpp"
#include "twin/line_transport.hpp"

namespace omnitwin::twin {

namespace {

constexpr double kTwoPi = 2 * std::numbers::pi;

m3::SegmentConfig segment_config(const Scenario& s) {
  const M3Spec& m = s.bus.m3;
  m3::SegmentConfig c;
  c.topology = m.topology == "star" ? m3::Topology::star_of(m.stations, m.cable_m)
                                    : m3::Topology::cascade_of(m.stations, m.cable_m);
  c.response_ns = std::llround(m.response_us * 1e3);
  c.servo.drive.counts_per_rev = m.counts_per_rev;
  c.servo.drive.gear_ratio = 1.0;
  c.servo.drive.period_s = m.drive_period;
  c.servo.drive.max_speed_rad_s = s.platform.motor.speed_limit;
  c.servo.drive.rated_torque_nm = s.platform.motor.torque_limit;
  return c;
}

}  // namespace

M3Network::M3Network(const Scenario& s, Scheduler& sched, Hooks hooks)
    : spec_(s.bus.m3), clock_(s.clock), sched_(sched), hooks_(std::move(hooks)), rng_(s.bus.m3.seed), jitter_rng_(s.bus.m3.seed ^ 0x6a09e667f3bcc908ULL) {
  open_transport(s);
  segment_ = std::make_unique<m3::M3Segment>(segment_config(s), *transport_);
  segment_->line().set_fault_hook(
      [this](bool from_master, int k, std::span<const std::uint8_t> f) { return fate(from_master, k, f); });
  const int n = spec_.stations;
  powered_.assign(static_cast<std::size_t>(n), true);
  loss_.assign(static_cast<std::size_t>(n), 0.0);
  corrupt_.assign(static_cast<std::size_t>(n), 0.0);
  delay_ns_.assign(static_cast<std::size_t>(n), 0);
  jitter_ns_.assign(static_cast<std::size_t>(n), 0);
  last_.assign(static_cast<std::size_t>(n), {});
  shafts_.resize(static_cast<std::size_t>(n - 4));  // the servos beyond the wheels turn no wheel
  // Each servo's drive period, a little apart (they follow the master's SYNC for
  // communication; their control loops run on their own).
  const SimTime period = std::llround(spec_.drive_period * 1e9);
  for (int i = 0; i < n; ++i)
    sched_.add_periodic(fmt::format("m3-servo{}", i + 1), Phase::device, period * (i % 8 + 1) / 8, period,
                        [this, i](SimTime t) { on_drive_timer(i, t); });
}

M3Network::~M3Network() = default;

void M3Network::open_transport(const Scenario& s) {
  // auto: veth as root, else UDP on loopback (lockstep: a free port; realtime: the documented one).
  LineTransport line = choose_line_transport(spec_.transport, spec_.master_iface, s.clock == ClockMode::lockstep,
                                             "udp:127.0.0.1:34997");
  veth_ = line.veth;
  transport_spec_ = line.slaves_spec;
  // The interfaces the scenario names are claimed, the slaves' and the master's end alike (a
  // second twin on the other end of the same link was let run; found in review). A pair made
  // for the run is the run's own.
  if (!veth_) claim_interfaces(claims_, {transport_spec_, line.master_iface});
  transport_ = m3::open_transport(transport_spec_, m3::Role::slaves);
  transport_->set_refuse_foreign_senders(spec_.refuse_foreign);
  if (!(s.clock == ClockMode::lockstep)) transport_->set_master_handover(kMasterHandoverNs);
  // UDP on port 0: the master is told the port the slaves' socket was given.
  master_iface_ = line.master_iface.empty() ? transport_->spec() : line.master_iface;
}

void M3Network::flush_pcap() {
  segment_->flush_capture();
  if (segment_->pcap()) segment_->pcap()->flush();
}

std::string M3Network::pcap_error() const {
  return capture_error(segment_->pcap());
}

// ---- frames ----------------------------------------------------------------------------

// The line's fault hook: a frame to (from_master) or from slave k is lost, corrupted or passes.
m3::Fate M3Network::fate(bool from_master, int k, std::span<const std::uint8_t>) {
  if (k < 0 || k >= spec_.stations) return m3::Fate::deliver;
  const auto i = static_cast<std::size_t>(k);
  // A delay fault's jitter, drawn per response: the line adds the extra delay it is given here
  // to this very frame (Line::from_slave asks the fate first).
  if (!from_master && jitter_ns_[i] > 0)
    segment_->line().set_extra_delay(
        k, delay_ns_[i] + std::llround(std::uniform_real_distribution<double>(0, double(jitter_ns_[i]))(jitter_rng_)));
  const double loss = from_master ? std::max(loss_[i], master_loss_) : loss_[i];
  if (loss > 0 && std::uniform_real_distribution<double>(0, 1)(rng_) < loss) {
    ++lost_;
    return m3::Fate::drop;
  }
  const double corrupt = from_master ? std::max(corrupt_[i], master_corrupt_) : corrupt_[i];
  if (corrupt > 0 && std::uniform_real_distribution<double>(0, 1)(rng_) < corrupt) {
    ++corrupted_;
    return m3::Fate::corrupt;
  }
  return m3::Fate::deliver;
}

// The second C1 master's commands, one NOP per station, at the tick's instant: address 01h
// like ours, a WDT count stuck at 5 (so a slave whose previous command carried 5 sees it
// repeat: a WDT error).
void M3Network::flush_transport() {
  if (!second_master_) return;
  std::array<std::uint8_t, m3::kMaxFrame> out{};
  std::array<std::uint8_t, 32> cmd{};
  m3::write_header(cmd, m3::CommandHeader{static_cast<std::uint8_t>(m3::Command::nop), 0x50, 0});
  second_sequence_ = static_cast<std::uint8_t>((second_sequence_ + 1) & 0xF);
  SimTime at = linked_to_;
  for (int k = 0; k < spec_.stations; ++k) {
    const std::size_t n = m3::encode(m3::FrameSpec{.dst = static_cast<std::uint8_t>(m3::kFirstSlave + k),
                                                   .src = m3::kC1Master, .type = m3::FrameType::cyclic_command,
                                                   .sequence = second_sequence_, .retry = false, .data = cmd},
                                     out);
    segment_->inject(std::span<const std::uint8_t>(out.data(), n), at);
    at += m3::frame_slot_ns(cmd.size());
  }
}

void M3Network::advance(SimTime t) {
  if (t <= linked_to_) return;  // the exchange inside a tick may already have run them further
  linked_to_ = t;
  segment_->advance(t);
}

simclock::Horizon M3Network::on_sent(const simclock::Sent& s, std::chrono::milliseconds timeout) {
  advance(s.t_ns);
  const m3::SegmentAnswer a = segment_->take_sent(s.frames[0], s.t_ns, timeout);
  simclock::Horizon h;
  h.tick = s.tick;
  h.arrival_ns = a.ok ? a.arrival_ns : -2;
  h.frames[0] = a.to_master;
  return h;
}

// Lockstep: every frame was met inside the tick; one the master counted but never reported
// is taken now, at the tick's instant.
bool M3Network::drain_transport(std::uint64_t count, SimTime t, std::chrono::milliseconds timeout) {
  if (segment_->from_master() >= count) return true;
  return segment_->take_sent(count, t, timeout).ok;
}

// Realtime: frames are taken only when the pacer wakes on the transport (on_wake), each
// stamped with its arrival (the kernel's receive time). Taking them here, before a physics
// step, would stamp them with that step's simulated time instead.
int M3Network::poll_transport(SimTime) { return 0; }

void M3Network::on_wake(SimTime t) {
  segment_->poll(t, linked_to_);  // each frame at its arrival, the slaves' timers up to it
  advance(t);
}

int M3Network::wake_fd() const { return transport_->fd(); }

// ---- servos ----------------------------------------------------------------------------

// One drive period of servo k against its wheel: feedback from the shaft, setpoint back. A
// servo beyond the wheels drives its own unloaded shaft.
void M3Network::on_drive_timer(int axis0, SimTime t) {
  advance(t);
  const auto k = static_cast<std::size_t>(axis0);
  if (!powered_[k]) return;
  if (axis0 >= 4) {
    drive::AxisModel& shaft = shafts_[k - 4];
    shaft.step(segment_->step_drive(axis0, t, shaft.feedback()), spec_.drive_period);
    return watch_states(t);
  }
  drive::Feedback fb;
  fb.position_rad = hooks_.wheel_angle(axis0);
  fb.velocity_rad_s = hooks_.wheel_speed(axis0);
  const drive::Command c = segment_->step_drive(axis0, t, fb);
  hooks_.set_setpoint(axis0, (c.power && !c.brake_engaged) ? c.velocity_rad_s : 0.0);
  watch_states(t);
}

// Events for phase, alarm and servo changes, and the instant all four servos first were on.
void M3Network::watch_states(SimTime t) {
  bool all_on = true;
  for (int i = 0; i < spec_.stations; ++i) {
    const auto k = static_cast<std::size_t>(i);
    const m3::SlaveLink& l = segment_->link(i);
    const StationState now{static_cast<std::uint8_t>(l.phase()), static_cast<std::uint8_t>(l.comm_alarm()),
                           static_cast<std::uint8_t>(l.cmd_alarm()),
                           static_cast<std::uint8_t>(segment_->servo(i).drive().state())};
    if (now != last_[k]) {
      if (hooks_.log)
        hooks_.log(t, "bus", fmt::format("slave {} ({:02X}h) phase {}, COMM_ALM {}, CMD_ALM {}, servo {}", i + 1,
                                         l.address(), now.phase, m3::to_string(l.comm_alarm()), m3::to_string(l.cmd_alarm()),
                                         drive::to_string(segment_->servo(i).drive().state())));
      last_[k] = now;
    }
    all_on = all_on && drive_state(i) == DriveStateCode::running;
  }
  if (all_on && running_since_ns_ < 0) running_since_ns_ = t;
}

// ---- faults ----------------------------------------------------------------------------

// A station is on the line when it has power, is not behind a cut cable and (cascade) every
// station between it and the master has power too: a dead station passes nothing on.
void M3Network::update_reachability() {
  const bool cascade = spec_.topology != "star";
  bool path = true;
  for (int k = 0; k < spec_.stations; ++k) {
    const bool cut = cut_after_ >= 0 && (cascade ? k >= cut_after_ : k == cut_after_);
    const bool on = powered_[static_cast<std::size_t>(k)] && !cut && path;
    segment_->line().set_reachable(k, on);
    if (cascade && (!powered_[static_cast<std::size_t>(k)] || cut)) path = false;
  }
}

void M3Network::set_power(int axis0, bool on, SimTime t) {
  const auto k = static_cast<std::size_t>(axis0);
  powered_[k] = on;
  if (on) {
    segment_->servo(axis0).power_cycle();
    segment_->link(axis0).power_on(t);
  } else {
    segment_->link(axis0).power_off(t);
    hooks_.set_setpoint(axis0, 0.0);  // the motor coasts
  }
  update_reachability();
}

void M3Network::apply_fault(const FaultSpec& f, bool begin, SimTime t) {
  advance(t);
  const int k = std::clamp(f.wheel, 0, 3);
  const bool all = f.wheel == FaultSpec::kAllNodes, master = f.wheel == FaultSpec::kMaster;
  const std::string who = all ? "every slave" : master ? "the master" : fmt::format("slave {}", k + 1);
  std::string what;
  switch (f.kind) {
    case FaultSpec::Kind::frame_loss:
      if (master) master_loss_ = begin ? f.rate : 0.0;
      for (int i = 0; i < spec_.stations; ++i)
        if (all || (!master && i == k)) loss_[static_cast<std::size_t>(i)] = begin ? f.rate : 0.0;
      what = fmt::format("frame_loss {} rate {}", who, f.rate);
      break;
    case FaultSpec::Kind::corruption:
      // Node master: the master's commands only, as frame_loss (it corrupted the slaves'
      // responses too, as `all`; found in review); a node: its commands and responses.
      if (master) master_corrupt_ = begin ? f.rate : 0.0;
      for (int i = 0; i < spec_.stations; ++i)
        if (all || (!master && i == k)) corrupt_[static_cast<std::size_t>(i)] = begin ? f.rate : 0.0;
      what = fmt::format("corruption {} rate {}", who, f.rate);
      break;
    case FaultSpec::Kind::delay: {
      // The jitter is drawn per frame (fate()). The one draw at the start stays so the loss and
      // corruption draws after it, and so the runs of existing scenarios, are unchanged.
      if (begin) (void)std::uniform_real_distribution<double>(0, f.jitter_ms * 1e6)(rng_);
      const SimTime extra = begin ? std::llround(f.extra_ms * 1e6) : 0;
      const SimTime jitter = begin ? std::llround(f.jitter_ms * 1e6) : 0;
      for (int i = 0; i < spec_.stations; ++i)
        if (master || i == k) {
          delay_ns_[static_cast<std::size_t>(i)] = extra;
          jitter_ns_[static_cast<std::size_t>(i)] = jitter;
          segment_->line().set_extra_delay(i, extra);
        }
      what = fmt::format("delay of {}'s responses {} ms", master ? std::string("every slave") : who, f.extra_ms);
      break;
    }
    case FaultSpec::Kind::power_loss:
      set_power(k, !begin, t);
      what = fmt::format("power_loss slave {}", k + 1);
      break;
    case FaultSpec::Kind::link_break:
      cut_after_ = begin ? f.wheel : -1;
      update_reachability();
      what = f.wheel == 0 ? std::string("link_break between master and slave 1") : fmt::format("link_break after slave {}", f.wheel);
      break;
    case FaultSpec::Kind::second_master:
      second_master_ = begin;
      what = "a second C1 master on the line";
      break;
    case FaultSpec::Kind::wheel_slip:
    case FaultSpec::Kind::drift:
    case FaultSpec::Kind::bus_off:
      return;  // not a fault of this bus (the scenario loader refuses drift and bus_off here)
  }
  if (hooks_.log) hooks_.log(t, "fault", fmt::format("{} ({})", what, begin ? "begins" : "ends"));
}

// ---- observation -----------------------------------------------------------------------

BusSample M3Network::bus_sample() const {
  BusSample b;
  b.has_frames = true;
  b.frames_tx = segment_->to_master();
  b.frames_rx = segment_->from_master();
  b.dropouts = segment_->line().dropped();
  const m3::M3Transport::Stats ts = transport_->stats();
  b.errors = segment_->line().corrupted() + segment_->send_failures() + segment_->line().overflow() + ts.dropped_malformed;
  return b;
}

DriveStateCode M3Network::drive_state(int axis0) const {
  if (!powered_[static_cast<std::size_t>(axis0)]) return DriveStateCode::off;
  const m3::SlaveLink& l = segment_->link(axis0);
  const m3::ServoProfile& servo = segment_->servo(axis0);
  // A communication warning (1h-3h: one frame missed or bad) is no fault: the servo runs on
  // (it read fault, so drives.faults counted four faulted drives that drove to the goal).
  if (servo.device_alarm() || m3::is_alarm(l.comm_alarm())) return DriveStateCode::fault;
  // Connected (phase 3 cyclic, phase 2 event-driven) with its servo on.
  const bool connected = l.phase() == m3::Phase::p3 || (l.phase() == m3::Phase::p2 && !l.connection().synchronous);
  return connected && servo.servo_on() ? DriveStateCode::running : DriveStateCode::waiting;
}

BusNetwork::DriveDetail M3Network::drive_detail(int axis0) const {
  if (!powered_[static_cast<std::size_t>(axis0)]) return {"off", ""};
  const m3::SlaveLink& l = segment_->link(axis0);
  const m3::ServoProfile& servo = segment_->servo(axis0);
  const char* comm = "phase 1";
  switch (l.phase()) {
    case m3::Phase::p1: comm = "phase 1"; break;
    case m3::Phase::p2: comm = "phase 2"; break;
    case m3::Phase::p3: comm = "phase 3"; break;
    case m3::Phase::p5: comm = "phase 5"; break;
  }
  if (l.comm_alarm() != m3::CommAlarm::normal) comm = m3::to_string(l.comm_alarm());
  const char* device = servo.device_alarm() ? "alarm" : servo.servo_on() ? "servo on" : "servo off";
  return {comm, device};
}

WheelRecord M3Network::wheel_record(int axis0) const {
  const m3::ServoProfile& servo = segment_->servo(axis0);
  const drive::Objects& o = servo.drive().objects();
  const double per_rad = spec_.counts_per_rev / kTwoPi;
  WheelRecord r;
  r.command_rad_s = static_cast<double>(o.velocity_demand) / per_rad;
  r.count = static_cast<double>(o.position_actual);
  r.command_counts = static_cast<double>(o.velocity_demand);
  r.measured_counts = static_cast<double>(o.velocity_actual);
  r.output = static_cast<double>(o.torque_demand);
  r.node = segment_->link(axis0).address();
  return r;
}

nlohmann::json M3Network::bus_metrics(SimTime now) const {
  const BusSample b = bus_sample();
  const double sim_s = static_cast<double>(now) * 1e-9;
  const m3::M3Transport::Stats ts = transport_->stats();
  return {{"name", "m3"},
          {"transport", transport_spec_},
          {"master_iface", master_iface_},
          {"topology", spec_.topology},
          {"cycle_ns", std::llround(spec_.cycle * 1e9)},
          {"frames_tx", b.frames_tx},
          {"frames_rx", b.frames_rx},
          {"dropouts", b.dropouts},
          {"dropout_rate", b.frames_rx > 0 ? static_cast<double>(b.dropouts) / static_cast<double>(b.frames_rx) : 0.0},
          {"errors", b.errors},
          {"lost_frames", lost_},
          {"corrupted_frames", corrupted_},
          {"malformed", ts.dropped_malformed},
          {"foreign_frames", ts.foreign_sender},  // from a sender other than the first (the master)
          {"refused_frames", ts.refused_sender},  // … of which dropped (bus.refuse_foreign)
          {"master_changes", ts.master_changes},  // senders taken for the master from a silent one
          {"send_failures", segment_->send_failures()},
          {"overflow", segment_->line().overflow()},
          {"load", sim_s > 0 ? static_cast<double>(segment_->busy_ns()) * 1e-9 / sim_s : 0.0},
          {"servos_on_since_s", running_since_ns_ < 0 ? -1.0 : static_cast<double>(running_since_ns_) * 1e-9}};
}

nlohmann::json M3Network::slave_metrics() const {
  nlohmann::json out = nlohmann::json::array();
  for (int i = 0; i < spec_.stations; ++i) {
    const m3::SlaveLink& l = segment_->link(i);
    const m3::LinkStats& st = l.stats();
    const drive::Cia402Drive& d = segment_->servo(i).drive();
    out.push_back({{"position", i},
                   {"address", l.address()},
                   {"phase", static_cast<int>(l.phase())},
                   {"comm_alarm", m3::to_string(l.comm_alarm())},
                   {"cmd_alarm", m3::to_string(l.cmd_alarm())},
                   {"servo", drive::to_string(d.state())},
                   {"error_code", d.objects().error_code},
                   {"mode", segment_->servo(i).motion_mode()},  // the last motion command's: VELCTRL 9, INTERPOLATE 8; 0 none
                   {"powered", powered_[static_cast<std::size_t>(i)]},
                   {"commands", st.commands},
                   {"responses", st.responses},
                   {"fcs_errors", st.fcs_errors},
                   {"bad_frames", st.bad_frames},
                   {"missed_syncs", st.missed_syncs},
                   {"missed_commands", st.missed_commands},
                   {"wdt_errors", st.wdt_errors},
                   {"phase_errors", st.phase_errors},
                   {"length_errors", st.length_errors},
                   {"comm_alarms", st.comm_alarms},
                   {"repeated", st.repeated}});
  }
  return out;
}

}  // namespace omnitwin::twin
