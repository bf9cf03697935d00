// bus_emulators/mechatrolink3/transport — the twin's side of an M-III line; see m3_segment.hpp.
#include "bus_emulators/mechatrolink3/transport/m3_segment.hpp"

namespace omnitwin::m3 {

M3Segment::M3Segment(const SegmentConfig& config, M3Transport& transport)
    : line_(config.topology), transport_(transport) {
  for (int k = 0; k < config.topology.slaves(); ++k) {
    servos_.push_back(std::make_unique<ServoProfile>(config.servo));
    const LinkConfig lc{.address = static_cast<std::uint8_t>(kFirstSlave + k), .response_ns = config.response_ns};
    links_.push_back(std::make_unique<SlaveLink>(
        lc, *servos_.back(), [this, k](std::span<const std::uint8_t> f, SimTime t) { line_.from_slave(k, f, t); }));
    line_.attach_slave(k, [this, k](std::span<const std::uint8_t> f, SimTime t) {
      links_[static_cast<std::size_t>(k)]->on_frame(f, t);
    });
    links_.back()->power_on(0);
  }
  line_.attach_master([this](std::span<const std::uint8_t> f, SimTime t) { to_master_frame(f, t); });
}

M3Segment::~M3Segment() = default;

void M3Segment::open_pcap(const std::string& path) { pcap_ = std::make_unique<PcapWriter>(path); }

// A frame whose last bit reached the master at t: onto the transport and into the capture.
void M3Segment::to_master_frame(std::span<const std::uint8_t> frame, SimTime t) {
  if (transport_.send(frame)) ++to_master_;
  else ++send_failures_;
  if (pcap_) pcap_->write_frame(frame, t, Direction::back);
  last_arrival_ = t;
}

SegmentAnswer M3Segment::take_sent(std::uint64_t master_frames, SimTime t_send, std::chrono::nanoseconds wait) {
  SegmentAnswer a;
  // The master's new frames enter the line when they started leaving it.
  while (from_master_ < master_frames) {
    const int n = transport_.receive(rx_, wait);
    if (n <= 0) return a;
    ++from_master_;
    const std::span<const std::uint8_t> frame(rx_.data(), static_cast<std::size_t>(n));
    if (pcap_) pcap_->write_frame(frame, t_send, Direction::out);
    line_.from_master(frame, t_send);
  }
  // The line runs dry: every answer reaches the master now.
  last_arrival_ = -1;
  for (SimTime due = line_.next_due(); due >= 0; due = line_.next_due()) line_.advance(due);
  a.ok = true;
  a.to_master = to_master_;
  a.arrival_ns = last_arrival_;
  return a;
}

void M3Segment::advance(SimTime t) {
  for (auto& l : links_) l->advance(t);
}

drive::Command M3Segment::step_drive(int k, SimTime t, const drive::Feedback& fb) {
  return servos_[static_cast<std::size_t>(k)]->step(t, fb);
}

}  // namespace omnitwin::m3
