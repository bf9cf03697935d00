// Tests bus_emulators/mechatrolink3/m3_frame: the frame layout byte for byte, the FCS as
// IEEE CRC-32 (its published check value), every kind of bad input refused with its own
// status (truncated, oversized, corrupted, reserved addresses and bits, unknown types, data
// lengths a type does not allow), every single-bit corruption caught, and the Ethernet
// encapsulation (station MACs, EtherType 0x88B5, padding to 60 bytes and back).
#include "bus_emulators/mechatrolink3/m3_frame.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cstring>
#include <string>
#include <vector>

namespace omnitwin::m3 {
namespace {

std::vector<std::uint8_t> encoded(const FrameSpec& f) {
  std::vector<std::uint8_t> out(kMaxFrame);
  out.resize(encode(f, out));
  return out;
}

std::array<std::uint8_t, 8> eight() { return {0, 1, 2, 3, 4, 5, 6, 7}; }

// Recomputes the FCS after a test edited header bytes on purpose.
void refresh_fcs(std::vector<std::uint8_t>& b) {
  const std::uint32_t c = fcs(std::span(b).first(b.size() - kFcsSize));
  for (int i = 0; i < 4; ++i) b[b.size() - 4 + i] = static_cast<std::uint8_t>(c >> (8 * i));
}

FrameStatus status_of(const std::vector<std::uint8_t>& b) {
  FrameView v;
  return decode(b, v);
}

TEST(M3Frame, FcsIsIeeeCrc32) {
  const std::string check = "123456789";
  EXPECT_EQ(fcs({reinterpret_cast<const std::uint8_t*>(check.data()), check.size()}), 0xCBF43926u);
}

TEST(M3Frame, EncodesTheLayoutByteForByte) {
  const auto data = eight();
  const auto b = encoded({.dst = 0x03, .src = kC1Master, .type = FrameType::cyclic_command, .sequence = 21,
                          .retry = true, .data = data});
  ASSERT_EQ(b.size(), 5u + 8u + 4u);
  EXPECT_EQ(b[0], 0x03);
  EXPECT_EQ(b[1], 0x01);
  EXPECT_EQ(b[2], 0x15) << "sequence 21 mod 16 = 5, retry bit 0x10";
  EXPECT_EQ(b[3], 0x02);
  EXPECT_EQ(b[4], 8);
  for (int i = 0; i < 8; ++i) EXPECT_EQ(b[5 + i], i);
  const std::uint32_t c = fcs(std::span(b).first(13));
  EXPECT_EQ(b[13] | (b[14] << 8) | (b[15] << 16) | (static_cast<std::uint32_t>(b[16]) << 24), c) << "little endian";
  FrameView v;
  ASSERT_EQ(decode(b, v), FrameStatus::ok);
  EXPECT_EQ(v.dst, 0x03);
  EXPECT_EQ(v.src, kC1Master);
  EXPECT_EQ(v.type, FrameType::cyclic_command);
  EXPECT_EQ(v.sequence(), 5);
  EXPECT_TRUE(v.retry());
  ASSERT_EQ(v.data.size(), 8u);
  EXPECT_EQ(v.data[7], 7);
}

TEST(M3Frame, DataLengthsFollowTheFrameType) {
  for (std::size_t n : {8u, 16u, 32u, 48u, 64u}) EXPECT_TRUE(data_length_allowed(FrameType::cyclic_response, n)) << n;
  for (std::size_t n : {0u, 4u, 12u, 40u, 65u}) EXPECT_FALSE(data_length_allowed(FrameType::cyclic_command, n)) << n;
  EXPECT_TRUE(data_length_allowed(FrameType::event_command, 64));
  EXPECT_FALSE(data_length_allowed(FrameType::event_response, 32)) << "event-driven data is fixed at 64 bytes";
  EXPECT_TRUE(data_length_allowed(FrameType::sync, 8));
  EXPECT_TRUE(data_length_allowed(FrameType::delay_request, 0));
  EXPECT_FALSE(data_length_allowed(FrameType::delay_reply, 8));
  EXPECT_TRUE(data_length_allowed(FrameType::cycle_notify, 16));
}

TEST(M3Frame, DecodeRefusesEachKindOfBadInput) {
  const auto data = eight();
  const auto good = encoded({.dst = 0x05, .type = FrameType::cyclic_command, .data = data});
  ASSERT_EQ(status_of(good), FrameStatus::ok);
  EXPECT_EQ(status_of({0x03, 0x01, 0x00, 0x02}), FrameStatus::truncated);
  EXPECT_EQ(status_of({good.begin(), good.end() - 1}), FrameStatus::truncated);
  auto longer = good;
  longer.push_back(0);
  EXPECT_EQ(status_of(longer), FrameStatus::oversized);
  EXPECT_EQ(status_of(std::vector<std::uint8_t>(kMaxFrame + 1, 0)), FrameStatus::oversized);
  auto flipped = good;
  flipped[7] ^= 0x40;
  EXPECT_EQ(status_of(flipped), FrameStatus::bad_fcs);
  // Header edits with a matching FCS: each is refused for what it is.
  auto edit = [&](std::size_t at, std::uint8_t value) {
    auto b = good;
    b[at] = value;
    refresh_fcs(b);
    return status_of(b);
  };
  EXPECT_EQ(edit(0, 0x00), FrameStatus::bad_address) << "00h is no station";
  EXPECT_EQ(edit(0, 0xF5), FrameStatus::bad_address) << "F0h-FEh are reserved";
  EXPECT_EQ(edit(1, kBroadcast), FrameStatus::bad_address) << "nobody sends as broadcast";
  EXPECT_EQ(edit(2, 0x20), FrameStatus::bad_control);
  EXPECT_EQ(edit(3, 0x7E), FrameStatus::unknown_type);
  EXPECT_EQ(edit(3, static_cast<std::uint8_t>(FrameType::event_command)), FrameStatus::bad_data_length);
  EXPECT_EQ(edit(0, kBroadcast), FrameStatus::ok) << "a broadcast destination is fine";
}

TEST(M3Frame, ADataLengthBeyondTheBytesIsTruncatedAndBeyond64IsRefused) {
  const auto data = eight();
  auto b = encoded({.dst = 0x05, .type = FrameType::cyclic_command, .data = data});
  b[4] = 16;  // says 16, carries 8: the "FCS" would be read from beyond the end
  EXPECT_EQ(status_of(b), FrameStatus::truncated);
  b[4] = 200;
  EXPECT_EQ(status_of(b), FrameStatus::bad_data_length);
}

// CRC-32 catches every single-bit error: no corrupted frame is ever taken as good.
TEST(M3Frame, EverySingleBitCorruptionIsCaught) {
  std::array<std::uint8_t, 48> data{};
  for (std::size_t i = 0; i < data.size(); ++i) data[i] = static_cast<std::uint8_t>(i * 37);
  const auto good = encoded({.dst = 0x10, .type = FrameType::cyclic_response, .sequence = 3, .data = data});
  for (std::size_t bit = 0; bit < good.size() * 8; ++bit) {
    auto b = good;
    b[bit / 8] ^= static_cast<std::uint8_t>(1u << (bit % 8));
    EXPECT_NE(status_of(b), FrameStatus::ok) << "bit " << bit;
  }
}

TEST(M3Frame, EncodeRefusesWhatIsNotAFrame) {
  std::vector<std::uint8_t> out(kMaxFrame);
  const std::array<std::uint8_t, 12> twelve{};
  const auto data = eight();
  EXPECT_EQ(encode({.dst = 0x03, .type = FrameType::cyclic_command, .data = twelve}, out), 0u);
  EXPECT_EQ(encode({.dst = 0x03, .src = kBroadcast, .type = FrameType::cyclic_command, .data = data}, out), 0u);
  EXPECT_EQ(encode({.dst = 0xF0, .type = FrameType::cyclic_command, .data = data}, out), 0u);
  std::vector<std::uint8_t> small(16);
  EXPECT_EQ(encode({.dst = 0x03, .type = FrameType::cyclic_command, .data = data}, small), 0u) << "needs 17 bytes";
  EXPECT_EQ(encode({.type = FrameType::delay_request, .sequence = 0, .retry = false, .data = {}}, out), kHeaderSize + kFcsSize);
}

TEST(M3Frame, AddressesAndTypeNames) {
  EXPECT_TRUE(is_slave_address(0x03));
  EXPECT_TRUE(is_slave_address(0xEF));
  EXPECT_FALSE(is_slave_address(0x02));
  EXPECT_FALSE(is_slave_address(0xF0));
  EXPECT_TRUE(is_station_address(kC2Master));
  EXPECT_STREQ(to_string(FrameType::cyclic_command), "CMD");
  EXPECT_STREQ(to_string(static_cast<FrameType>(0x99)), "?");
  EXPECT_FALSE(is_known(static_cast<FrameType>(0x99)));
  EXPECT_STREQ(to_string(FrameStatus::bad_fcs), "bad FCS");
}

TEST(M3Frame, EthernetCarriesTheFrameWithStationMacsAndPadding) {
  const auto b = encoded({.dst = 0x07, .type = FrameType::delay_request, .sequence = 0, .retry = false, .data = {}});
  std::vector<std::uint8_t> eth(128);
  const std::size_t n = encapsulate(b, eth);
  ASSERT_EQ(n, kMinEthFrame) << "9 bytes padded to the Ethernet minimum";
  eth.resize(n);
  EXPECT_EQ(std::vector<std::uint8_t>(eth.begin(), eth.begin() + 6), (std::vector<std::uint8_t>{2, 0x4D, 0x33, 0, 0, 7}));
  EXPECT_EQ(std::vector<std::uint8_t>(eth.begin() + 6, eth.begin() + 12), (std::vector<std::uint8_t>{2, 0x4D, 0x33, 0, 0, 1}));
  EXPECT_EQ(eth[12], 0x88);
  EXPECT_EQ(eth[13], 0xB5);
  EXPECT_TRUE(std::equal(b.begin(), b.end(), eth.begin() + 14));
  FrameView v;
  ASSERT_EQ(decapsulate(eth, v), FrameStatus::ok);
  EXPECT_EQ(v.dst, 0x07);
  EXPECT_EQ(v.type, FrameType::delay_request);
  // A capture that kept the Ethernet FCS: 64 bytes, still this frame.
  auto with_fcs = eth;
  with_fcs.insert(with_fcs.end(), {0xDE, 0xAD, 0xBE, 0xEF});
  EXPECT_EQ(decapsulate(with_fcs, v), FrameStatus::ok);
  with_fcs.push_back(0);
  EXPECT_EQ(decapsulate(with_fcs, v), FrameStatus::oversized);
  auto other = eth;
  other[13] = 0xA4;  // EtherCAT
  EXPECT_EQ(decapsulate(other, v), FrameStatus::not_m3);
  EXPECT_EQ(decapsulate(std::span(eth).first(10), v), FrameStatus::truncated);
}

TEST(M3Frame, TheLargestFrameNeedsNoPaddingAndBroadcastUsesTheBroadcastMac) {
  std::array<std::uint8_t, 64> data{};
  const auto b = encoded({.dst = kBroadcast, .type = FrameType::event_command, .data = data});
  ASSERT_EQ(b.size(), kMaxFrame);
  std::vector<std::uint8_t> eth(128);
  EXPECT_EQ(encapsulate(b, eth), kEthHeaderSize + kMaxFrame);
  EXPECT_EQ(eth[0], 0xFF);
  EXPECT_EQ(eth[5], 0xFF);
  std::vector<std::uint8_t> small(kEthHeaderSize + kMaxFrame - 1);
  EXPECT_EQ(encapsulate(b, small), 0u);
  auto bad = b;
  bad[6] ^= 1;
  EXPECT_EQ(encapsulate(bad, eth), 0u) << "a corrupted frame is not wrapped";
}

}  // namespace
}  // namespace omnitwin::m3
