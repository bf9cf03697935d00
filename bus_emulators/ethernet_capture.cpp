// bus_emulators — the Ethernet-framed buses' capture file; see ethernet_capture.hpp.
#include "bus_emulators/ethernet_capture.hpp"

#include <algorithm>
#include <cstring>
#include <limits>

#include "bus_emulators/pcap_record.hpp"

namespace omnitwin::bus_emulators {

namespace {
constexpr std::size_t kMinEthFrame = 60;  // without the FCS
}  // namespace

EthernetCapture::EthernetCapture(const std::string& path, std::size_t buffer_bytes, bool flush_each_frame)
    : path_(path), flush_each_frame_(flush_each_frame),
      file_(std::make_unique<PcapFile>(path, kLinkType, buffer_bytes)) {}

EthernetCapture::~EthernetCapture() { close(); }

bool EthernetCapture::writable() const { return file_->is_open() && file_->ok(); }

bool EthernetCapture::record(std::size_t size, std::int64_t t_ns, int dir) {
  if (size < kMinEthFrame) {
    std::memset(frame_.data() + size, 0, kMinEthFrame - size);
    size = kMinEthFrame;
  }
  if (held_.empty()) return dump(frame_.data(), size, t_ns, dir);
  if (held_count_ == held_.size()) release(std::numeric_limits<std::int64_t>::max());
  Held& h = held_[held_count_++];
  h.t_ns = t_ns;
  h.dir = dir;
  h.size = size;
  std::memcpy(h.bytes.data(), frame_.data(), size);
  return true;
}

bool EthernetCapture::dump(const std::uint8_t* data, std::size_t size, std::int64_t t_ns, int dir) {
  const pcap_pkthdr h = pcap_record_header(t_ns, static_cast<std::uint32_t>(size));
  if (!file_->dump(h, data)) return false;
  ++written_[dir];
  return !flush_each_frame_ || file_->flush();
}

void EthernetCapture::hold_in_time_order(std::size_t capacity) {
  held_.resize(capacity);
  spare_.resize(capacity);
  order_.reserve(capacity);
}

void EthernetCapture::release(std::int64_t upto_ns) {
  if (held_count_ == 0) return;
  order_.clear();
  for (std::size_t i = 0; i < held_count_; ++i) order_.push_back(i);
  std::stable_sort(order_.begin(), order_.end(), [this](std::size_t a, std::size_t b) { return held_[a].t_ns < held_[b].t_ns; });
  std::size_t done = 0;
  for (; done < order_.size() && held_[order_[done]].t_ns <= upto_ns; ++done) {
    const Held& h = held_[order_[done]];
    if (writable()) dump(h.bytes.data(), h.size, h.t_ns, h.dir);
  }
  // The later ones stay held, in time order, through the spare slots.
  std::size_t kept = 0;
  for (std::size_t k = done; k < order_.size(); ++k) spare_[kept++] = held_[order_[k]];
  std::swap(held_, spare_);
  held_count_ = kept;
}

bool EthernetCapture::write_ethernet(std::span<const std::uint8_t> eth_frame, std::int64_t t_ns, int dir) {
  if (!writable()) return false;
  if (eth_frame.size() > frame_.size()) {
    ++refused_;
    return false;
  }
  if (!eth_frame.empty()) std::memcpy(frame_.data(), eth_frame.data(), eth_frame.size());
  return record(eth_frame.size(), t_ns, dir);
}

bool EthernetCapture::flush() { return file_->flush(); }
bool EthernetCapture::close() {
  release(std::numeric_limits<std::int64_t>::max());
  return file_->close();
}
bool EthernetCapture::is_open() const { return file_->is_open(); }
bool EthernetCapture::ok() const { return file_->ok(); }
std::string EthernetCapture::error() const { return file_->error(); }
std::string EthernetCapture::part_path() const { return file_->part_path(); }

}  // namespace omnitwin::bus_emulators
