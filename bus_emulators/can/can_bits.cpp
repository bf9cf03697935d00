// bus_emulators/can — the bit sequence of a classic CAN frame; see can_bits.hpp.
#include "bus_emulators/can/can_bits.hpp"

#include <stdexcept>

namespace omnitwin::can {

namespace {

constexpr std::uint8_t kDominant = 0;
constexpr std::uint8_t kRecessive = 1;

// Appends the stuffed form of `in` to `out` (bit stuffing after five equal bits).
void stuff_into(const BitBuffer& in, BitBuffer& out, int& stuff_bits) {
  std::uint8_t last = 2;  // no previous bit
  int run = 0;
  stuff_bits = 0;
  for (int i = 0; i < in.size; ++i) {
    const std::uint8_t b = in[i];
    out.push(b);
    run = (b == last) ? run + 1 : 1;
    last = b;
    if (run == 5) {
      const std::uint8_t s = b ^ 1u;
      out.push(s);
      ++stuff_bits;
      last = s;
      run = 1;
    }
  }
}

// SOF … CRC sequence, destuffed.
BitBuffer stuffable_region(const Frame& f) {
  BitBuffer b = crc_input_bits(f);
  const std::uint16_t crc = crc15(b.data(), b.size);
  b.push_value(crc, kCrcBits);
  return b;
}

void push_tail(BitBuffer& b, Intermission ifs) {
  b.push(kRecessive);  // CRC delimiter
  b.push(kDominant);   // ACK slot, acknowledged by a receiver
  b.push(kRecessive);  // ACK delimiter
  for (int i = 0; i < kEofBits; ++i) b.push(kRecessive);
  if (ifs == Intermission::included)
    for (int i = 0; i < kIntermissionBits; ++i) b.push(kRecessive);
}

BitBuffer error_frame_bits(Intermission ifs) {
  BitBuffer b;
  for (int i = 0; i < kErrorFlagBits; ++i) b.push(kDominant);
  for (int i = 0; i < kErrorDelimiterBits; ++i) b.push(kRecessive);
  if (ifs == Intermission::included)
    for (int i = 0; i < kIntermissionBits; ++i) b.push(kRecessive);
  return b;
}

constexpr int kTailBits = 3 + kEofBits;  // CRC delimiter, ACK slot, ACK delimiter, EOF

}  // namespace

void BitBuffer::push(std::uint8_t bit) {
  if (size >= kMaxWireBits) throw std::length_error("can::BitBuffer: more than kMaxWireBits bits");
  bits[static_cast<std::size_t>(size++)] = bit ? kRecessive : kDominant;
}

void BitBuffer::push_value(std::uint32_t value, int count) {
  for (int i = count - 1; i >= 0; --i) push(static_cast<std::uint8_t>((value >> i) & 1u));
}

std::uint16_t crc15(const std::uint8_t* bits, int count) {
  // ISO 11898-1 shift-register form: CRC_NXT = NXTBIT xor CRC_RG(14); shift left; xor poly.
  std::uint16_t reg = 0;
  for (int i = 0; i < count; ++i) {
    const unsigned next = (bits[i] & 1u) ^ ((reg >> 14) & 1u);
    reg = static_cast<std::uint16_t>((reg << 1) & 0x7FFF);
    if (next) reg ^= kCrc15Polynomial;
  }
  return reg;
}

BitBuffer crc_input_bits(const Frame& f) {
  BitBuffer b;
  if (f.kind == FrameKind::error) return b;
  const std::uint8_t rtr = f.kind == FrameKind::remote ? kRecessive : kDominant;
  b.push(kDominant);  // SOF
  if (f.extended) {
    b.push_value((f.id >> 18) & 0x7FFu, 11);  // base identifier
    b.push(kRecessive);                       // SRR
    b.push(kRecessive);                       // IDE
    b.push_value(f.id & 0x3FFFFu, 18);        // identifier extension
    b.push(rtr);
    b.push(kDominant);  // r1
    b.push(kDominant);  // r0
  } else {
    b.push_value(f.id & 0x7FFu, 11);
    b.push(rtr);
    b.push(kDominant);  // IDE
    b.push(kDominant);  // r0
  }
  b.push_value(f.dlc & 0xFu, 4);
  for (int i = 0; i < f.payload_size(); ++i) b.push_value(f.data[static_cast<std::size_t>(i)], 8);
  return b;
}

BitBuffer unstuffed_bits(const Frame& f, Intermission ifs) {
  if (f.kind == FrameKind::error) return error_frame_bits(ifs);
  BitBuffer b = stuffable_region(f);
  push_tail(b, ifs);
  return b;
}

BitBuffer stuffed_bits(const Frame& f, Intermission ifs) {
  if (f.kind == FrameKind::error) return error_frame_bits(ifs);
  const BitBuffer region = stuffable_region(f);
  BitBuffer out;
  int stuff = 0;
  stuff_into(region, out, stuff);
  push_tail(out, ifs);
  return out;
}

// The stuff bits a region needs, counted without building the stuffed copy (the same rule as
// stuff_into: after five equal bits a complement, which starts the next run).
static int count_stuff(const BitBuffer& in) {
  std::uint8_t last = 2;
  int run = 0, stuff = 0;
  for (int i = 0; i < in.size; ++i) {
    const std::uint8_t b = in[i];
    run = (b == last) ? run + 1 : 1;
    last = b;
    if (run == 5) {
      ++stuff;
      last = b ^ 1u;
      run = 1;
    }
  }
  return stuff;
}

int stuff_bit_count(const Frame& f) {
  if (f.kind == FrameKind::error) return 0;
  return count_stuff(stuffable_region(f));
}

int stuffed_region_bits(const Frame& f) {
  if (f.kind == FrameKind::error) return 0;
  // One pass: the region (SOF … CRC) built once, its stuff bits counted in place.
  const BitBuffer region = stuffable_region(f);
  return region.size + count_stuff(region);
}

int frame_bits(const Frame& f) {
  if (f.kind == FrameKind::error) return kErrorFlagBits + kErrorDelimiterBits;
  return stuffed_region_bits(f) + kTailBits;
}

int frame_bits_with_intermission(const Frame& f) { return frame_bits(f) + kIntermissionBits; }

int worst_case_frame_bits(bool extended, int data_bytes, Intermission ifs) {
  if (data_bytes < 0 || data_bytes > 8)
    throw std::invalid_argument("can::worst_case_frame_bits: data_bytes must be 0..8");
  const int g = extended ? 54 : 34;  // stuffable bits besides the data
  const int stuffable = g + 8 * data_bytes;
  const int bits = stuffable + (stuffable - 1) / 4 + kTailBits;
  return bits + (ifs == Intermission::included ? kIntermissionBits : 0);
}

bool destuff(const std::uint8_t* stuffed, int count, BitBuffer& out) {
  out.size = 0;
  std::uint8_t last = 2;
  int run = 0;
  for (int i = 0; i < count; ++i) {
    const std::uint8_t b = stuffed[i] ? kRecessive : kDominant;
    if (run == 5) {  // this bit must be a stuff bit of the opposite value
      if (b == last) return false;
      last = b;
      run = 1;
      continue;
    }
    out.push(b);
    run = (b == last) ? run + 1 : 1;
    last = b;
  }
  return true;
}

}  // namespace omnitwin::can
