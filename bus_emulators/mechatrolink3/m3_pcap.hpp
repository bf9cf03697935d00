// bus_emulators/mechatrolink3 — MECHATROLINK-III capture files (pcap, LINKTYPE_ETHERNET = 1)
// that Wireshark and tshark decode with tools/wireshark/mechatrolink3.lua as `eth` → `m3`.
//
// The data link of M-III is not Ethernet, but its frames travel in Ethernet frames here (and
// in UDP datagrams, and in process): every record is the Ethernet frame m3::encapsulate()
// builds, whatever transport moved the frame, so one dissector reads every capture. Station
// MACs come from the frame's addresses (02:4D:33:00:00:<address>, broadcast FF…FF),
// EtherType 0x88B5, zero padding to 60 bytes. Both directions are recorded; the caller says
// which (out: sent by a master; back: sent by a slave) and the writer counts each.
//
// write_frame() also records frames that m3::decode() refuses (a corrupted FCS, a reserved
// address, a bad data length) wrapped exactly as a valid one would be: a capture of a faulty
// line must show what the receiver saw; the dissector flags it. Frames that already carry
// their Ethernet header (a raw capture, or a UDP datagram in its IP and Ethernet headers) go
// in as they are with write_ethernet().
//
// Shaped like ethercat/transport/ec_pcap: libpcap with nanosecond timestamps taken from
// SimTime; the capture is DIR/.NAME.part until close() (or the destructor) renames it to
// DIR/NAME, only when every write succeeded (bus_emulators/pcap_record: PcapFile). write(),
// flush() never throw and allocate nothing (the record buffer is a member): the cyclic path
// may call them. A write error (a full disk) is a status: writes return false from then on,
// ok()/error() say why, and close() leaves DIR/NAME absent.
#pragma once

#include "bus_emulators/mechatrolink3/m3_frame.hpp"

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>

namespace omnitwin::bus_emulators {
class PcapFile;
}

namespace omnitwin::m3 {

enum class Direction : std::uint8_t { out, back };  // out: a master sent it; back: a slave did
const char* to_string(Direction d);

inline constexpr std::size_t kMaxEthFrame = 1514;  // what write_ethernet() takes (no Ethernet FCS)

class PcapWriter {
 public:
  struct Options {
    bool flush_each_frame = false;  // true: every record reaches the kernel at once
    std::size_t buffer_bytes = 64 * 1024;
  };

  // Creates `path`'s .part file (removing a stale `path`); throws std::runtime_error naming
  // `path` on failure.
  explicit PcapWriter(const std::string& path);
  PcapWriter(const std::string& path, Options options);
  ~PcapWriter();
  PcapWriter(const PcapWriter&) = delete;
  PcapWriter& operator=(const PcapWriter&) = delete;

  // Appends one bare M-III frame (header, data, FCS) in its Ethernet encapsulation, stamped
  // t_ns. Any 2 … kMaxFrame bytes are taken, corrupted frames included; others are counted
  // in refused(). False once closed, for a refused frame, or when writing failed. RT-safe.
  bool write_frame(std::span<const std::uint8_t> m3_frame, SimTime t_ns, Direction dir);
  // Appends a whole Ethernet frame as it is, padded to 60 bytes if shorter; over
  // kMaxEthFrame bytes it is refused. RT-safe.
  bool write_ethernet(std::span<const std::uint8_t> eth_frame, SimTime t_ns, Direction dir);
  // Hands buffered records to the kernel; the .part file is valid afterwards.
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

  std::uint64_t written() const { return written_[0] + written_[1]; }
  std::uint64_t written(Direction d) const { return written_[static_cast<int>(d)]; }
  std::uint64_t refused() const { return refused_; }
  const std::string& path() const { return path_; }

  static constexpr int kLinkType = 1;  // LINKTYPE_ETHERNET / DLT_EN10MB

 private:
  bool writable() const;
  bool emit(std::size_t size, SimTime t_ns, Direction dir);

  std::string path_;
  Options options_;
  std::unique_ptr<bus_emulators::PcapFile> file_;  // opaque, so users need not include <pcap.h>
  std::array<std::uint8_t, kMaxEthFrame> frame_{};
  std::uint64_t written_[2] = {0, 0};
  std::uint64_t refused_ = 0;
};

}  // namespace omnitwin::m3
