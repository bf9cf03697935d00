// twin layer — the EtherCAT segment of the twin; see ethercat_network.hpp.
#include "twin/ethercat_network.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numbers>
#include <stdexcept>

#include "bus_emulators/drive/cia402_drive.hpp"
#include "bus_emulators/ethercat/device/ec_slave.hpp"
#include "bus_emulators/ethercat/ec_esc.hpp"
#include "bus_emulators/ethercat/transport/ec_pcap.hpp"
#include "bus_emulators/ethercat/transport/ec_transport.hpp"
#include "bus_emulators/ethercat/transport/ec_transport_udp.hpp"
#include "bus_emulators/ethercat/transport/ec_veth.hpp"
#include "twin/line_transport.hpp"

namespace omnitwin::twin {

namespace {

constexpr double kTwoPi = 2 * std::numbers::pi;
constexpr std::size_t kMaxInFlight = 64;    // frames from the master not yet through the chain
constexpr std::size_t kMaxReplies = 64;     // returned frames not yet on the transport
constexpr double kWireBitsPerByte = 8.0;
constexpr double kLinkBitRate = 100e6;      // 100BASE-TX
constexpr std::size_t kEthOverhead = 14 + 4 + 8 + 12;  // header, FCS, preamble+SFD, inter-frame gap

// Time one frame occupies the line at 100 Mbit/s [ns] (padded to the Ethernet minimum).
std::int64_t wire_ns(std::size_t pdu) {
  const std::size_t payload = std::max<std::size_t>(pdu, 46);
  return std::llround(static_cast<double>(payload + kEthOverhead) * kWireBitsPerByte / kLinkBitRate * 1e9);
}

// The scheduler's drift of a timer on an oscillator fast by d: period·(1 + x) = period/(1 + d).
double timer_drift(double d) { return 1.0 / (1.0 + d) - 1.0; }

DriveStateCode from_al(ethercat::AlState al, drive::State fsa, bool powered) {
  if (!powered) return DriveStateCode::off;
  if (fsa == drive::State::fault || fsa == drive::State::fault_reaction_active) return DriveStateCode::fault;
  if (al == ethercat::AlState::op && fsa == drive::State::operation_enabled) return DriveStateCode::running;
  return DriveStateCode::waiting;
}

}  // namespace

std::string ethercat_esi_path(const EthercatSpec& e) {
  // Absolute: the master process resolves relative names against its configuration file.
  if (!e.esi.empty()) return std::filesystem::absolute(e.esi).lexically_normal().string();
  return std::string(OMNITWIN_SOURCE_DIR) + "/models/ethercat/omnitwin_drive.xml";
}

std::string ethercat_multiaxis_esi_path() {
  return std::string(OMNITWIN_SOURCE_DIR) + "/models/ethercat/omnitwin_multiaxis.xml";
}

// Axis cards per seed 001 multi-axis slave (the ESI's 8 module slots); the last one takes the rest.
constexpr int kCardsPerMultiAxisSlave = 8;

int ethercat_extra_slaves(const EthercatSpec& e) {
  return (e.extra_axes + kCardsPerMultiAxisSlave - 1) / kCardsPerMultiAxisSlave;
}

EthercatNetwork::EthercatNetwork(const Scenario& s, Scheduler& sched, Hooks hooks)
    : s_(s), spec_(s.bus.ethercat), sched_(sched), hooks_(std::move(hooks)), rng_(s.bus.ethercat.seed), jitter_rng_(s.bus.ethercat.seed ^ 0x6a09e667f3bcc908ULL) {
  const std::vector<ethercat::DeviceDescription> devices = ethercat::load_esi(ethercat_esi_path(spec_));
  if (devices.empty()) throw std::runtime_error(fmt::format("{}: no Device in the file", ethercat_esi_path(spec_)));
  device_ = devices.front();
  pending_.resize(kMaxInFlight);
  replies_.resize(kMaxReplies);
  for (int i = 0; i < 4; ++i) {
    const auto k = static_cast<std::size_t>(i);
    drift_[k] = spec_.drift[k];
    ethercat::DriveSlaveConfig c;
    c.axes = 1;
    c.serial = static_cast<std::uint32_t>(i + 1);
    c.esc.oscillator_drift = drift_[k];
    c.esc.power_on_time_ns = 1'000'000'000LL * (i + 1);  // each slave was switched on at its own instant
    c.drive.counts_per_rev = spec_.counts_per_rev;
    c.drive.gear_ratio = 1.0;
    c.drive.period_s = spec_.drive_period;
    c.drive.max_speed_rad_s = s.platform.motor.speed_limit;
    c.drive.rated_torque_nm = s.platform.motor.torque_limit;
    slaves_[k] = std::make_unique<ethercat::DriveSlave>(device_, c);
    chain_.add(&slaves_[k]->esc());
    last_al_[k] = static_cast<std::uint8_t>(ethercat::AlState::init);
  }
  // Each drive's firmware cycle on its own oscillator (a clock fast by d ticks every P/(1+d)),
  // the four starting at different instants.
  const SimTime period = std::llround(spec_.drive_period * 1e9);
  for (int i = 0; i < 4; ++i) {
    const auto k = static_cast<std::size_t>(i);
    timers_[k] = sched_.add_periodic(fmt::format("ecat-slave{}", i + 1), Phase::device, period / (i + 2), period,
                                     [this, i](SimTime t) { on_drive_timer(i, t); }, timer_drift(drift_[k]));
  }
  add_extra_slaves(period);
  open_transport(s);
}

// Seed 001's multi-axis slaves behind the four wheel drives (bus.ethercat.extra_axes): 8 axis
// cards each, the rest on the last, every card held at rest and stepped by its slave's
// firmware cycle (on the SYNC0 pulses once DC runs). One timer cycles them all (mailbox
// replies, and the process data without DC).
void EthercatNetwork::add_extra_slaves(SimTime period) {
  if (spec_.extra_axes <= 0) return;
  const std::vector<ethercat::DeviceDescription> multi = ethercat::load_esi(ethercat_multiaxis_esi_path());
  if (multi.empty()) throw std::runtime_error(fmt::format("{}: no Device in the file", ethercat_multiaxis_esi_path()));
  multi_device_ = multi.front();
  for (int left = spec_.extra_axes, i = 0; left > 0; left -= kCardsPerMultiAxisSlave, ++i) {
    ethercat::DriveSlaveConfig c;
    c.axes = std::min(left, kCardsPerMultiAxisSlave);
    c.serial = static_cast<std::uint32_t>(101 + i);
    c.esc.power_on_time_ns = 1'000'000'000LL * (5 + i);
    c.drive.period_s = spec_.drive_period;
    extra_.push_back(std::make_unique<ethercat::DriveSlave>(multi_device_, c));
    ethercat::DriveSlave* sl = extra_.back().get();
    sl->set_cycle_hook([sl](SimTime at) {
      for (int a = 0; a < sl->axes(); ++a) sl->axis(a).step(at, drive::Feedback{});
    });
    chain_.add(&sl->esc());
  }
  sched_.add_periodic("ecat-extra-slaves", Phase::device, period / 7, period, [this](SimTime t) {
    advance(t);
    for (auto& e : extra_) e->cycle(t);
  });
}

EthercatNetwork::~EthercatNetwork() = default;

void EthercatNetwork::open_transport(const Scenario& s) {
  std::string spec = spec_.transport;
  const bool lockstep = s.clock == ClockMode::lockstep;
  // Lockstep holds the replies: for omni-master until the next grant, for a master on the
  // virtual clock until they are due back (release_due).
  batch_ = lockstep;
  // auto: veth as root, else UDP on loopback (lockstep: a free port; realtime: the documented one).
  LineTransport line = choose_line_transport(spec, spec_.master_iface, lockstep, "udp:127.0.0.1:34980");
  veth_ = line.veth;
  transport_spec_ = line.slaves_spec;
  // The interfaces the scenario names are claimed, the slaves' and the master's end alike (a
  // second twin on the other end of the same link was let run; found in review). A pair made
  // for the run is the run's own.
  if (!veth_) claim_interfaces(claims_, {transport_spec_, line.master_iface});
  master_iface_ = line.master_iface.empty() ? line.slaves_spec : line.master_iface;
  transport_ = ethercat::open_transport(transport_spec_, ethercat::Role::slaves);
  transport_->set_refuse_foreign_senders(spec_.refuse_foreign);
  if (!(lockstep)) transport_->set_master_handover(kMasterHandoverNs);
  // A UDP segment on port 0: the master is told the port the slaves' socket was given.
  if (const auto* udp = dynamic_cast<const ethercat::UdpTransport*>(transport_.get()); udp) {
    ethercat::TransportSpec t = ethercat::parse_transport_spec(transport_spec_);
    t.port = udp->local_port();
    master_iface_ = t.canonical();
  }
}

void EthercatNetwork::open_pcap(const std::string& path) {
  pcap_ = std::make_unique<ethercat::PcapWriter>(path);
  pcap_->hold_in_time_order(kHeld);
}

std::string EthercatNetwork::close_pcap() { return close_capture(pcap_.get()); }
std::string EthercatNetwork::pcap_error() const { return capture_error(pcap_.get()); }

void EthercatNetwork::flush_pcap() {
  if (!pcap_) return;
  pcap_->release(sched_.now());
  pcap_->flush();
}

// ---- frames ----------------------------------------------------------------------------

void EthercatNetwork::take_frame(const std::uint8_t* pdu, std::size_t size, SimTime t) {
  ++from_transport_;
  if (pending_count_ == pending_.size()) {
    ++overflow_;  // the master floods the segment: a real line would drop it too
    return;
  }
  Pending& p = pending_[(pending_head_ + pending_count_) % pending_.size()];
  p.size = static_cast<std::uint16_t>(std::min(size, p.pdu.size()));
  // Frames share the line: one sent right behind another (a master's cyclic image in several
  // frames) enters when the earlier one's last bit and the inter-frame gap have gone out.
  p.at = std::max<SimTime>(t + std::llround(spec_.t_pre_us * 1e3), line_free_);
  line_free_ = p.at + wire_ns(p.size);
  std::copy_n(pdu, p.size, p.pdu.begin());
  p.wire = transport_ && transport_->wire_header(p.hdr);
  ++pending_count_;
}

bool EthercatNetwork::lose_frame() {
  if (loss_left_ > 0) {
    --loss_left_;
    return true;
  }
  if (loss_rate_ <= 0) return false;
  if (std::uniform_real_distribution<double>(0, 1)(rng_) >= loss_rate_) return false;
  loss_left_ = loss_burst_ - 1;
  return true;
}

void EthercatNetwork::process_frame(Pending& p) {
  const std::span<std::uint8_t> pdu(p.pdu.data(), p.size);
  capture(p, pdu, p.at, ethercat::Direction::out);
  busy_ns_ += wire_ns(p.size);
  if (lose_frame()) {
    ++lost_frames_;
    return;
  }
  if (!chain_.process(pdu, p.at)) {
    ++not_returned_;
    return;
  }
  // Back at the master after the line's round trip (plus any delay fault).
  // The jitter is drawn per frame (FaultSpec), from its own generator so the loss draws stay.
  const double jitter =
      delay_jitter_ns_ > 0 ? std::uniform_real_distribution<double>(0, delay_jitter_ns_)(jitter_rng_) : 0.0;
  send_reply(p, chain_.last_return_time() + std::llround(delay_ns_ + jitter));
}

// One record of the capture (held by it until the tick passes its instant): with the
// addresses the frame carried when the transport knows them.
void EthercatNetwork::capture(const Pending& p, std::span<const std::uint8_t> pdu, SimTime t, ethercat::Direction dir) {
  if (!pcap_) return;
  if (!p.wire) {
    pcap_->write(pdu, t, dir);
    return;
  }
  ethercat::Mac dst{}, src{};
  std::copy_n(p.hdr.begin(), 6, dst.begin());
  std::copy_n(p.hdr.begin() + 6, 6, src.begin());
  pcap_->write(pdu, t, dir, dst, src);
}

void EthercatNetwork::send_reply(const Pending& p, SimTime t) {
  const std::uint8_t* pdu = p.pdu.data();
  const std::size_t size = p.size;
  capture(p, std::span<const std::uint8_t>(pdu, size), t, ethercat::Direction::back);
  if (!batch_ && delay_ns_ + delay_jitter_ns_ <= 0) {
    if (transport_->send(std::span<const std::uint8_t>(pdu, size)))
      ++to_transport_;
    else
      ++send_failures_;
    return;
  }
  if (replies_count_ == replies_.size()) {
    ++overflow_;
    return;
  }
  Reply& r = replies_[replies_count_++];
  r.at = t;
  r.delayed = delay_ns_ + delay_jitter_ns_ > 0;
  r.size = static_cast<std::uint16_t>(size);
  std::copy_n(pdu, size, r.pdu.begin());
}

// Hands over the replies due by t (realtime with a delay fault), in order.
void EthercatNetwork::release_replies(SimTime t, bool undelayed_too) {
  std::size_t kept = 0;
  for (std::size_t i = 0; i < replies_count_; ++i) {
    Reply& r = replies_[i];
    if (r.at > t && !(undelayed_too && !r.delayed)) {
      if (kept != i) replies_[kept] = r;
      ++kept;
      continue;
    }
    if (transport_->send(std::span<const std::uint8_t>(r.pdu.data(), r.size)))
      ++to_transport_;
    else
      ++send_failures_;
  }
  replies_count_ = kept;
}

void EthercatNetwork::flush_transport() {
  // Lockstep: every reply no delay held goes before the grant; a delayed reply that is not
  // back yet waits for a later grant (the master sees a lost frame meanwhile), also when the
  // delay fault has ended in between: it was released with everything at the fault's end, a
  // frame early (found in review).
  release_replies(sched_.now(), batch_);
}

SimTime EthercatNetwork::next_master_event() const {
  SimTime next = pending_count_ > 0 ? pending_[pending_head_].at : std::numeric_limits<SimTime>::max();
  for (std::size_t i = 0; i < replies_count_; ++i) next = std::min(next, replies_[i].at);
  return next;
}

void EthercatNetwork::advance(SimTime t) {
  while (pending_count_ > 0 && pending_[pending_head_].at <= t) {
    Pending& p = pending_[pending_head_];
    chain_.advance(p.at);
    process_frame(p);
    pending_head_ = (pending_head_ + 1) % pending_.size();
    --pending_count_;
  }
  chain_.advance(t);
  if (!batch_) release_replies(t);
}

bool EthercatNetwork::drain_transport(std::uint64_t count, SimTime t, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (from_transport_ < count) {
    const auto left = deadline - std::chrono::steady_clock::now();
    if (left <= std::chrono::nanoseconds(0)) return false;
    const int n = transport_->receive(rx_, std::chrono::duration_cast<std::chrono::nanoseconds>(left));
    if (n > 0) take_frame(rx_.data(), static_cast<std::size_t>(n), t);
    if (n < 0) return false;
  }
  return true;
}

int EthercatNetwork::poll_transport(SimTime t) {
  int taken = 0;
  for (;;) {
    const int n = transport_->receive(rx_, std::chrono::nanoseconds(0));
    if (n <= 0) break;
    take_frame(rx_.data(), static_cast<std::size_t>(n), t);
    ++taken;
  }
  return taken;
}

int EthercatNetwork::wake_fd() const { return transport_->fd(); }

// Realtime: frames that arrived while the run slept pass the segment at once and go back.
void EthercatNetwork::on_wake(SimTime t) {
  if (poll_transport(t) > 0) advance(t + std::llround(spec_.t_pre_us * 1e3));
}

// ---- drives ----------------------------------------------------------------------------

void EthercatNetwork::on_drive_timer(int axis0, SimTime t) {
  advance(t);
  drive_cycle(axis0, t);
}

// One cycle of a slave on its own oscillator: the firmware posts mailbox replies and, unless
// SYNC0 drives the process data, exchanges it; then the drive runs its loops against its
// wheel. With DC the process data moves on the (synchronised) SYNC0 pulses while the drive's
// loops keep their own rate, as in a real servo drive. Real-time safe.
void EthercatNetwork::drive_cycle(int axis0, SimTime t) {
  const auto k = static_cast<std::size_t>(axis0);
  if (!powered_[k]) return;
  slaves_[k]->cycle(t);
  drive_step(axis0, t);
  watch_states(t);
}

// The drive against its wheel: feedback from the shaft, the amplifier's setpoint back.
// Real-time safe.
void EthercatNetwork::drive_step(int axis0, SimTime t) {
  const auto k = static_cast<std::size_t>(axis0);
  if (!powered_[k]) return;
  drive::Cia402Drive& d = slaves_[k]->axis(0);
  drive::Feedback fb;
  fb.position_rad = hooks_.wheel_angle(axis0);
  fb.velocity_rad_s = hooks_.wheel_speed(axis0);
  const drive::Command c = d.step(t, fb);
  const double setpoint = (c.power && !c.brake_engaged) ? c.velocity_rad_s : 0.0;
  hooks_.set_setpoint(axis0, setpoint);
}

// Events for AL and drive state changes, and the instant all four drives first ran in OP.
void EthercatNetwork::watch_states(SimTime t) {
  bool all_running = true;
  for (std::size_t k = 0; k < 4; ++k) {
    const ethercat::DriveSlave& sl = *slaves_[k];
    const auto al = static_cast<std::uint8_t>(sl.esc().al_state());
    const auto fsa = static_cast<std::uint8_t>(sl.axis(0).state());
    if (al != last_al_[k] || fsa != last_fsa_[k]) {
      std::string text = fmt::format("slave {} AL {}", k + 1, ethercat::to_string(sl.esc().al_state()));
      if (sl.esc().al_error()) text += fmt::format(" (error 0x{:04X} {})", static_cast<unsigned>(sl.esc().al_status_code()),
                                                 ethercat::to_string(sl.esc().al_status_code()));
      text += fmt::format(", drive {}", drive::to_string(sl.axis(0).state()));
      if (hooks_.log) hooks_.log(t, "bus", text);
      last_al_[k] = al;
      last_fsa_[k] = fsa;
    }
    all_running = all_running && drive_state(static_cast<int>(k)) == DriveStateCode::running;
  }
  if (all_running && op_since_ns_ < 0) op_since_ns_ = t;
}

// ---- faults ----------------------------------------------------------------------------

void EthercatNetwork::apply_fault(const FaultSpec& f, bool begin, SimTime t) {
  advance(t);
  const auto k = static_cast<std::size_t>(std::clamp(f.wheel, 0, 3));
  std::string what;
  switch (f.kind) {
    case FaultSpec::Kind::frame_loss:
      loss_rate_ = begin ? f.rate : 0.0;
      loss_burst_ = f.burst;
      loss_left_ = 0;
      what = fmt::format("frame_loss rate {} burst {}", f.rate, f.burst);
      break;
    case FaultSpec::Kind::delay:
      // The jitter is drawn per frame (process_frame). The one draw at the start stays so the
      // frame-loss draws after it, and so the runs of existing scenarios, are unchanged.
      if (begin) (void)std::uniform_real_distribution<double>(0, f.jitter_ms * 1e6)(rng_);
      delay_ns_ = begin ? f.extra_ms * 1e6 : 0.0;
      delay_jitter_ns_ = begin ? f.jitter_ms * 1e6 : 0.0;
      what = fmt::format("delay of returned frames {} ms", f.extra_ms);
      break;
    case FaultSpec::Kind::drift: {
      drift_[k] = begin ? f.drift : spec_.drift[k];
      slaves_[k]->esc().set_oscillator_drift(drift_[k], t);
      sched_.set_drift(timers_[k], timer_drift(drift_[k]));
      what = fmt::format("drift slave {} {}, its period x{:.6f}", k + 1, drift_[k], 1.0 + timer_drift(drift_[k]));
      break;
    }
    case FaultSpec::Kind::power_loss:
      powered_[k] = !begin;
      chain_.set_powered(static_cast<int>(k), !begin, t);
      // Off: the motor coasts (setpoint 0); on again: ESC (the chain restarts it) and the
      // whole device firmware in their power-on state: object dictionary, CoE, the SyncManagers
      // it keeps closed until PRE-OP, the drive (only the drive was reset, so the mailbox was
      // open in INIT after a power loss; found in review).
      hooks_.set_setpoint(static_cast<int>(k), 0.0);
      if (!begin) slaves_[k]->power_cycle(t);
      what = fmt::format("power_loss slave {}", k + 1);
      break;
    case FaultSpec::Kind::link_break:
      chain_.set_link_break(begin ? f.wheel : -1);
      what = f.wheel == 0 ? std::string("link_break between master and slave 1")
                          : fmt::format("link_break after slave {}", f.wheel);
      break;
    case FaultSpec::Kind::wheel_slip:
    case FaultSpec::Kind::bus_off:
    case FaultSpec::Kind::corruption:
    case FaultSpec::Kind::second_master:  // M-III only; the loader refuses it on `ethercat`
      return;  // not a fault of this bus (the scenario loader refuses bus_off here)
  }
  if (hooks_.log) hooks_.log(t, "fault", fmt::format("{} ({})", what, begin ? "begins" : "ends"));
}

// ---- observation -----------------------------------------------------------------------

// Frames that were not EtherCAT or did not parse: dropped by the transport or the line.
std::uint64_t EthercatNetwork::malformed() const {
  return transport_->stats().dropped_malformed + chain_.stats().malformed;
}

BusSample EthercatNetwork::bus_sample() const {
  BusSample b;
  b.has_frames = true;
  b.frames_tx = to_transport_;
  b.frames_rx = from_transport_;
  b.dropouts = lost_frames_ + not_returned_;
  b.errors = malformed() + send_failures_ + overflow_;
  b.wkc = chain_.last_process_wkc();
  return b;
}

DriveStateCode EthercatNetwork::drive_state(int axis0) const {
  const auto k = static_cast<std::size_t>(axis0);
  return from_al(slaves_[k]->esc().al_state(), slaves_[k]->axis(0).state(), powered_[k]);
}

BusNetwork::DriveDetail EthercatNetwork::drive_detail(int axis0) const {
  const auto k = static_cast<std::size_t>(axis0);
  if (!powered_[k]) return {"off", ""};
  return {ethercat::to_string(slaves_[k]->esc().al_state()), drive::to_string(slaves_[k]->axis(0).state())};
}

WheelRecord EthercatNetwork::wheel_record(int axis0) const {
  const ethercat::DriveSlave& sl = *slaves_[static_cast<std::size_t>(axis0)];
  const drive::Objects& o = sl.axis(0).objects();
  const double per_rad = spec_.counts_per_rev / kTwoPi;
  WheelRecord r;
  r.command_rad_s = static_cast<double>(o.target_velocity) / per_rad;
  r.count = static_cast<double>(o.position_actual);
  r.command_counts = static_cast<double>(o.velocity_demand);
  r.measured_counts = static_cast<double>(o.velocity_actual);
  r.output = static_cast<double>(o.torque_demand);
  r.node = sl.esc().station_address();
  return r;
}

nlohmann::json EthercatNetwork::bus_metrics(SimTime now) const {
  const BusSample b = bus_sample();
  const double sim_s = static_cast<double>(now) * 1e-9;
  return {{"name", "ethercat"},
          {"transport", transport_spec_},
          {"master_iface", master_iface_},
          {"device", fmt::format("{} (vendor 0x{:08X}, product 0x{:08X})", device_.name, device_.vendor_id,
                                 device_.product_code)},
          {"frames_tx", b.frames_tx},
          {"frames_rx", b.frames_rx},
          {"dropouts", b.dropouts},
          {"dropout_rate", b.frames_rx > 0 ? static_cast<double>(b.dropouts) / static_cast<double>(b.frames_rx) : 0.0},
          {"errors", b.errors},
          {"lost_frames", lost_frames_},
          {"foreign_frames", transport_->stats().foreign_sender},  // from a second sender
          {"refused_frames", transport_->stats().refused_sender},
          {"master_changes", transport_->stats().master_changes},  // senders taken for the master from a silent one
          // EtherCAT frames of another header type than 1 (network variables, mailbox gateway)
          {"other_pdu_types", transport_->stats().dropped_foreign},
          {"not_returned", not_returned_},
          {"malformed", malformed()},
          {"send_failures", send_failures_},
          {"overflow", overflow_},
          {"in_flight", pending_count_},  // taken from the transport, not yet on the segment at the end
          {"replies_held", replies_count_},  // returned (and captured), not yet handed to the transport
          {"load", sim_s > 0 ? static_cast<double>(busy_ns_) * 1e-9 / sim_s : 0.0},
          {"op_since_s", op_since_ns_ < 0 ? -1.0 : static_cast<double>(op_since_ns_) * 1e-9}};
}

nlohmann::json EthercatNetwork::slave_metrics() const {
  nlohmann::json out = nlohmann::json::array();
  for (std::size_t k = 0; k < 4; ++k) {
    const ethercat::DriveSlave& sl = *slaves_[k];
    const ethercat::Esc& esc = sl.esc();
    const drive::Cia402Drive& d = sl.axis(0);
    out.push_back({{"position", k},
                   {"station_address", esc.station_address()},
                   {"al_state", ethercat::to_string(esc.al_state())},
                   {"al_status_code", static_cast<unsigned>(esc.al_status_code())},
                   {"drive_state", drive::to_string(d.state())},
                   {"error_code", d.objects().error_code},
                   {"mode", d.objects().mode_display},              // 0x6061: the mode the drive ran in
                   {"dc_sync0", esc.dc().sync0_active() ? 1 : 0},  // SYNC0 pulses running (DC mode)
                   {"drift", drift_[k]},
                   {"powered", powered_[k]}});
  }
  return out;
}

}  // namespace omnitwin::twin
