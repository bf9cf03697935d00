// bus_emulators/can — CAN capture files (pcap, LINKTYPE_CAN_SOCKETCAN = 227) that Wireshark
// and tshark decode.
//
// Written through libpcap (pcap_open_dead_with_tstamp_precision + pcap_dump_open) with
// nanosecond timestamps (the twin's clock is integer nanoseconds; the file gets the
// nanosecond pcap magic). Every record is flushed to the kernel as it is written
// (pcap_dump_flush), so a run that ends by SIGINT/SIGTERM/SIGKILL leaves a valid file holding
// every frame written so far; close() (or the destructor) just closes it.
//
// Each record is a Linux `struct can_frame` (16 bytes) as SocketCAN captures it: can_id in
// network byte order with CAN_EFF_FLAG / CAN_RTR_FLAG / CAN_ERR_FLAG, the length byte, three
// reserved bytes and 8 data bytes (zero beyond the payload). Error frames are written with
// length 8 (CAN_ERR_DLC) and the frame's 8 data bytes, as the kernel reports them.
//
// Direction: classic pcap records have no direction field and LINKTYPE_CAN_SOCKETCAN has
// none either, so the direction is not stored; `record_directions` chooses which directions
// the writer records (both by default) and the count per direction is kept.
#pragma once

#include "bus_emulators/can/can_frame.hpp"

#include <cstdint>
#include <string>

namespace omnitwin::can {

enum class Direction : std::uint8_t { rx, tx };

class PcapWriter {
 public:
  struct Options {
    bool record_rx = true;
    bool record_tx = true;
    bool flush_each_packet = true;  // keep true for recordings that must survive a kill
  };

  // Creates/truncates `path`; throws std::runtime_error with libpcap's message on failure.
  explicit PcapWriter(const std::string& path);
  PcapWriter(const std::string& path, Options options);
  ~PcapWriter();
  PcapWriter(const PcapWriter&) = delete;
  PcapWriter& operator=(const PcapWriter&) = delete;

  // Appends one frame stamped `timestamp_ns` (nanoseconds since the epoch of the capture:
  // the simulated clock, or CLOCK_REALTIME in real-time mode). Frames with an invalid
  // identifier or DLC are written with their DLC clamped to 8 (a capture shows what was seen).
  // Returns false once the writer is closed or when writing failed.
  bool write(const Frame& f, std::int64_t timestamp_ns, Direction dir = Direction::rx);
  void flush();
  void close();
  bool is_open() const { return dumper_ != nullptr; }

  std::uint64_t written() const { return written_; }
  std::uint64_t written(Direction d) const { return d == Direction::rx ? written_rx_ : written_tx_; }
  const std::string& path() const { return path_; }

  static constexpr int kLinkType = 227;  // LINKTYPE_CAN_SOCKETCAN / DLT_CAN_SOCKETCAN

 private:
  std::string path_;
  Options options_;
  void* pcap_ = nullptr;    // pcap_t*, kept opaque so users need not include <pcap.h>
  void* dumper_ = nullptr;  // pcap_dumper_t*
  std::uint64_t written_ = 0;
  std::uint64_t written_rx_ = 0;
  std::uint64_t written_tx_ = 0;
};

}  // namespace omnitwin::can
