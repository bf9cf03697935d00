// bus_emulators/ethercat/transport — EtherCAT capture files (pcap, LINKTYPE_ETHERNET = 1) that
// Wireshark and tshark decode as `eth` → `ecatf` → `ecat`.
//
// Both directions of every exchange are recorded as the Ethernet frames a wire would carry,
// whatever transport moved them (raw, UDP, in-process): the frame going out is addressed from
// the master's MAC to ff:ff:ff:ff:ff:ff, the frame coming back has bit 1 of the first
// source-MAC byte set (as ESCs mark it), both with EtherType 0x88A4 and padded with zeros to
// 60 bytes. When the transport knows the addresses a frame really carried (raw), the caller
// passes them and the record shows those, so a capture shows what was on the wire. Frames already carrying their Ethernet header (a raw capture) can be written as
// they are with write_frame().
//
// Written through libpcap (pcap_open_dead_with_tstamp_precision + pcap_dump_fopen) with
// nanosecond timestamps taken from SimTime (the file gets the nanosecond pcap magic), so the
// records line up with the simulated timeline. The capture is written as DIR/.NAME.part and
// renamed to DIR/NAME by close() (or the destructor) only when every write succeeded
// (bus_emulators/pcap_record: PcapFile); a stale DIR/NAME is removed at open. Buffered (a
// 64 KiB stdio buffer by default; one EtherCAT cycle is one or two records): the .part file
// is valid up to each flush() once the write-behind thread wrote it (within 20 ms,
// bus_emulators/write_behind); the file header is flushed when it is opened, so an empty
// capture is valid too. A run that must survive SIGKILL sets flush_each_frame (or flushes
// per tick) and finds the capture in the .part file; SIGINT/SIGTERM end the run normally and
// the destructor closes and renames it (as bus_emulators/can/can_pcap).
//
// write() and flush() never throw and allocate nothing (the record buffer is a member), so the
// cyclic path may call them; a full stdio buffer costs a copy, never a write(2). A write error (a full
// disk) is a status: write() and flush() return false from then on, ok()/error() say why,
// and close() removes the .part file, so that DIR/NAME stays absent.
#pragma once

#include "bus_emulators/ethercat/ec_frame.hpp"

#include "bus_emulators/ethernet_capture.hpp"

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>

namespace omnitwin::ethercat {

enum class Direction : std::uint8_t { out, back };  // out: master → slaves; back: the returned frame
const char* to_string(Direction d);

// 00:00:5e:00:53:01, from the range RFC 7042 reserves for documentation: bit 1 of its first
// byte is clear, so the marked source of returned frames (02:00:5e:00:53:01) differs from it.
inline constexpr Mac kDefaultMasterMac = {0x00, 0x00, 0x5e, 0x00, 0x53, 0x01};

class PcapWriter : public bus_emulators::EthernetCapture {
 public:
  struct Options {
    Mac master_mac = kDefaultMasterMac;  // source of out frames (a raw master: its NIC's MAC)
    bool flush_each_frame = false;       // true: every record is flushed (on disk within 20 ms)
    std::size_t buffer_bytes = 64 * 1024;
  };

  // Creates `path`'s .part file (removing a stale `path`); throws std::runtime_error naming
  // `path` on failure.
  explicit PcapWriter(const std::string& path) : PcapWriter(path, Options{}) {}
  PcapWriter(const std::string& path, Options options)
      : EthernetCapture(path, options.buffer_bytes, options.flush_each_frame), master_mac_(options.master_mac) {}

  // Appends one PDU as an Ethernet frame stamped t [ns] (see the file comment for the
  // addresses). Returns false once closed, for a PDU over kMaxPdu bytes (counted in
  // refused()), or when writing or flushing failed (then and from then on). RT-safe.
  bool write(std::span<const std::uint8_t> pdu, SimTime t, Direction dir);
  // The same with the addresses the frame carried on the wire (a raw transport): an out frame as
  // `dst` ← `src`; a returned one as `dst` ← `src` with bit 1 of its first byte set, as the
  // first slave marks it on its way back.
  bool write(std::span<const std::uint8_t> pdu, SimTime t, Direction dir, const Mac& dst, const Mac& src);
  // Appends a whole Ethernet frame (header included) as it is, padded to 60 bytes if shorter.
  bool write_frame(std::span<const std::uint8_t> frame, SimTime t, Direction dir) {
    return write_ethernet(frame, t, static_cast<int>(dir));
  }

  using EthernetCapture::written;
  std::uint64_t written(Direction d) const { return written_in(static_cast<int>(d)); }

 private:
  Mac master_mac_;
};

}  // namespace omnitwin::ethercat
