// bus_emulators/ethercat — the EtherCAT frame codec shared by every EtherCAT layer (ESC core,
// slave devices, transports, pcap, our master).
//
// An EtherCAT PDU is the 2-byte EtherCAT header (length: 11 bits, type: 4 bits at 15:12,
// type 1 = "talk to slaves") followed by datagrams chained by the M ("more") bit. A datagram
// is a 10-byte header (cmd u8, index u8, ADP u16, ADO u16, length u16 = 11-bit data length |
// bit 14 circulating | bit 15 more, IRQ u16), the data, and a 16-bit working counter. All
// multi-byte fields are little endian.
//
// Shaped as views over caller memory: slaves process datagrams in place as the frame passes
// (read, write, WKC increment, ADP increment), so parse_pdu() hands out Datagram views into
// the caller's buffer and never copies, allocates or throws. PduBuilder is the reverse (the
// master side and tests). Nothing here knows about sockets or time.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

namespace omnitwin::ethercat {

using SimTime = std::int64_t;  // ns on the simulated timeline

inline constexpr std::uint16_t kEtherType = 0x88A4;
inline constexpr std::uint16_t kUdpPort = 0x88A4;  // 34980
inline constexpr std::size_t kEthHeaderSize = 14, kEcatHeaderSize = 2, kDatagramHeaderSize = 10,
                             kWkcSize = 2, kMinEthFrame = 60,
                             kMaxPdu = 1500;  // PDU = EtherCAT header + datagrams
inline constexpr std::size_t kMaxDatagrams = 64;
inline constexpr std::uint16_t kMaxDatagramData = 0x07FF;  // 11-bit length field
inline constexpr std::uint8_t kPduTypeSlaves = 1;          // EtherCAT header type "commands"

using Mac = std::array<std::uint8_t, 6>;

// Datagram commands (the cmd byte). Values above frmw are not defined by the standard.
enum class Cmd : std::uint8_t {
  nop = 0, aprd, apwr, aprw, fprd, fpwr, fprw, brd, bwr, brw, lrd, lwr, lrw, armw, frmw
};
const char* to_string(Cmd);  // "APRD", …; "?" for undefined values

// Command classification (what the addressed slave does with the data).
enum class CmdAddressing : std::uint8_t { none, position, node, broadcast, logical };
CmdAddressing addressing(Cmd) noexcept;
bool cmd_reads(Cmd) noexcept;   // the addressed slave copies memory into the datagram
bool cmd_writes(Cmd) noexcept;  // the addressed slave copies the datagram into memory

// Little-endian helpers. Real-time safe.
inline std::uint16_t get_u16(const std::uint8_t* p) {
  return static_cast<std::uint16_t>(p[0] | (p[1] << 8));
}
inline std::uint32_t get_u32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}
inline std::uint64_t get_u64(const std::uint8_t* p) {
  return static_cast<std::uint64_t>(get_u32(p)) | (static_cast<std::uint64_t>(get_u32(p + 4)) << 32);
}
inline void put_u16(std::uint8_t* p, std::uint16_t v) {
  p[0] = static_cast<std::uint8_t>(v);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}
inline void put_u32(std::uint8_t* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
inline void put_u64(std::uint8_t* p, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

// A view of one datagram inside a PDU buffer (no ownership). The header pointer must point at
// a complete datagram (header, length() data bytes, WKC), as parse_pdu() guarantees.
class Datagram {
 public:
  explicit Datagram(std::uint8_t* header = nullptr) : h_(header) {}

  bool valid() const { return h_ != nullptr; }
  Cmd cmd() const { return static_cast<Cmd>(h_[0]); }
  std::uint8_t raw_cmd() const { return h_[0]; }
  std::uint8_t index() const { return h_[1]; }
  std::uint16_t adp() const { return get_u16(h_ + 2); }
  std::uint16_t ado() const { return get_u16(h_ + 4); }
  std::uint32_t logical() const { return get_u32(h_ + 2); }  // adp | ado << 16
  std::uint16_t length() const { return get_u16(h_ + 6) & kMaxDatagramData; }  // data bytes
  bool circulating() const { return (get_u16(h_ + 6) & 0x4000) != 0; }
  bool more() const { return (get_u16(h_ + 6) & 0x8000) != 0; }
  std::uint16_t irq() const { return get_u16(h_ + 8); }
  std::uint8_t* data() const { return h_ + kDatagramHeaderSize; }
  std::span<std::uint8_t> payload() const { return {data(), length()}; }
  std::uint16_t wkc() const { return get_u16(h_ + kDatagramHeaderSize + length()); }

  void set_adp(std::uint16_t v) { put_u16(h_ + 2, v); }
  void set_ado(std::uint16_t v) { put_u16(h_ + 4, v); }
  void set_wkc(std::uint16_t v) { put_u16(h_ + kDatagramHeaderSize + length(), v); }
  void set_irq(std::uint16_t v) { put_u16(h_ + 8, v); }
  void set_circulating(bool on) {
    const std::uint16_t f = get_u16(h_ + 6);
    put_u16(h_ + 6, static_cast<std::uint16_t>(on ? (f | 0x4000) : (f & ~0x4000)));
  }

  std::size_t size() const { return kDatagramHeaderSize + length() + kWkcSize; }  // header + data + wkc
  std::uint8_t* header() const { return h_; }

 private:
  std::uint8_t* h_;
};

enum class PduError : std::uint8_t {
  ok,
  too_short,           // fewer than 2 bytes, or fewer than the header length declares
  wrong_type,          // EtherCAT header type is not 1
  length_mismatch,     // header length > 1498, or the datagram chain ends before it
  truncated_datagram,  // a datagram (or the chain: M set on the last one) runs past the header length
  too_many_datagrams,  // more than kMaxDatagrams chained
};
const char* to_string(PduError);

struct PduView {
  std::array<Datagram, kMaxDatagrams> datagrams;
  std::size_t count = 0;
  std::size_t length = 0;  // EtherCAT header + datagrams (bytes after it are padding)
};

// Parses an EtherCAT PDU (2-byte header, type 1, then datagrams chained by the M bit) in place.
// Bytes after the declared length (Ethernet padding) are allowed; the header length must cover
// exactly the chained datagrams (at least one). Never throws, never allocates. On error `out`
// holds count = 0.
PduError parse_pdu(std::span<std::uint8_t> pdu, PduView& out) noexcept;

// Builds a PDU into caller memory (master side, tests). Real-time safe (no allocation).
class PduBuilder {
 public:
  explicit PduBuilder(std::span<std::uint8_t> buf);  // at most kMaxPdu bytes of buf are used

  // Appends one datagram with `length` data bytes (copied from data, zeros if null), WKC 0,
  // IRQ 0. Returns the offset of its data within buf, or -1 when it does not fit (buffer
  // room, 11-bit length, kMaxDatagrams).
  int add(Cmd cmd, std::uint8_t index, std::uint16_t adp, std::uint16_t ado, std::uint16_t length,
          const void* data = nullptr);
  int add_logical(Cmd cmd, std::uint8_t index, std::uint32_t address, std::uint16_t length,
                  const void* data = nullptr);
  std::size_t finish();  // writes the EtherCAT header, sets the M bits; returns the PDU size
  void reset();          // empties the builder (same buffer)
  std::size_t datagrams() const { return count_; }
  std::size_t size() const { return pos_; }
  std::size_t room() const;  // data bytes a further datagram could still carry
  // A point to come back to: rewind(mark()) drops every datagram added since (a caller that
  // wants a group of datagrams whole or not at all). Real-time safe.
  struct Mark {
    std::size_t pos = 0, count = 0, last = 0;
  };
  Mark mark() const { return {pos_, count_, last_}; }
  void rewind(const Mark& m);

 private:
  std::span<std::uint8_t> buf_;
  std::size_t cap_ = 0;
  std::size_t pos_ = kEcatHeaderSize;
  std::size_t count_ = 0;
  std::size_t last_ = 0;  // offset of the last datagram header (valid when count_ > 0)
};

// Ethernet framing (raw transport, pcap): dst, src, EtherType 0x88A4 (big endian on the wire).
std::size_t write_eth_header(std::uint8_t* out, const Mac& dst, const Mac& src) noexcept;  // returns 14

}  // namespace omnitwin::ethercat
