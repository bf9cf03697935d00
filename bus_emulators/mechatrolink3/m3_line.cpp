// bus_emulators/mechatrolink3 — the in-process line; see m3_line.hpp.
#include "bus_emulators/mechatrolink3/m3_line.hpp"

#include <algorithm>
#include <stdexcept>

namespace omnitwin::m3 {

Line::Line(const Topology& topology, std::size_t queue_capacity)
    : topology_(topology),
      slaves_(topology.cable_m.size()),
      reachable_(topology.cable_m.size(), true),
      extra_(topology.cable_m.size(), 0),
      capacity_(queue_capacity != 0 ? queue_capacity : 4 * topology.cable_m.size() + 16) {
  if (const std::string why = check(topology); !why.empty()) throw std::invalid_argument("M-III line: " + why);
  for (int k = 0; k < topology.slaves(); ++k) one_way_.push_back(one_way_delay_ns(topology, k));
  heap_.reserve(capacity_);
}

bool Line::later(const InFlight& a, const InFlight& b) {
  return a.due != b.due ? a.due > b.due : a.order > b.order;  // min-heap on (due, order)
}

void Line::put(int to, std::span<const std::uint8_t> frame, SimTime due, Fate fate) {
  if (fate == Fate::drop || frame.empty() || frame.size() > kMaxFrame) return void(++dropped_);
  if (heap_.size() >= capacity_) return void(++overflow_);
  InFlight f;
  f.due = due;
  f.order = order_++;
  f.to = to;
  f.size = static_cast<std::uint8_t>(frame.size());
  std::copy(frame.begin(), frame.end(), f.bytes.begin());
  if (fate == Fate::corrupt) {
    // One bit of the FCS: the frame keeps its length and addresses, so it reaches the
    // receiver as the same frame with a bad FCS (a bit error the ASIC finds), not as a
    // frame of another length or for another station.
    f.bytes[f.size - 1] ^= 0x10;
    ++corrupted_;
  }
  heap_.push_back(f);
  std::push_heap(heap_.begin(), heap_.end(), later);
}

void Line::from_master(std::span<const std::uint8_t> frame, SimTime t_start) {
  if (frame.size() < kHeaderSize + kFcsSize) return void(++dropped_);
  const SimTime length = frame_time_ns(frame.size() - kHeaderSize - kFcsSize);
  const std::uint8_t dst = frame[0];
  for (int k = 0; k < topology_.slaves(); ++k) {
    if (dst != kBroadcast && dst != kFirstSlave + k) continue;
    if (!reachable_[static_cast<std::size_t>(k)]) {
      ++dropped_;
      continue;
    }
    const Fate fate = fault_ ? fault_(true, k, frame) : Fate::deliver;
    put(k, frame, t_start + one_way_[static_cast<std::size_t>(k)] + length, fate);
  }
}

void Line::from_slave(int k, std::span<const std::uint8_t> frame, SimTime t_start) {
  if (k < 0 || k >= topology_.slaves() || !reachable_[static_cast<std::size_t>(k)]) return void(++dropped_);
  if (frame.size() < kHeaderSize + kFcsSize) return void(++dropped_);
  const SimTime length = frame_time_ns(frame.size() - kHeaderSize - kFcsSize);
  // The fault hook runs first: it may set this frame's extra delay (a per frame jitter).
  const Fate fate = fault_ ? fault_(false, k, frame) : Fate::deliver;
  const auto i = static_cast<std::size_t>(k);
  put(-1, frame, t_start + one_way_[i] + extra_[i] + length, fate);
}

void Line::advance(SimTime t) {
  while (!heap_.empty() && heap_.front().due <= t) {
    std::pop_heap(heap_.begin(), heap_.end(), later);
    const InFlight f = heap_.back();
    heap_.pop_back();
    const std::span<const std::uint8_t> bytes(f.bytes.data(), f.size);
    const Receive& r = f.to < 0 ? master_ : slaves_[static_cast<std::size_t>(f.to)];
    if (r) r(bytes, f.due);
  }
}

void Line::cut_cable(int after) {
  for (int k = after + 1; k < topology_.slaves(); ++k) {
    reachable_[static_cast<std::size_t>(k)] = false;
    if (topology_.kind == TopologyKind::star) break;  // a star cable feeds one slave
  }
}

void Line::mend_cable() { std::fill(reachable_.begin(), reachable_.end(), true); }

SimTime Line::next_due() const { return heap_.empty() ? -1 : heap_.front().due; }

}  // namespace omnitwin::m3
