// Tests bus_emulators/ethercat/ec_fmmu: decoding the 16 FMMU register bytes and the bit-exact
// overlap of an FMMU with a datagram's logical range (byte and sub-byte mappings, partial cover).
#include "bus_emulators/ethercat/ec_fmmu.hpp"

#include <gtest/gtest.h>

namespace omnitwin::ethercat {
namespace {

TEST(EcFmmu, DecodesRegisters) {
  const std::uint8_t r[16] = {0x00, 0x00, 0x01, 0x00, 0x04, 0x00, 0x02, 0x05,
                              0x00, 0x11, 0x03, 0x02, 0x01, 0, 0, 0};
  const Fmmu f = decode_fmmu(r);
  EXPECT_EQ(f.logical_start, 0x00010000u);
  EXPECT_EQ(f.length, 4);
  EXPECT_EQ(f.start_bit, 2);
  EXPECT_EQ(f.end_bit, 5);
  EXPECT_EQ(f.physical_start, 0x1100);
  EXPECT_EQ(f.physical_bit, 3);
  EXPECT_TRUE(f.writes());
  EXPECT_FALSE(f.reads());
  EXPECT_TRUE(f.active);
}

TEST(EcFmmu, ByteMappingOverlap) {
  Fmmu f;
  f.logical_start = 0x100;
  f.length = 4;
  f.physical_start = 0x1100;
  f.active = true;
  FmmuSpan s = fmmu_overlap(f, 0x100, 8);
  EXPECT_EQ(s.bits, 32u);
  EXPECT_EQ(s.frame_bit, 0u);
  EXPECT_EQ(s.first_byte(), 0x1100u);
  EXPECT_EQ(s.last_byte(), 0x1103u);
  s = fmmu_overlap(f, 0xFE, 4);  // covers the first two bytes from frame byte 2
  EXPECT_EQ(s.bits, 16u);
  EXPECT_EQ(s.frame_bit, 16u);
  EXPECT_EQ(s.physical_bit, 0x1100u * 8);
  s = fmmu_overlap(f, 0x102, 10);
  EXPECT_EQ(s.bits, 16u);
  EXPECT_EQ(s.frame_bit, 0u);
  EXPECT_EQ(s.first_byte(), 0x1102u);
  EXPECT_EQ(fmmu_overlap(f, 0x104, 4).bits, 0u);
  f.active = false;
  EXPECT_EQ(fmmu_overlap(f, 0x100, 4).bits, 0u);
}

TEST(EcFmmu, BitMappingOverlap) {
  Fmmu f;  // logical bits 4..7 of byte 0x200 → physical 0x0F00 bits 1..4
  f.logical_start = 0x200;
  f.length = 1;
  f.start_bit = 4;
  f.end_bit = 7;
  f.physical_start = 0x0F00;
  f.physical_bit = 1;
  f.active = true;
  const FmmuSpan s = fmmu_overlap(f, 0x1FF, 2);
  EXPECT_EQ(s.bits, 4u);
  EXPECT_EQ(s.frame_bit, 12u);
  EXPECT_EQ(s.physical_bit, 0x0F00u * 8 + 1);
  std::uint8_t frame[2] = {0, 0xA0};
  std::uint8_t mem[1] = {0x81};
  for (std::uint32_t b = 0; b < s.bits; ++b) set_bit(mem, 1 + b, get_bit(frame, s.frame_bit + b));
  EXPECT_EQ(mem[0], 0x81 | (0xA << 1) | 0);  // bit 0 and 7 untouched
  f.end_bit = 3;  // end before start in a one-byte FMMU: nothing
  EXPECT_EQ(fmmu_overlap(f, 0x200, 1).bits, 0u);
}

}  // namespace
}  // namespace omnitwin::ethercat
