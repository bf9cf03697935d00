// bus_emulators/can — pcap writer for CAN (LINKTYPE_CAN_SOCKETCAN); see can_pcap.hpp.
#include "bus_emulators/can/can_pcap.hpp"
#include "bus_emulators/pcap_record.hpp"

#include <pcap/pcap.h>

#include <algorithm>

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

// The file header is flushed at once, so that even an empty capture interrupted at once is
// a valid .part file.
PcapWriter::PcapWriter(const std::string& path, Options options)
    : path_(path), options_(options), file_(std::make_unique<bus_emulators::PcapFile>(path, kLinkType, 0)) {}

PcapWriter::~PcapWriter() { close(); }

bool PcapWriter::write(const Frame& f, std::int64_t timestamp_ns, Direction dir) {
  if (!file_->is_open() || !file_->ok()) return false;
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
  if (!file_->dump(h, rec)) return false;
  if (options_.flush_each_packet && !file_->flush()) return false;
  ++written_;
  ++(dir == Direction::rx ? written_rx_ : written_tx_);
  return true;
}

bool PcapWriter::flush() { return file_->flush(); }

bool PcapWriter::close() { return file_->close(); }

bool PcapWriter::is_open() const { return file_->is_open(); }
bool PcapWriter::ok() const { return file_->ok(); }
std::string PcapWriter::error() const { return file_->error(); }
std::string PcapWriter::part_path() const { return file_->part_path(); }

}  // namespace omnitwin::can
