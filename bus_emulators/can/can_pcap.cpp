// bus_emulators/can — pcap writer for CAN (LINKTYPE_CAN_SOCKETCAN); see can_pcap.hpp.
#include "bus_emulators/can/can_pcap.hpp"
#include "bus_emulators/pcap_record.hpp"

#include <pcap/pcap.h>

#include <algorithm>
#include <stdexcept>

namespace omnitwin::can {

namespace {

constexpr std::uint32_t kEffFlag = 0x80000000u;  // CAN_EFF_FLAG
constexpr std::uint32_t kRtrFlag = 0x40000000u;  // CAN_RTR_FLAG
constexpr std::uint32_t kErrFlag = 0x20000000u;  // CAN_ERR_FLAG
constexpr std::uint32_t kEffMask = 0x1FFFFFFFu;
constexpr std::uint32_t kSffMask = 0x000007FFu;
constexpr int kRecordSize = 16;  // sizeof(struct can_frame)

}  // namespace

PcapWriter::PcapWriter(const std::string& path) : PcapWriter(path, Options{}) {}

PcapWriter::PcapWriter(const std::string& path, Options options) : path_(path), options_(options) {
  pcap_t* p = pcap_open_dead_with_tstamp_precision(kLinkType, 65535, PCAP_TSTAMP_PRECISION_NANO);
  if (!p) throw std::runtime_error("pcap: pcap_open_dead failed");
  pcap_dumper_t* d = pcap_dump_open(p, path.c_str());
  if (!d) {
    const std::string msg = std::string("pcap: cannot create ") + path + ": " + pcap_geterr(p);
    pcap_close(p);
    throw std::runtime_error(msg);
  }
  pcap_ = p;
  dumper_ = d;
  // The file header is in stdio's buffer until the first flush: write it now, so that even
  // an empty capture interrupted at once is a valid file.
  pcap_dump_flush(d);
}

PcapWriter::~PcapWriter() { close(); }

bool PcapWriter::write(const Frame& f, std::int64_t timestamp_ns, Direction dir) {
  if (!dumper_) return false;
  if (dir == Direction::rx ? !options_.record_rx : !options_.record_tx) return true;

  std::uint32_t id = 0;
  std::uint8_t len = std::min<std::uint8_t>(f.dlc, 8);
  switch (f.kind) {
    case FrameKind::data:
      id = f.extended ? (f.id & kEffMask) | kEffFlag : f.id & kSffMask;
      break;
    case FrameKind::remote:
      id = (f.extended ? (f.id & kEffMask) | kEffFlag : f.id & kSffMask) | kRtrFlag;
      break;
    case FrameKind::error:
      id = (f.id & kEffMask) | kErrFlag;
      len = 8;  // CAN_ERR_DLC: the kernel always reports 8 detail bytes
      break;
  }
  std::uint8_t rec[kRecordSize] = {};
  rec[0] = static_cast<std::uint8_t>(id >> 24);  // network byte order for this link type
  rec[1] = static_cast<std::uint8_t>(id >> 16);
  rec[2] = static_cast<std::uint8_t>(id >> 8);
  rec[3] = static_cast<std::uint8_t>(id);
  rec[4] = len;
  const int payload = f.kind == FrameKind::remote ? 0 : len;
  std::copy_n(f.data.begin(), payload, rec + 8);

  const pcap_pkthdr h = bus_emulators::pcap_record_header(timestamp_ns, kRecordSize);
  auto* d = static_cast<pcap_dumper_t*>(dumper_);
  pcap_dump(reinterpret_cast<u_char*>(d), &h, rec);
  if (options_.flush_each_packet && pcap_dump_flush(d) != 0) return false;
  ++written_;
  ++(dir == Direction::rx ? written_rx_ : written_tx_);
  return true;
}

void PcapWriter::flush() {
  if (dumper_) pcap_dump_flush(static_cast<pcap_dumper_t*>(dumper_));
}

void PcapWriter::close() {
  if (dumper_) {
    pcap_dump_flush(static_cast<pcap_dumper_t*>(dumper_));
    pcap_dump_close(static_cast<pcap_dumper_t*>(dumper_));
    dumper_ = nullptr;
  }
  if (pcap_) {
    pcap_close(static_cast<pcap_t*>(pcap_));
    pcap_ = nullptr;
  }
}

}  // namespace omnitwin::can
