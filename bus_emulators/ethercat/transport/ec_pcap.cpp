// bus_emulators/ethercat/transport — EtherCAT pcap writer (LINKTYPE_ETHERNET); see ec_pcap.hpp.
#include "bus_emulators/ethercat/transport/ec_pcap.hpp"
#include "bus_emulators/pcap_record.hpp"

#include <pcap/pcap.h>

#include <cstring>

namespace omnitwin::ethercat {

namespace {
constexpr Mac kBroadcast = {0xff, 0xff, 0xff, 0xff, 0xff, 0xff};
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

bool PcapWriter::emit(std::size_t size, SimTime t, Direction dir) {
  if (size < kMinEthFrame) {
    std::memset(frame_.data() + size, 0, kMinEthFrame - size);
    size = kMinEthFrame;
  }
  const pcap_pkthdr h = bus_emulators::pcap_record_header(t, static_cast<std::uint32_t>(size));
  if (!file_->dump(h, frame_.data())) return false;
  ++written_[static_cast<int>(dir)];
  return !options_.flush_each_frame || file_->flush();
}

bool PcapWriter::write(std::span<const std::uint8_t> pdu, SimTime t, Direction dir) {
  if (!file_->is_open() || !file_->ok()) return false;
  if (pdu.size() > kMaxPdu) {
    ++refused_;
    return false;
  }
  Mac src = options_.master_mac;
  if (dir == Direction::back) src[0] |= 0x02;
  write_eth_header(frame_.data(), kBroadcast, src);
  if (!pdu.empty()) std::memcpy(frame_.data() + kEthHeaderSize, pdu.data(), pdu.size());
  return emit(kEthHeaderSize + pdu.size(), t, dir);
}

bool PcapWriter::write_frame(std::span<const std::uint8_t> frame, SimTime t, Direction dir) {
  if (!file_->is_open() || !file_->ok()) return false;
  if (frame.size() > frame_.size()) {
    ++refused_;
    return false;
  }
  if (!frame.empty()) std::memcpy(frame_.data(), frame.data(), frame.size());
  return emit(frame.size(), t, dir);
}

bool PcapWriter::flush() { return file_->flush(); }

bool PcapWriter::close() { return file_->close(); }

bool PcapWriter::is_open() const { return file_->is_open(); }
bool PcapWriter::ok() const { return file_->ok(); }
std::string PcapWriter::error() const { return file_->error(); }
std::string PcapWriter::part_path() const { return file_->part_path(); }

}  // namespace omnitwin::ethercat
