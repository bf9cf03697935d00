// bus_emulators/mechatrolink3 — the MECHATROLINK-III data-link frame codec shared by every
// M-III layer (slaves, the line model, transports, pcap, our C1 master, the dissector).
//
// Seed 000 table 2 names the fields of an M-III frame: preamble and SFD, destination
// address, source address, message control, frame type, data length, information field and
// FCS; their sizes and codes are not public, so the layout below is ours
// (docs/protocols/mechatrolink3.md says so line by line). Preamble and SFD are physical layer:
// they are never carried, only counted in frame times (m3_wire). The frame as carried:
//
//   offset  size  field
//   0       1     destination address  01h C1 master, 02h C2 master, 03h-EFh slaves, FFh all
//   1       1     source address       as above (never FFh)
//   2       1     message control      bits 0-3 cycle sequence (mod 16), bit 4 retry, 5-7 zero
//   3       1     frame type           FrameType
//   4       1     data length          bytes of information field, 0 … 64; fixed per type
//   5       n     information field    the application's command or response
//   5+n     4     FCS                  CRC-32 (IEEE 802.3, zlib's crc32) of bytes 0 … 4+n,
//                                      little endian
//
// The frame's own FCS is kept inside every encapsulation (Ethernet frames with EtherType
// 0x88B5, UDP datagrams, in process) so a corrupted frame is found where the ASIC would find
// it: the receiver, not the transport. Ethernet encapsulation pads to the 60-byte minimum;
// the data length field makes the padding unambiguous (a receiver accepts anything after the
// frame only within 64 bytes: padding, or an Ethernet FCS that a capture kept).
//
// Shaped like ec_frame: decode() hands out a view into the caller's bytes and never copies,
// allocates or throws; encode() writes into a caller buffer. Nothing here knows sockets or time.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

namespace omnitwin::m3 {

using SimTime = std::int64_t;  // ns on the simulated timeline

inline constexpr std::uint16_t kEtherType = 0x88B5;  // IEEE 802 local experimental EtherType 1
inline constexpr std::uint16_t kUdpPort = 0x88B5;    // 34997, UDP encapsulation's default
inline constexpr std::size_t kHeaderSize = 5, kFcsSize = 4, kMaxData = 64;
inline constexpr std::size_t kMaxFrame = kHeaderSize + kMaxData + kFcsSize;  // 73
inline constexpr std::size_t kEthHeaderSize = 14, kMinEthFrame = 60;
inline constexpr int kMaxSlaves = 62;  // seed 000 table 1

// Station addresses (the address bytes).
inline constexpr std::uint8_t kC1Master = 0x01, kC2Master = 0x02, kFirstSlave = 0x03, kLastSlave = 0xEF,
                              kBroadcast = 0xFF;
bool is_slave_address(std::uint8_t a) noexcept;
bool is_station_address(std::uint8_t a) noexcept;  // a master or a slave: may send frames

// Frame types (our codes). The link services before communication starts are what the C1
// master driver of seed 000 figs. 9-11 asks the ASIC for: connected-station detection, the
// delay (TR_DLY) measurement, transmission-cycle notification and communication start.
enum class FrameType : std::uint8_t {
  sync = 0x01,             // C1 → all: a transmission cycle begins (cyclic mode)
  cyclic_command = 0x02,   // C1 → slave, one per slave per cycle (and retries)
  cyclic_response = 0x03,  // slave → C1
  event_command = 0x04,    // C1 → slave, event-driven mode (64 bytes)
  event_response = 0x05,   // slave → C1
  detect = 0x10,           // C1 → station: are you connected?
  detect_reply = 0x11,     // station → C1: StationInfo
  delay_request = 0x12,    // C1 → slave: echo this at once (TR_DLY measurement)
  delay_reply = 0x13,      // slave → C1
  cycle_notify = 0x14,     // C1 → all: the transmission cycle and this slave's timing
  comm_start = 0x15,       // C1 → all: cyclic or event-driven communication starts
};
const char* to_string(FrameType);  // "SYNC", "CMD", …; "?" for undefined values
bool is_known(FrameType) noexcept;

// Why a frame was refused. Spec-like status codes: the receiver counts them, never throws.
enum class FrameStatus : std::uint8_t {
  ok,
  truncated,         // fewer bytes than a header and FCS, or than the data length says
  oversized,         // more than kMaxFrame bytes (after removing any encapsulation padding)
  bad_fcs,           // the FCS does not match: corrupted on the line
  bad_address,       // a reserved destination or an invalid source address
  unknown_type,      // a frame type this codec does not define
  bad_data_length,   // a data length the frame type does not allow
  bad_control,       // reserved message-control bits set
  not_m3,            // Ethernet: another EtherType
};
const char* to_string(FrameStatus);

// Message control byte.
inline constexpr std::uint8_t kSequenceMask = 0x0F, kRetryBit = 0x10, kReservedControl = 0xE0;

// The data lengths a cyclic exchange may use (seed 000: 8/16/32/48/64 per slave).
bool is_cyclic_length(std::size_t n) noexcept;
// Whether `type` allows an information field of n bytes. Real-time safe.
bool data_length_allowed(FrameType type, std::size_t n) noexcept;

// A decoded frame: a view into the bytes decode() was given.
struct FrameView {
  std::uint8_t dst = 0, src = 0, control = 0;
  FrameType type = FrameType::sync;
  std::span<const std::uint8_t> data;

  std::uint8_t sequence() const { return control & kSequenceMask; }
  bool retry() const { return (control & kRetryBit) != 0; }
};

// A frame to encode.
struct FrameSpec {
  std::uint8_t dst = kBroadcast, src = kC1Master;
  FrameType type = FrameType::sync;
  std::uint8_t sequence = 0;  // taken mod 16
  bool retry = false;
  std::span<const std::uint8_t> data;
};

// Decodes exactly `bytes` (header, data, FCS; no padding). Real-time safe: no allocation.
FrameStatus decode(std::span<const std::uint8_t> bytes, FrameView& out);
// Like decode(), for a buffer that may hold padding after the frame (the Ethernet minimum):
// the data length field says where the frame ends.
FrameStatus decode_prefix(std::span<const std::uint8_t> bytes, FrameView& out, std::size_t* used = nullptr);

// Writes the frame into out; returns its size (kHeaderSize + data + kFcsSize), or 0 when out
// is too small or the spec is not a valid frame (data length, addresses). Real-time safe.
std::size_t encode(const FrameSpec& f, std::span<std::uint8_t> out);

// CRC-32 (IEEE 802.3) of the bytes. Real-time safe.
std::uint32_t fcs(std::span<const std::uint8_t> bytes) noexcept;

// ---- Ethernet encapsulation ------------------------------------------------------------

using Mac = std::array<std::uint8_t, 6>;
// A station's MAC: locally administered 02:4D:33:00:00:<address> ("M3"); broadcast FF…FF.
Mac station_mac(std::uint8_t address) noexcept;

// Wraps an M-III frame (as encode() wrote it) in an Ethernet frame: station MACs from the
// frame's addresses, EtherType 0x88B5, zero padding to 60 bytes. Returns the Ethernet frame
// size or 0 if out is too small or m3 is not a frame. Real-time safe.
std::size_t encapsulate(std::span<const std::uint8_t> m3, std::span<std::uint8_t> out);
// The M-III frame inside an Ethernet frame: not_m3 for another EtherType, otherwise what
// decode_prefix() says about the payload. Real-time safe.
FrameStatus decapsulate(std::span<const std::uint8_t> eth, FrameView& out);

}  // namespace omnitwin::m3
