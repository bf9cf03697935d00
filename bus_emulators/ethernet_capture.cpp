// bus_emulators — the Ethernet-framed buses' capture file; see ethernet_capture.hpp.
#include "bus_emulators/ethernet_capture.hpp"

#include <cstring>

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
  const pcap_pkthdr h = pcap_record_header(t_ns, static_cast<std::uint32_t>(size));
  if (!file_->dump(h, frame_.data())) return false;
  ++written_[dir];
  return !flush_each_frame_ || file_->flush();
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
bool EthernetCapture::close() { return file_->close(); }
bool EthernetCapture::is_open() const { return file_->is_open(); }
bool EthernetCapture::ok() const { return file_->ok(); }
std::string EthernetCapture::error() const { return file_->error(); }
std::string EthernetCapture::part_path() const { return file_->part_path(); }

}  // namespace omnitwin::bus_emulators
