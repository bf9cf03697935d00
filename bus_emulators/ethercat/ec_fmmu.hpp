// bus_emulators/ethercat — FMMUs: bit-granular mapping of the logical address space (LRD/LWR/LRW)
// onto the ESC's physical memory.
//
// An FMMU entry (16 bytes at 0x0600 + 16·i) maps the logical bits from logical_start·8 +
// start_bit to (logical_start + length − 1)·8 + end_bit onto consecutive physical bits from
// physical_start·8 + physical_bit. Type bit 0 = read (memory → frame, inputs), bit 1 = write
// (frame → memory, outputs). Small slaves map a few bits, so the mapping is per bit; bits of a
// byte not covered by the FMMU are left untouched in the frame and in memory.
#pragma once

#include <cstdint>

namespace omnitwin::ethercat {

struct Fmmu {
  std::uint32_t logical_start = 0;
  std::uint16_t length = 0;
  std::uint8_t start_bit = 0, end_bit = 7;
  std::uint16_t physical_start = 0;
  std::uint8_t physical_bit = 0, type = 0;
  bool active = false;

  bool reads() const { return (type & 0x01) != 0; }
  bool writes() const { return (type & 0x02) != 0; }
};

Fmmu decode_fmmu(const std::uint8_t* regs16) noexcept;  // the 16 register bytes

// The overlap of one FMMU with a datagram's logical byte range [address, address + length).
struct FmmuSpan {
  std::uint32_t frame_bit = 0;     // first bit, counted from the datagram's first data bit
  std::uint32_t physical_bit = 0;  // first physical bit (address · 8 + bit)
  std::uint32_t bits = 0;          // 0: no overlap
  std::uint32_t first_byte() const { return physical_bit >> 3; }
  std::uint32_t last_byte() const { return (physical_bit + bits - 1) >> 3; }
};

// Real-time safe. An inactive FMMU, length 0 or end before start gives bits = 0.
FmmuSpan fmmu_overlap(const Fmmu& f, std::uint32_t address, std::uint16_t length) noexcept;

inline bool get_bit(const std::uint8_t* p, std::uint32_t bit) { return (p[bit >> 3] >> (bit & 7)) & 1; }
inline void set_bit(std::uint8_t* p, std::uint32_t bit, bool v) {
  const auto m = static_cast<std::uint8_t>(1u << (bit & 7));
  p[bit >> 3] = static_cast<std::uint8_t>(v ? (p[bit >> 3] | m) : (p[bit >> 3] & ~m));
}

}  // namespace omnitwin::ethercat
