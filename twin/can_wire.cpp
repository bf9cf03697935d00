// twin layer — the simulated CAN wire and its transport side; see can_wire.hpp.
#include "twin/can_wire.hpp"

#include <arpa/inet.h>
#include <sched.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <span>

#include <fmt/format.h>

#include "twin/bus_network.hpp"

namespace omnitwin::twin {

namespace {

// Lockstep: frames held for one flush_transport(); more are sent at once (one master tick at
// 1 ms carries about 8; a full 1 Mbit/s bus at 10 ms about 200).
constexpr std::size_t kPendingCapacity = 256;
// Frames of one tick handed to the transport before the master gets a turn: well inside a
// default receive buffer (212992 bytes hold about 275 of these datagrams). Between two bursts
// the twin yields its CPU, which in lockstep it shares with the master (omnitwin run pins both).
constexpr std::size_t kBurst = 128;

can::BusConfig bus_config(const Scenario& s, int nodes) {
  can::BusConfig c;
  c.bit_rate_bps = s.bus.can.bit_rate;
  c.queue_capacity = 64;  // the transport side may hand over a burst (a PC script)
  c.max_nodes = nodes;
  return c;
}

// A group address as the kernel holds it ("[ff15::7]" for "FF15:0::7"): one bus, one key.
std::string canonical_address(const std::string& name, bool ipv6) {
  unsigned char raw[sizeof(in6_addr)];
  char text[INET6_ADDRSTRLEN];
  const int af = ipv6 ? AF_INET6 : AF_INET;
  if (::inet_pton(af, name.c_str(), raw) != 1 || !::inet_ntop(af, raw, text, sizeof text)) return name;
  return ipv6 ? fmt::format("[{}]", text) : std::string(text);
}

}  // namespace

CanWire::CanWire(const Scenario& s, int nodes, bool batch)
    : s_(s), bus_(bus_config(s, nodes)), rng_(s.bus.can.seed), batch_(batch) {
  for (int i = 0; i < nodes; ++i) bus_.attach();
  // One twin per bus on this host (bus_claim.hpp): a named group and port, or a SocketCAN
  // interface, that another twin serves is refused before this one joins it.
  const can::TransportSpec t = can::parse_transport_spec(s.bus.can.transport);
  if (t.kind == can::TransportSpec::Kind::udp && t.port != 0)
    claim_ = std::make_unique<BusClaim>(fmt::format("udp:{}:{}", canonical_address(t.name, t.ipv6), t.port));
  else if (t.kind == can::TransportSpec::Kind::socketcan)
    claim_ = std::make_unique<BusClaim>("socketcan:" + t.name);
  transport_ = can::open_transport(s.bus.can.transport);
  // Lockstep keeps the first sender; on the wall clock a master started again takes over.
  gate_.set_handover(s.clock != ClockMode::lockstep ? kMasterHandoverNs : -1);
  gate_.set_refuse(s.bus.can.refuse_foreign);
  pending_.reserve(kPendingCapacity);
}

CanWire::~CanWire() { flush_transport(); }

void CanWire::open_pcap(const std::string& path) {
  can::PcapWriter::Options o;
  o.flush_each_packet = false;  // flushed once per master tick (flush_pcap)
  pcap_ = std::make_unique<can::PcapWriter>(path, o);
}

std::string CanWire::close_pcap() { return close_capture(pcap_.get()); }
std::string CanWire::pcap_error() const { return capture_error(pcap_.get()); }

// ---- the transport side ---------------------------------------------------------------------

void CanWire::submit_from_far(const can::Frame& f, SimTime t) {
  const SimTime stamp = t + std::llround(s_.bus.can.t_pre_us * 1e3) + extra_delay(FaultSpec::kMaster);
  // A burst beyond the transport side's queue is refused by the wire model: counted.
  if (bus_.submit(kFar, f, stamp) != can::SubmitStatus::queued) ++refused_from_far_;
}

void CanWire::take_from_far(const can::TimedFrame& r, SimTime t) {
  // Who the master is: the first sender, a new one after the master's silence (a master
  // started again), a stalled one back (bus_emulators/sender_gate.hpp).
  if (r.sender != 0) {
    std::array<std::uint8_t, sizeof r.sender> address{};
    std::memcpy(address.data(), &r.sender, sizeof r.sender);
    if (!gate_.admit(address, t, foreign_frames_, refused_foreign_)) return;
  }
  submit_from_far(r.frame, t);
}

void CanWire::flush_transport() {
  if (pending_.empty()) return;
  std::size_t sent = 0;
  for (std::size_t at = 0; at < pending_.size();) {
    if (unyielded_ >= kBurst) {
      ::sched_yield();  // the master reads what came so far (it polls its bus awaiting the grant)
      unyielded_ = 0;
    }
    const std::size_t n = std::min(kBurst - unyielded_, pending_.size() - at);
    sent += transport_->send_many(std::span<const can::TimedFrame>(pending_).subspan(at, n));
    unyielded_ += n;
    at += n;
  }
  to_transport_ += sent;
  send_failures_ += pending_.size() - sent;
  pending_.clear();
}

bool CanWire::drain_transport(std::uint64_t count, SimTime t, std::chrono::milliseconds timeout) {
  flush_transport();  // (the run has flushed before its grant; nothing is left here then)
  unyielded_ = 0;     // the master answered: it has read every frame of the tick
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (from_transport_ < count) {
    if (auto r = transport_->receive()) {
      ++from_transport_;
      take_from_far(*r, t);
      continue;
    }
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0 || !can::wait_readable(*transport_, left)) return from_transport_ >= count;
  }
  return true;
}

int CanWire::poll_transport(SimTime t) {
  int n = 0;
  while (auto r = transport_->receive()) {
    ++from_transport_;
    ++n;
    take_from_far(*r, t);
  }
  return n;
}

bool CanWire::completed(can::BusNode sender, const can::Frame& f, const can::FrameTiming& timing,
                        bool* reached_master) {
  if (pcap_) pcap_->write(f, timing.end_ns, sender == kFar ? can::Direction::rx : can::Direction::tx);
  if (f.extended) ++extended_frames_;
  if (reached_master) *reached_master = false;
  if (sender == kFar) return true;
  // A node's frame reaches the master (and anyone else on the transport) when it completes.
  if (!arrives(FaultSpec::kMaster)) return false;
  if (reached_master) *reached_master = true;
  if (batch_) {
    pending_.push_back(can::TimedFrame{f, timing.end_ns});
    if (pending_.size() >= kPendingCapacity) flush_transport();
  } else if (transport_->send(f, timing.end_ns)) {
    ++to_transport_;
  } else {
    ++send_failures_;
  }
  return false;
}

// ---- faults ---------------------------------------------------------------------------------

bool CanWire::arrives(int target) {
  if (!lose(target)) return true;
  ++lost_frames_;
  return false;
}

bool CanWire::lose(int target) {
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

std::int64_t CanWire::extra_delay(int node) {
  const DelayState& d = delay_[static_cast<std::size_t>(node)];
  if (!d.active) return 0;
  const double jitter = d.jitter_ns > 0 ? std::uniform_real_distribution<double>(0.0, d.jitter_ns)(rng_) : 0.0;
  return std::llround(d.extra_ns + jitter);
}

std::string CanWire::apply_loss(const FaultSpec& f, bool begin, const std::string& who) {
  loss_[static_cast<std::size_t>(f.wheel)] = LossState{f.rate, f.burst, 0, begin};
  return fmt::format("frame_loss to {} rate {} burst {} ({})", who, f.rate, f.burst, begin ? "begins" : "ends");
}

std::string CanWire::apply_delay(const FaultSpec& f, bool begin, const std::string& who) {
  delay_[static_cast<std::size_t>(f.wheel)] = DelayState{f.extra_ms * 1e6, f.jitter_ms * 1e6, begin};
  return fmt::format("delay of {} +{} ms jitter {} ms ({})", who, f.extra_ms, f.jitter_ms, begin ? "begins" : "ends");
}

// ---- metrics --------------------------------------------------------------------------------

std::uint64_t CanWire::malformed_rx() const {
  const can::TransportStats ts = transport_->stats();
  return ts.malformed_rx + ts.wrong_dlc_rx + ts.bad_id_rx + ts.unsupported_rx;
}

std::uint64_t CanWire::errors() const {
  return bus_.stats().error_frames + malformed_rx() + send_failures_ + refused_from_far_;
}

nlohmann::json CanWire::metrics(const char* name, SimTime now) const {
  return {{"name", name},
          {"bit_rate", s_.bus.can.bit_rate},
          {"transport", transport_->spec()},
          {"frames_tx", frames_tx()},
          {"frames_rx", from_transport_},
          {"frames", bus_.stats().frames},
          {"extended_frames", extended_frames_},  // of those, with a 29-bit identifier
          {"error_frames", bus_.stats().error_frames},
          {"lost_frames", lost_frames_},
          {"bus_off_events", bus_off_events_},
          {"load", bus_.bus_load(now)},
          {"refused_from_transport", refused_from_far_},
          {"foreign_frames", foreign_frames_},   // from a transport sender other than the master
          {"refused_frames", refused_foreign_},  // … of which kept off the wire (bus.refuse_foreign)
          {"master_changes", gate_.changes()},   // senders taken for the master from a silent one
          {"transport_rx_malformed", malformed_rx()},
          {"transport_send_failures", send_failures_},  // already counts the OS refusals (send_errors)
          {"pcap_frames", pcap_ ? pcap_->written() : 0}};
}

}  // namespace omnitwin::twin
