// bus_emulators/mechatrolink3/transport — the twin's side of an M-III line; see m3_segment.hpp.
#include "bus_emulators/mechatrolink3/transport/m3_segment.hpp"

#include <algorithm>
#include <limits>

namespace omnitwin::m3 {

namespace {

// A frame of `size` bytes (header and FCS included) on the wire, with its gap [ns].
std::int64_t wire_ns(std::size_t size) {
  return size >= kHeaderSize + kFcsSize ? frame_slot_ns(size - kHeaderSize - kFcsSize) : 0;
}

}  // namespace

M3Segment::M3Segment(const SegmentConfig& config, M3Transport& transport) : stations_(config), transport_(transport) {
  stations_.line().attach_master([this](std::span<const std::uint8_t> f, SimTime t) { to_master_frame(f, t); });
}

M3Segment::~M3Segment() = default;

void M3Segment::open_pcap(const std::string& path) {
  pcap_ = std::make_unique<PcapWriter>(path);
  pcap_->hold_in_time_order(kHeld);
}

// Into the capture's hold (written in time order by flush_capture).
void M3Segment::capture(std::span<const std::uint8_t> frame, SimTime t, Direction dir) {
  if (pcap_) pcap_->write_frame(frame, t, dir);
}

void M3Segment::flush_capture() {
  if (pcap_) pcap_->release(std::numeric_limits<SimTime>::max());
}

// A frame whose last bit reached the master at t: onto the transport and into the capture.
void M3Segment::to_master_frame(std::span<const std::uint8_t> frame, SimTime t) {
  busy_ns_ += wire_ns(frame.size());
  if (transport_.send(frame)) ++to_master_;
  else ++send_failures_;
  capture(frame, t, Direction::back);
  last_arrival_ = t;
}

// A frame of n bytes (in rx_) from the master enters the line when it started leaving it.
void M3Segment::enter(int n, SimTime t) {
  ++from_master_;
  busy_ns_ += wire_ns(static_cast<std::size_t>(n));
  const std::span<const std::uint8_t> frame(rx_.data(), static_cast<std::size_t>(n));
  capture(frame, t, Direction::out);
  stations_.line().from_master(frame, t);
}

// Everything in flight is delivered: a slave only answers what it receives.
void M3Segment::run_dry() {
  Line& line = stations_.line();
  for (SimTime due = line.next_due(); due >= 0; due = line.next_due()) line.advance(due);
}

SegmentAnswer M3Segment::take_sent(std::uint64_t master_frames, SimTime t_send, std::chrono::nanoseconds wait) {
  SegmentAnswer a;
  // Frames reported together were sent back to back, the last starting at t_send: each
  // earlier one a frame slot before the next. Taken first, then entered in order.
  std::size_t n = 0;
  while (from_master_ + n < master_frames) {
    if (n == batch_.size()) return a;  // more than a cycle's back-to-back frames: not our master
    const int got = transport_.receive(batch_[n].bytes, wait);
    if (got <= 0) return a;
    batch_[n++].size = static_cast<std::size_t>(got);
  }
  SimTime start = t_send;
  for (std::size_t i = n; i-- > 0;) {
    batch_[i].at = start;
    if (i > 0) start -= wire_ns(batch_[i - 1].size);
  }
  for (std::size_t i = 0; i < n; ++i) {
    std::copy_n(batch_[i].bytes.begin(), batch_[i].size, rx_.begin());
    enter(static_cast<int>(batch_[i].size), batch_[i].at);
  }
  last_arrival_ = -1;
  run_dry();
  a.ok = true;
  a.to_master = to_master_;
  a.arrival_ns = last_arrival_;
  return a;
}

int M3Segment::poll(SimTime t, SimTime not_before) {
  int taken = 0;
  for (int n = transport_.receive(rx_, std::chrono::nanoseconds(0)); n > 0;
       n = transport_.receive(rx_, std::chrono::nanoseconds(0))) {
    // When the frame came (the kernel's stamp), in the order frames came, never ahead of t.
    const std::int64_t age = transport_.last_age_ns();
    const SimTime at = std::clamp<SimTime>(age >= 0 ? t - age : t, std::max(not_before, last_entry_), t);
    stations_.advance(at);  // the slaves' timers up to its arrival, not up to now
    enter(n, at);
    last_entry_ = at;
    run_dry();
    ++taken;
  }
  return taken;
}

void M3Segment::inject(std::span<const std::uint8_t> frame, SimTime t) {
  busy_ns_ += wire_ns(frame.size());
  capture(frame, t, Direction::out);
  if (transport_.send(frame)) ++to_master_;
  else ++send_failures_;
  stations_.line().from_master(frame, t);
  run_dry();
}

void M3Segment::advance(SimTime t) { stations_.advance(t); }

drive::Command M3Segment::step_drive(int k, SimTime t, const drive::Feedback& fb) {
  return stations_.servo(k).step(t, fb);
}

}  // namespace omnitwin::m3
