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

#include "bus_emulators/ethernet_capture.hpp"

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>


namespace omnitwin::m3 {

enum class Direction : std::uint8_t { out, back };  // out: a master sent it; back: a slave did
const char* to_string(Direction d);

inline constexpr std::size_t kMaxEthFrame = bus_emulators::EthernetCapture::kMaxEthFrame;  // what write_ethernet() takes

class PcapWriter : public bus_emulators::EthernetCapture {
 public:
  struct Options {
    bool flush_each_frame = false;  // true: every record is flushed (on disk within 20 ms)
    std::size_t buffer_bytes = 64 * 1024;
  };

  // Creates `path`'s .part file (removing a stale `path`); throws std::runtime_error naming
  // `path` on failure.
  explicit PcapWriter(const std::string& path) : PcapWriter(path, Options{}) {}
  PcapWriter(const std::string& path, Options options)
      : EthernetCapture(path, options.buffer_bytes, options.flush_each_frame) {}

  // Appends one bare M-III frame (header, data, FCS) in its Ethernet encapsulation, stamped
  // t_ns. Any 2 … kMaxFrame bytes are taken, corrupted frames included; others are counted
  // in refused(). False once closed, for a refused frame, or when writing failed. RT-safe.
  bool write_frame(std::span<const std::uint8_t> m3_frame, SimTime t_ns, Direction dir);
  // Appends a whole Ethernet frame as it is, padded to 60 bytes if shorter; over
  // kMaxEthFrame bytes it is refused. RT-safe.
  bool write_ethernet(std::span<const std::uint8_t> eth_frame, SimTime t_ns, Direction dir) {
    return EthernetCapture::write_ethernet(eth_frame, t_ns, static_cast<int>(dir));
  }

  using EthernetCapture::written;
  std::uint64_t written(Direction d) const { return written_in(static_cast<int>(d)); }
};

}  // namespace omnitwin::m3
