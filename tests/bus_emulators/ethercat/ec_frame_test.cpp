// Tests bus_emulators/ethercat/ec_frame: the exact bytes PduBuilder writes (EtherCAT header,
// datagram header fields, M-bit chaining), parse_pdu's views and its errors for short,
// oversized, wrong-type, truncated and over-long chains, Datagram setters, the Ethernet header.
#include "bus_emulators/ethercat/ec_frame.hpp"

#include <gtest/gtest.h>

#include <vector>

namespace omnitwin::ethercat {
namespace {

TEST(EcFrame, BuildsGoldenBytesForOneDatagram) {
  std::array<std::uint8_t, 64> buf{};
  PduBuilder b(buf);
  const std::uint8_t data[2] = {0xAA, 0x55};
  EXPECT_EQ(b.add(Cmd::fpwr, 0x42, 0x1001, 0x0120, 2, data), 12);
  EXPECT_EQ(b.finish(), 16u);
  const std::uint8_t golden[16] = {
      0x0E, 0x10,              // length 14, type 1
      0x05, 0x42,              // FPWR, index
      0x01, 0x10, 0x20, 0x01,  // ADP 0x1001, ADO 0x0120
      0x02, 0x00,              // length 2, not circulating, last
      0x00, 0x00,              // IRQ
      0xAA, 0x55,              // data
      0x00, 0x00};             // WKC
  EXPECT_EQ(std::vector<std::uint8_t>(buf.begin(), buf.begin() + 16),
            std::vector<std::uint8_t>(golden, golden + 16));
}

TEST(EcFrame, ChainsDatagramsWithTheMoreBit) {
  std::array<std::uint8_t, 128> buf{};
  PduBuilder b(buf);
  ASSERT_EQ(b.add(Cmd::brd, 1, 0, 0x0000, 2), 12);
  ASSERT_EQ(b.add_logical(Cmd::lrw, 2, 0x00010000, 4), 12 + 2 + 2 + 10);
  ASSERT_EQ(b.add(Cmd::frmw, 3, 0x1000, 0x0910, 8), 26 + 4 + 2 + 10);
  const std::size_t n = b.finish();
  EXPECT_EQ(n, 2u + 14 + 16 + 20);
  EXPECT_EQ(b.datagrams(), 3u);
  // M bit set on the first two, clear on the last.
  EXPECT_EQ(buf[2 + 7], 0x80);
  EXPECT_EQ(buf[16 + 7], 0x80);
  EXPECT_EQ(buf[32 + 7], 0x00);
  EXPECT_EQ(get_u16(buf.data()), 0x1000 | (n - 2));

  PduView v;
  ASSERT_EQ(parse_pdu(std::span(buf.data(), n), v), PduError::ok);
  ASSERT_EQ(v.count, 3u);
  EXPECT_EQ(v.length, n);
  EXPECT_EQ(v.datagrams[0].cmd(), Cmd::brd);
  EXPECT_TRUE(v.datagrams[0].more());
  EXPECT_EQ(v.datagrams[1].cmd(), Cmd::lrw);
  EXPECT_EQ(v.datagrams[1].logical(), 0x00010000u);
  EXPECT_EQ(v.datagrams[1].adp(), 0x0000);
  EXPECT_EQ(v.datagrams[1].ado(), 0x0001);
  EXPECT_EQ(v.datagrams[1].length(), 4);
  EXPECT_EQ(v.datagrams[2].cmd(), Cmd::frmw);
  EXPECT_EQ(v.datagrams[2].index(), 3);
  EXPECT_EQ(v.datagrams[2].adp(), 0x1000);
  EXPECT_EQ(v.datagrams[2].ado(), 0x0910);
  EXPECT_FALSE(v.datagrams[2].more());
  EXPECT_EQ(v.datagrams[2].size(), 20u);
}

TEST(EcFrame, SettersWriteInPlace) {
  std::array<std::uint8_t, 32> buf{};
  PduBuilder b(buf);
  b.add(Cmd::aprd, 7, 0, 0x0130, 2);
  const std::size_t n = b.finish();
  PduView v;
  ASSERT_EQ(parse_pdu(std::span(buf.data(), n), v), PduError::ok);
  Datagram d = v.datagrams[0];
  d.set_adp(0xFFFF);
  d.set_wkc(3);
  d.set_irq(0x1234);
  d.set_circulating(true);
  EXPECT_EQ(get_u16(buf.data() + 4), 0xFFFF);
  EXPECT_EQ(get_u16(buf.data() + 14), 3);
  EXPECT_EQ(get_u16(buf.data() + 10), 0x1234);
  EXPECT_EQ(buf[9], 0x40);
  EXPECT_TRUE(d.circulating());
  EXPECT_EQ(d.length(), 2);  // the circulating bit is not part of the length
  d.set_circulating(false);
  EXPECT_EQ(buf[9], 0x00);
}

TEST(EcFrame, PaddingAfterTheDeclaredLengthIsAllowed) {
  std::array<std::uint8_t, kMinEthFrame> buf{};
  PduBuilder b(buf);
  b.add(Cmd::brd, 0, 0, 0, 2);
  const std::size_t n = b.finish();
  PduView v;
  EXPECT_EQ(parse_pdu(buf, v), PduError::ok);  // 46 bytes of padding after 16
  EXPECT_EQ(v.length, n);
  EXPECT_EQ(v.count, 1u);
}

TEST(EcFrame, RejectsShortWrongTypeAndOversized) {
  PduView v;
  std::array<std::uint8_t, 1> one{0x0C};
  EXPECT_EQ(parse_pdu(one, v), PduError::too_short);

  std::array<std::uint8_t, 32> buf{};
  PduBuilder b(buf);
  b.add(Cmd::brd, 0, 0, 0, 2);
  const std::size_t n = b.finish();
  auto pdu = std::span(buf.data(), n);

  auto bad = buf;
  put_u16(bad.data(), static_cast<std::uint16_t>((n - 2) | 0x4000));  // type 4
  EXPECT_EQ(parse_pdu(std::span(bad.data(), n), v), PduError::wrong_type);
  EXPECT_EQ(v.count, 0u);

  // Header declares more than the input holds.
  EXPECT_EQ(parse_pdu(pdu.first(n - 1), v), PduError::too_short);

  // Header length above what an Ethernet frame carries (1498).
  std::vector<std::uint8_t> big(2100, 0);
  put_u16(big.data(), 0x1000 | 0x7FF);
  EXPECT_EQ(parse_pdu(big, v), PduError::length_mismatch);
}

TEST(EcFrame, RejectsTruncatedDatagramsAndBrokenChains) {
  std::array<std::uint8_t, 64> buf{};
  PduBuilder b(buf);
  b.add(Cmd::brd, 0, 0, 0, 4);
  const std::size_t n = b.finish();  // 2 + 16
  PduView v;

  // A datagram length running past the header length.
  auto bad = buf;
  put_u16(bad.data() + 2 + 6, 5);
  EXPECT_EQ(parse_pdu(std::span(bad.data(), n), v), PduError::truncated_datagram);

  // M bit set on the last datagram: the chain runs past the end.
  bad = buf;
  put_u16(bad.data() + 2 + 6, 0x8004);
  EXPECT_EQ(parse_pdu(std::span(bad.data(), n), v), PduError::truncated_datagram);

  // Header length longer than the chain (garbage after the last datagram inside the PDU).
  bad = buf;
  put_u16(bad.data(), static_cast<std::uint16_t>(0x1000 | (n - 2 + 3)));
  EXPECT_EQ(parse_pdu(std::span(bad.data(), n + 3), v), PduError::length_mismatch);

  // Header length too small for even one datagram, or zero.
  bad = buf;
  put_u16(bad.data(), 0x1000 | 8);
  EXPECT_EQ(parse_pdu(std::span(bad.data(), n), v), PduError::truncated_datagram);
  put_u16(bad.data(), 0x1000);
  EXPECT_EQ(parse_pdu(std::span(bad.data(), n), v), PduError::truncated_datagram);
}

TEST(EcFrame, RejectsMoreThanMaxDatagrams) {
  std::array<std::uint8_t, kMaxPdu> buf{};
  // Build 65 zero-length datagrams by hand (the builder stops at 64).
  std::size_t pos = 2;
  for (int i = 0; i < 65; ++i) {
    buf[pos] = static_cast<std::uint8_t>(Cmd::nop);
    put_u16(buf.data() + pos + 6, i < 64 ? 0x8000 : 0);
    pos += 12;
  }
  put_u16(buf.data(), static_cast<std::uint16_t>(0x1000 | (pos - 2)));
  PduView v;
  EXPECT_EQ(parse_pdu(std::span(buf.data(), pos), v), PduError::too_many_datagrams);
  EXPECT_EQ(v.count, 0u);
}

TEST(EcFrame, BuilderStopsAtLimits) {
  std::array<std::uint8_t, 40> buf{};
  PduBuilder b(buf);
  EXPECT_EQ(b.room(), 40u - 2 - 12);
  EXPECT_EQ(b.add(Cmd::lrd, 0, 0, 0, 27), -1);  // one byte too many
  EXPECT_GE(b.add(Cmd::lrd, 0, 0, 0, 26), 0);
  EXPECT_EQ(b.room(), 0u);
  EXPECT_EQ(b.add(Cmd::lrd, 0, 0, 0, 0), -1);
  EXPECT_EQ(b.finish(), 40u);

  std::array<std::uint8_t, 3000> big{};
  PduBuilder c(big);  // only kMaxPdu used
  EXPECT_EQ(c.room(), kMaxPdu - 2 - 12);
  EXPECT_EQ(c.add(Cmd::lrd, 0, 0, 0, 0x800), -1);  // 11-bit length
  for (int i = 0; i < 64; ++i) ASSERT_GE(c.add(Cmd::nop, 0, 0, 0, 0), 0);
  EXPECT_EQ(c.add(Cmd::nop, 0, 0, 0, 0), -1);
  EXPECT_EQ(c.room(), 0u);
  c.reset();
  EXPECT_EQ(c.datagrams(), 0u);
  EXPECT_EQ(c.size(), 2u);
}

TEST(EcFrame, DataIsCopiedOrZeroed) {
  std::array<std::uint8_t, 64> buf;
  buf.fill(0xEE);
  PduBuilder b(buf);
  const std::uint32_t v = 0x11223344;
  const int o1 = b.add(Cmd::apwr, 0, 0, 0x0010, 4, &v);
  const int o2 = b.add(Cmd::aprd, 0, 0, 0x0010, 3);
  b.finish();
  EXPECT_EQ(get_u32(buf.data() + o1), 0x11223344u);
  EXPECT_EQ(buf[o2], 0);
  EXPECT_EQ(buf[o2 + 2], 0);
  EXPECT_EQ(get_u16(buf.data() + o2 + 3), 0);  // WKC
}

TEST(EcFrame, LittleEndianHelpersRoundTrip) {
  std::uint8_t b[8];
  put_u64(b, 0x0102030405060708ull);
  EXPECT_EQ(b[0], 0x08);
  EXPECT_EQ(b[7], 0x01);
  EXPECT_EQ(get_u64(b), 0x0102030405060708ull);
  EXPECT_EQ(get_u32(b + 4), 0x01020304u);
  EXPECT_EQ(get_u16(b), 0x0708);
}

TEST(EcFrame, EthernetHeaderAndNames) {
  std::uint8_t out[14];
  const Mac dst{0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF}, src{0x02, 0, 0, 0, 0, 1};
  EXPECT_EQ(write_eth_header(out, dst, src), 14u);
  EXPECT_EQ(out[0], 0xFF);
  EXPECT_EQ(out[6], 0x02);
  EXPECT_EQ(out[11], 0x01);
  EXPECT_EQ(out[12], 0x88);
  EXPECT_EQ(out[13], 0xA4);
  EXPECT_STREQ(to_string(Cmd::armw), "ARMW");
  EXPECT_STREQ(to_string(static_cast<Cmd>(0x20)), "?");
  EXPECT_STREQ(to_string(PduError::wrong_type), "wrong type");
  EXPECT_EQ(addressing(Cmd::frmw), CmdAddressing::node);
  EXPECT_TRUE(cmd_reads(Cmd::lrw));
  EXPECT_TRUE(cmd_writes(Cmd::lrw));
  EXPECT_FALSE(cmd_writes(Cmd::armw));
}

}  // namespace
}  // namespace omnitwin::ethercat
