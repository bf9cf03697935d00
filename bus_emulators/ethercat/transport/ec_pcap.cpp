// bus_emulators/ethercat/transport — EtherCAT pcap writer (LINKTYPE_ETHERNET); see ec_pcap.hpp.
#include "bus_emulators/ethercat/transport/ec_pcap.hpp"
#include "bus_emulators/pcap_record.hpp"

#include <pcap/pcap.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <stdexcept>

namespace omnitwin::ethercat {

namespace {
constexpr Mac kBroadcast = {0xff, 0xff, 0xff, 0xff, 0xff, 0xff};
constexpr int kSnapLen = 65535;
}  // namespace

const char* to_string(Direction d) {
  switch (d) {
    case Direction::out: return "out";
    case Direction::back: return "back";
  }
  return "?";
}

PcapWriter::PcapWriter(const std::string& path) : PcapWriter(path, Options{}) {}

PcapWriter::PcapWriter(const std::string& path, Options options) : path_(path), options_(options) {
  pcap_t* p = pcap_open_dead_with_tstamp_precision(kLinkType, kSnapLen, PCAP_TSTAMP_PRECISION_NANO);
  if (!p) throw std::runtime_error("pcap: pcap_open_dead failed for " + path);
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) {
    const std::string msg = "pcap: cannot create " + path + ": " + std::strerror(errno);
    pcap_close(p);
    throw std::runtime_error(msg);
  }
  if (options_.buffer_bytes > 0) std::setvbuf(f, nullptr, _IOFBF, options_.buffer_bytes);
  pcap_dumper_t* d = pcap_dump_fopen(p, f);
  if (!d) {
    const std::string msg = "pcap: cannot write " + path + ": " + pcap_geterr(p);
    std::fclose(f);
    pcap_close(p);
    throw std::runtime_error(msg);
  }
  pcap_ = p;
  dumper_ = d;
  pcap_dump_flush(d);  // the file header: an empty capture is a valid file
}

PcapWriter::~PcapWriter() { close(); }

bool PcapWriter::emit(std::size_t size, SimTime t, Direction dir) {
  if (size < kMinEthFrame) {
    std::memset(frame_.data() + size, 0, kMinEthFrame - size);
    size = kMinEthFrame;
  }
  const pcap_pkthdr h = bus_emulators::pcap_record_header(t, static_cast<std::uint32_t>(size));
  auto* d = static_cast<pcap_dumper_t*>(dumper_);
  pcap_dump(reinterpret_cast<u_char*>(d), &h, frame_.data());
  ++written_[static_cast<int>(dir)];
  return !options_.flush_each_frame || pcap_dump_flush(d) == 0;
}

bool PcapWriter::write(std::span<const std::uint8_t> pdu, SimTime t, Direction dir) {
  if (!dumper_) return false;
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
  if (!dumper_) return false;
  if (frame.size() > frame_.size()) {
    ++refused_;
    return false;
  }
  if (!frame.empty()) std::memcpy(frame_.data(), frame.data(), frame.size());
  return emit(frame.size(), t, dir);
}

bool PcapWriter::flush() {
  return dumper_ && pcap_dump_flush(static_cast<pcap_dumper_t*>(dumper_)) == 0;
}

void PcapWriter::close() {
  if (dumper_) {
    pcap_dump_flush(static_cast<pcap_dumper_t*>(dumper_));
    pcap_dump_close(static_cast<pcap_dumper_t*>(dumper_));  // closes the FILE too
    dumper_ = nullptr;
  }
  if (pcap_) {
    pcap_close(static_cast<pcap_t*>(pcap_));
    pcap_ = nullptr;
  }
}

}  // namespace omnitwin::ethercat
