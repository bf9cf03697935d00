// Tests bus_emulators/can/can_bits: the CRC-15 against the catalogue check value and against an
// independent long-division reference, the field layout of standard/extended/remote frames,
// stuff-bit insertion (all-zero frames, worst-case bounds, no six equal bits on the wire,
// destuffing round trip and stuff errors), and the frame lengths 44/108/64/128 (+3).
#include "bus_emulators/can/can_bits.hpp"

#include <gtest/gtest.h>

#include <bitset>
#include <string>

namespace omnitwin::can {
namespace {

// --- independent reference: frames as '0'/'1' strings, CRC by polynomial long division ---

std::string ref_field(std::uint32_t value, int width) {
  return std::bitset<32>(value).to_string().substr(static_cast<std::size_t>(32 - width));
}

std::string ref_crc_input(const Frame& f) {
  const bool remote = f.kind == FrameKind::remote;
  std::string s = "0";
  if (f.extended)
    s += ref_field(f.id >> 18, 11) + "11" + ref_field(f.id & 0x3FFFF, 18) + (remote ? "1" : "0") + "00";
  else
    s += ref_field(f.id, 11) + (remote ? "1" : "0") + "00";
  s += ref_field(f.dlc, 4);
  for (int i = 0; i < f.payload_size(); ++i) s += ref_field(f.data[static_cast<std::size_t>(i)], 8);
  return s;
}

// Remainder of message·x^15 divided by the generator x^15+x^14+x^10+x^8+x^7+x^4+x^3+1.
std::uint16_t ref_crc(const std::string& message) {
  const std::string generator = "1100010110011001";  // 0xC599, 16 coefficients
  std::string r = message + std::string(15, '0');
  for (std::size_t i = 0; i + 15 < r.size(); ++i) {
    if (r[i] != '1') continue;
    for (std::size_t j = 0; j < generator.size(); ++j) r[i + j] = (r[i + j] == generator[j]) ? '0' : '1';
  }
  return static_cast<std::uint16_t>(std::stoul(r.substr(r.size() - 15), nullptr, 2));
}

std::string as_string(const BitBuffer& b) {
  std::string s;
  for (int i = 0; i < b.size; ++i) s += b[i] ? '1' : '0';
  return s;
}

std::uint16_t crc_of(const Frame& f) {
  const BitBuffer in = crc_input_bits(f);
  return crc15(in.data(), in.size);
}

// Deterministic frame generator for property sweeps.
struct Lcg {
  std::uint64_t s = 12345;
  std::uint32_t next() {
    s = s * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<std::uint32_t>(s >> 33);
  }
};

Frame random_frame(Lcg& g) {
  Frame f;
  f.extended = g.next() & 1u;
  f.id = g.next() & (f.extended ? 0x1FFFFFFFu : 0x7FFu);
  f.kind = (g.next() % 5 == 0) ? FrameKind::remote : FrameKind::data;
  f.dlc = static_cast<std::uint8_t>(g.next() % 9);
  const std::uint32_t style = g.next() % 3;  // random, all-zero, all-one bytes: runs matter
  for (auto& d : f.data) d = style == 0 ? static_cast<std::uint8_t>(g.next()) : (style == 1 ? 0x00 : 0xFF);
  return f;
}

TEST(CanBits, Crc15MatchesTheCatalogueCheckValue) {
  // CRC-15/CAN of ASCII "123456789" is 0x059E (init 0, no reflection, no final xor).
  BitBuffer b;
  for (char c : std::string("123456789")) b.push_value(static_cast<std::uint8_t>(c), 8);
  EXPECT_EQ(crc15(b.data(), b.size), 0x059E);
  EXPECT_EQ(ref_crc("00110001001100100011001100110100001101010011011000110111001110000011100"
                    "1"),
            0x059E);
}

TEST(CanBits, Crc15OfFramesMatchesGoldenValuesAndTheLongDivisionReference) {
  // Golden values computed independently (Python shift register) for the thesis's frames.
  EXPECT_EQ(crc_of(make_data(0x102, {0x02, 0, 0, 0, 0})), 0x313C);
  EXPECT_EQ(crc_of(make_remote(0x000)), 0x73C5);
  EXPECT_EQ(crc_of(make_data(0x1ABCDEF0, {0x11}, true)), 0x7DA7);
  EXPECT_EQ(crc_of(make_data(0x7FF, {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF})), 0x4C89);
  Lcg g;
  for (int i = 0; i < 500; ++i) {
    const Frame f = random_frame(g);
    ASSERT_EQ(as_string(crc_input_bits(f)), ref_crc_input(f)) << to_string(f);
    ASSERT_EQ(crc_of(f), ref_crc(ref_crc_input(f))) << to_string(f);
  }
}

TEST(CanBits, FieldLayoutOfStandardExtendedAndRemoteFrames) {
  const BitBuffer s = crc_input_bits(make_data(0x555, {0xA5}));
  EXPECT_EQ(as_string(s), "0" "10101010101" "0" "0" "0" "0001" "10100101");
  const BitBuffer r = crc_input_bits(make_remote(0x001, 3));
  EXPECT_EQ(as_string(r), "0" "00000000001" "1" "00" "0011");  // RTR recessive, DLC kept, no data
  const BitBuffer x = crc_input_bits(make_data(0x12345678, {}, true));
  ASSERT_EQ(x.size, 39);
  EXPECT_EQ(x[12], 1);  // SRR recessive
  EXPECT_EQ(x[13], 1);  // IDE recessive
  EXPECT_EQ(as_string(x).substr(1, 11), ref_field(0x12345678u >> 18, 11));
  EXPECT_EQ(as_string(x).substr(14, 18), ref_field(0x12345678u & 0x3FFFF, 18));
  EXPECT_EQ(as_string(x).substr(32, 3), "000");  // RTR, r1, r0
}

TEST(CanBits, UnstuffedLengthsAreTheTextbookValues) {
  EXPECT_EQ(unstuffed_bits(make_data(0x123, {})).size, 44);
  EXPECT_EQ(unstuffed_bits(make_data(0x123, {1, 2, 3, 4, 5, 6, 7, 8})).size, 108);
  EXPECT_EQ(unstuffed_bits(make_data(0x123, {}, true)).size, 64);
  EXPECT_EQ(unstuffed_bits(make_data(0x123, {1, 2, 3, 4, 5, 6, 7, 8}, true)).size, 128);
  EXPECT_EQ(unstuffed_bits(make_data(0x123, {}), Intermission::included).size, 47);
  EXPECT_EQ(unstuffed_bits(make_data(0x123, {1, 2, 3, 4, 5, 6, 7, 8}), Intermission::included).size, 111);
  EXPECT_EQ(unstuffed_bits(make_data(0x123, {}, true), Intermission::included).size, 67);
  EXPECT_EQ(unstuffed_bits(make_data(0x123, {1, 2, 3, 4, 5, 6, 7, 8}, true), Intermission::included).size, 131);
  EXPECT_EQ(unstuffed_bits(make_remote(0x123, 8)).size, 44);  // a remote frame carries no data
}

TEST(CanBits, AllZeroFrameStillGetsStuffBits) {
  // id 0, DLC 0: 34 dominant bits and a zero CRC: a recessive stuff bit after every five
  // dominant ones (the stuff bit ends the run, so the next run is again five long).
  const Frame f = make_data(0x000, {});
  EXPECT_EQ(crc_of(f), 0);
  EXPECT_EQ(stuff_bit_count(f), 6);
  EXPECT_EQ(stuffed_region_bits(f), 40);
  EXPECT_EQ(frame_bits(f), 50);
  EXPECT_EQ(frame_bits_with_intermission(f), 53);
  const BitBuffer w = stuffed_bits(f);
  EXPECT_EQ(as_string(w).substr(0, 40), "0000010000010000010000010000010000010000");
}

TEST(CanBits, WireTailIsDelimitersAckAndEof) {
  const Frame f = make_data(0x102, {0x02, 0, 0, 0, 0});
  const BitBuffer w = stuffed_bits(f, Intermission::included);
  const int region = stuffed_region_bits(f);
  ASSERT_EQ(w.size, region + 10 + 3);
  EXPECT_EQ(as_string(w).substr(static_cast<std::size_t>(region)), "1" "0" "1" "1111111" "111");
  EXPECT_EQ(stuff_bit_count(f), 9);
  EXPECT_EQ(frame_bits(f), 93);
}

TEST(CanBits, StuffCountsOfWorstCasePatterns) {
  // Bound: floor((g + 8n − 1) / 4) stuff bits, g = 34 / 54; with intermission 55+10n / 80+10n.
  EXPECT_EQ(worst_case_frame_bits(false, 0), 55);
  EXPECT_EQ(worst_case_frame_bits(false, 8), 135);
  EXPECT_EQ(worst_case_frame_bits(true, 0), 80);
  EXPECT_EQ(worst_case_frame_bits(true, 8), 160);
  EXPECT_EQ(worst_case_frame_bits(true, 8, Intermission::excluded), 157);
  EXPECT_THROW(worst_case_frame_bits(true, 9), std::invalid_argument);
  // All-dominant and all-recessive data: runs of 8n equal bits stuffed every 4 after the first 5.
  EXPECT_EQ(stuff_bit_count(make_data(0x000, {0, 0, 0, 0, 0, 0, 0, 0})), 16);
  EXPECT_EQ(stuff_bit_count(make_data(0x7FF, {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF})), 15);
  // Alternating bits never need stuffing: 0x555 id, 0x55 data (runs only where fields meet).
  EXPECT_LE(stuff_bit_count(make_data(0x555, {0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55})), 2);
  // No real frame exceeds the bound; the stuffed wire never shows six equal bits.
  Lcg g;
  for (int i = 0; i < 3000; ++i) {
    const Frame f = random_frame(g);
    const int n = f.payload_size();
    const int g_bits = f.extended ? 54 : 34;
    ASSERT_LE(stuff_bit_count(f), (g_bits + 8 * n - 1) / 4) << to_string(f);
    const BitBuffer w = stuffed_bits(f);
    const int region = stuffed_region_bits(f);
    int run = 1;
    for (int k = 1; k < region; ++k) {
      run = (w[k] == w[k - 1]) ? run + 1 : 1;
      ASSERT_LT(run, 6) << to_string(f) << " at bit " << k;
    }
  }
}

TEST(CanBits, DestuffRecoversTheRegionAndDetectsStuffErrors) {
  Lcg g;
  for (int i = 0; i < 500; ++i) {
    const Frame f = random_frame(g);
    const BitBuffer w = stuffed_bits(f);
    BitBuffer out;
    ASSERT_TRUE(destuff(w.data(), stuffed_region_bits(f), out));
    const BitBuffer u = unstuffed_bits(f);
    ASSERT_EQ(as_string(out), as_string(u).substr(0, static_cast<std::size_t>(out.size)));
    ASSERT_EQ(out.size, crc_input_bits(f).size + kCrcBits);
  }
  const std::uint8_t bad[] = {0, 0, 0, 0, 0, 0, 1};  // six dominant bits
  BitBuffer out;
  EXPECT_FALSE(destuff(bad, 7, out));
  const std::uint8_t good[] = {0, 0, 0, 0, 0, 1, 0};
  EXPECT_TRUE(destuff(good, 7, out));
  EXPECT_EQ(out.size, 6);
}

TEST(CanBits, ErrorFrameIsFlagAndDelimiter) {
  Frame e;
  e.kind = FrameKind::error;
  EXPECT_EQ(as_string(stuffed_bits(e)), "00000011111111");
  EXPECT_EQ(frame_bits(e), 14);
  EXPECT_EQ(frame_bits_with_intermission(e), 17);
  EXPECT_EQ(stuff_bit_count(e), 0);
  EXPECT_EQ(crc_input_bits(e).size, 0);
}

TEST(CanBits, LongestFrameFitsTheBuffer) {
  // Extended, 8 bytes, content with maximal stuffing: still well inside kMaxWireBits.
  const Frame f = make_data(0x000C3C3C, {0x3C, 0x3C, 0x3F, 0xFF, 0x0F, 0x0F, 0x0F, 0x0F}, true);
  EXPECT_EQ(stuff_bit_count(f), 27);
  EXPECT_EQ(stuffed_bits(f, Intermission::included).size, 158);
  EXPECT_LE(158, kMaxWireBits);
}

}  // namespace
}  // namespace omnitwin::can
