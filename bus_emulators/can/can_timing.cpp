// bus_emulators/can — the thesis's CAN timing model; see can_timing.hpp.
#include "bus_emulators/can/can_timing.hpp"

#include <stdexcept>

namespace omnitwin::can {

bool valid_bit_rate(std::int64_t bit_rate_bps) {
  return bit_rate_bps >= kMinBitRate && bit_rate_bps <= kMaxBitRate;
}

std::int64_t bits_to_ns(std::int64_t bits, std::int64_t bit_rate_bps) {
  constexpr std::int64_t kNsPerS = 1'000'000'000;
  return (bits * kNsPerS + bit_rate_bps / 2) / bit_rate_bps;
}

std::int64_t transmission_time_ns(const Frame& f, std::int64_t bit_rate_bps, Intermission ifs) {
  const int bits = ifs == Intermission::included ? frame_bits_with_intermission(f) : frame_bits(f);
  return bits_to_ns(bits, bit_rate_bps);
}

MessageDelay message_delay(const Frame& f, std::int64_t bit_rate_bps, std::int64_t wait_ns,
                           const NodeTiming& sender, const NodeTiming& receiver) {
  MessageDelay d;
  d.pre_ns = sender.pre_ns;
  d.wait_ns = wait_ns;
  d.tx_ns = transmission_time_ns(f, bit_rate_bps);
  d.post_ns = receiver.post_ns;
  return d;
}

namespace thesis {

namespace {

struct Reference {
  std::uint32_t id;
  std::array<std::uint8_t, 8> data;
};

// Found offline by an exact dynamic programme over (CRC register, last bit, run length)
// across every free bit (29 identifier bits, 8·n data bits) with the CRC's own stuffing
// added at the end: each reaches the maximum of 11 + 2n stuff bits. The test re-checks the
// counts and, for n = 0, re-proves the maximum.
constexpr std::array<Reference, 9> kReferences{{
    {0x07C30FFC, {}},
    {0x1F0C3FF0, {0xF0}},
    {0x1F0C3DF0, {0x08, 0x3C}},
    {0x01EE1E1E, {0xE1, 0xE1, 0xFF}},
    {0x1F0C1F0F, {0x00, 0xF0, 0xF0, 0xF0}},
    {0x17C30F0F, {0xF0, 0xF0, 0xF0, 0xFF, 0x87}},
    {0x000C3FE0, {0x0F, 0x0F, 0x0F, 0xF8, 0x78, 0x78}},
    {0x1F0C3C3E, {0x87, 0x87, 0x87, 0x87, 0x87, 0x80, 0x00}},
    {0x000C3C3C, {0x3C, 0x3C, 0x3F, 0xFF, 0x0F, 0x0F, 0x0F, 0x0F}},
}};

}  // namespace

Frame table_2_2_frame(int data_bytes) {
  if (data_bytes < 0 || data_bytes > 8)
    throw std::invalid_argument("can::thesis::table_2_2_frame: data_bytes must be 0..8");
  const Reference& r = kReferences[static_cast<std::size_t>(data_bytes)];
  Frame f;
  f.id = r.id;
  f.extended = true;
  f.kind = FrameKind::data;
  f.dlc = static_cast<std::uint8_t>(data_bytes);
  f.data = r.data;
  return f;
}

bool table_2_2_cell_claimed(int row, int data_bytes) {
  return !(row == 0 && data_bytes == 0);
}

}  // namespace thesis

}  // namespace omnitwin::can
