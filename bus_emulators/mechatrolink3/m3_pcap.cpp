// bus_emulators/mechatrolink3 — M-III pcap writer (LINKTYPE_ETHERNET); see m3_pcap.hpp.
#include "bus_emulators/mechatrolink3/m3_pcap.hpp"

#include "bus_emulators/pcap_record.hpp"

#include <pcap/pcap.h>

#include <cstring>

namespace omnitwin::m3 {

namespace {

// The Ethernet header encapsulate() writes, taken from the frame's address bytes whether or
// not the frame is valid (a corrupted frame is recorded as the receiver saw it).
void write_eth_header(std::uint8_t* out, std::uint8_t dst, std::uint8_t src) {
  const Mac d = station_mac(dst), s = station_mac(src);
  std::memcpy(out, d.data(), d.size());
  std::memcpy(out + 6, s.data(), s.size());
  out[12] = static_cast<std::uint8_t>(kEtherType >> 8);
  out[13] = static_cast<std::uint8_t>(kEtherType & 0xFF);
}

}  // namespace

const char* to_string(Direction d) {
  switch (d) {
    case Direction::out: return "out";
    case Direction::back: return "back";
  }
  return "?";
}

PcapWriter::PcapWriter(const std::string& path) : PcapWriter(path, Options{}) {}

// The file header is flushed at once: an empty capture is a valid .part file.
PcapWriter::PcapWriter(const std::string& path, Options options)
    : path_(path), options_(options),
      file_(std::make_unique<bus_emulators::PcapFile>(path, kLinkType, options.buffer_bytes)) {}

PcapWriter::~PcapWriter() { close(); }

bool PcapWriter::writable() const { return file_->is_open() && file_->ok(); }

bool PcapWriter::emit(std::size_t size, SimTime t_ns, Direction dir) {
  if (size < kMinEthFrame) {
    std::memset(frame_.data() + size, 0, kMinEthFrame - size);
    size = kMinEthFrame;
  }
  const pcap_pkthdr h = bus_emulators::pcap_record_header(t_ns, static_cast<std::uint32_t>(size));
  if (!file_->dump(h, frame_.data())) return false;
  ++written_[static_cast<int>(dir)];
  return !options_.flush_each_frame || file_->flush();
}

bool PcapWriter::write_frame(std::span<const std::uint8_t> m3_frame, SimTime t_ns, Direction dir) {
  if (!writable()) return false;
  if (m3_frame.size() < 2 || m3_frame.size() > kMaxFrame) {
    ++refused_;
    return false;
  }
  write_eth_header(frame_.data(), m3_frame[0], m3_frame[1]);
  std::memcpy(frame_.data() + kEthHeaderSize, m3_frame.data(), m3_frame.size());
  return emit(kEthHeaderSize + m3_frame.size(), t_ns, dir);
}

bool PcapWriter::write_ethernet(std::span<const std::uint8_t> eth_frame, SimTime t_ns, Direction dir) {
  if (!writable()) return false;
  if (eth_frame.size() > frame_.size()) {
    ++refused_;
    return false;
  }
  if (!eth_frame.empty()) std::memcpy(frame_.data(), eth_frame.data(), eth_frame.size());
  return emit(eth_frame.size(), t_ns, dir);
}

bool PcapWriter::flush() { return file_->flush(); }

bool PcapWriter::close() { return file_->close(); }

bool PcapWriter::is_open() const { return file_->is_open(); }
bool PcapWriter::ok() const { return file_->ok(); }
std::string PcapWriter::error() const { return file_->error(); }
std::string PcapWriter::part_path() const { return file_->part_path(); }

}  // namespace omnitwin::m3
