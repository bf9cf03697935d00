// bus_emulators/can — CAN capture files (pcap, LINKTYPE_CAN_SOCKETCAN = 227) that Wireshark
// and tshark decode.
//
// Written through libpcap (pcap_open_dead_with_tstamp_precision + pcap_dump_open) with
// nanosecond timestamps (the twin's clock is integer nanoseconds; the file gets the
// nanosecond pcap magic). The capture is written as DIR/.NAME.part and renamed to DIR/NAME
// by close() (or the destructor) only when every write succeeded (bus_emulators/pcap_record:
// PcapFile); a stale DIR/NAME is removed at open. Every record is a record boundary as it is
// written (flush_each_packet): the file is write-behind (bus_emulators/write_behind), so the
// record reaches the file within the writer thread's 20 ms period, and a run killed by
// SIGKILL leaves a valid .part file holding every frame written up to that period before the
// kill, and never a file under the final name. A write error (a full
// disk) is a status, not an exception: write() returns false from then on, ok()/error() say
// why, and close() removes the .part file, so that DIR/NAME stays absent.
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
#include <memory>
#include <string>

namespace omnitwin::bus_emulators {
class PcapFile;
}

namespace omnitwin::can {

enum class Direction : std::uint8_t { rx, tx };

class PcapWriter {
 public:
  struct Options {
    bool record_rx = true;
    bool record_tx = true;
    bool flush_each_packet = true;  // keep true for recordings that must survive a kill
  };

  // Creates `path`'s .part file (removing a stale `path`); throws std::runtime_error naming
  // `path` on failure.
  explicit PcapWriter(const std::string& path);
  PcapWriter(const std::string& path, Options options);
  ~PcapWriter();
  PcapWriter(const PcapWriter&) = delete;
  PcapWriter& operator=(const PcapWriter&) = delete;

  // Appends one frame stamped `timestamp_ns` (nanoseconds since the epoch of the capture:
  // the simulated clock, or CLOCK_REALTIME in real-time mode). Frames with an invalid
  // identifier or DLC are written with their DLC clamped to 8 (a capture shows what was seen).
  // Returns false once the writer is closed or when writing failed (then and from then on).
  bool write(const Frame& f, std::int64_t timestamp_ns, Direction dir = Direction::rx);
  // Hands buffered records to the kernel; false on a write error (kept in error()).
  bool flush();
  // Flushes and closes; renames the .part file to path() when every write succeeded, else
  // removes it. Idempotent. True when path() now holds the complete capture.
  bool close();
  bool is_open() const;
  // false once a write, flush, sync or the final rename failed; error() then names the file
  // and the system's reason ("" while ok). Both stay readable after close().
  bool ok() const;
  std::string error() const;
  std::string part_path() const;  // where the capture is until close()

  std::uint64_t written() const { return written_; }
  std::uint64_t written(Direction d) const { return d == Direction::rx ? written_rx_ : written_tx_; }
  const std::string& path() const { return path_; }

  static constexpr int kLinkType = 227;  // LINKTYPE_CAN_SOCKETCAN / DLT_CAN_SOCKETCAN

 private:
  std::string path_;
  Options options_;
  std::unique_ptr<bus_emulators::PcapFile> file_;  // opaque, so users need not include <pcap.h>
  std::uint64_t written_ = 0;
  std::uint64_t written_rx_ = 0;
  std::uint64_t written_tx_ = 0;
};

}  // namespace omnitwin::can
