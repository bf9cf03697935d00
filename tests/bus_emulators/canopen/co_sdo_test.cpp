// Tests bus_emulators/canopen/co_sdo: the SDO frame layer — byte-exact encodings of every
// service per CiA 301's layouts, decode round trips and their status codes, the 8-byte frame
// check, and the block transfer CRC-16 against the CRC-16/XMODEM check value.
#include "bus_emulators/canopen/co_sdo.hpp"

#include <gtest/gtest.h>

#include <string_view>
#include <vector>

namespace omnitwin::canopen::sdo {
namespace {

Payload bytes(std::initializer_list<std::uint8_t> b) {
  Payload p{};
  std::copy(b.begin(), b.end(), p.begin());
  return p;
}

TEST(SdoCrc, MatchesTheXmodemCheckValue) {
  constexpr std::string_view s = "123456789";
  const std::vector<std::uint8_t> v(s.begin(), s.end());
  EXPECT_EQ(crc16(v), 0x31C3);
  EXPECT_EQ(crc16({}), 0x0000);
  // Continuing over a split gives the same as one pass.
  const std::uint16_t part = crc16(std::span(v).first(4));
  EXPECT_EQ(crc16(std::span(v).subspan(4), part), 0x31C3);
  // One flipped bit changes it.
  auto w = v;
  w[5] ^= 0x01;
  EXPECT_NE(crc16(w), 0x31C3);
}

TEST(SdoFrame, PayloadNeedsAStandardDataFrameWithEightBytes) {
  Payload p{};
  can::Frame f = make_frame(0x605, bytes({0x40, 0x00, 0x10, 0x00}));
  EXPECT_EQ(f.id, 0x605u);
  EXPECT_EQ(f.dlc, 8);
  EXPECT_EQ(payload_of(f, p), FrameStatus::ok);
  EXPECT_EQ(p[0], 0x40);
  EXPECT_EQ(p[2], 0x10);
  f.dlc = 7;
  EXPECT_EQ(payload_of(f, p), FrameStatus::not_sdo);
  f.dlc = 8;
  f.kind = can::FrameKind::remote;
  EXPECT_EQ(payload_of(f, p), FrameStatus::not_sdo);
  f.kind = can::FrameKind::data;
  f.extended = true;
  EXPECT_EQ(payload_of(f, p), FrameStatus::not_sdo);
}

TEST(SdoFrame, ExpeditedDownloadLayouts) {
  Initiate m;
  m.index = 0x6040;
  m.sub = 0x00;
  m.expedited = m.sized = true;
  m.data = {0x0F, 0x00, 0xAA, 0xBB};
  m.size = 2;
  EXPECT_EQ(encode_initiate_download(m), bytes({0x2B, 0x40, 0x60, 0x00, 0x0F, 0x00, 0x00, 0x00}));
  m.size = 1;
  EXPECT_EQ(encode_initiate_download(m)[0], 0x2F);
  m.size = 3;
  EXPECT_EQ(encode_initiate_download(m)[0], 0x27);
  m.size = 4;
  EXPECT_EQ(encode_initiate_download(m), bytes({0x23, 0x40, 0x60, 0x00, 0x0F, 0x00, 0xAA, 0xBB}));
  m.sized = false;
  EXPECT_EQ(encode_initiate_download(m)[0], 0x22);
  // Decoding gives the size back from n.
  Initiate d;
  ASSERT_EQ(decode_initiate(bytes({0x27, 0x00, 0x20, 0x03, 1, 2, 3, 9}), d), FrameStatus::ok);
  EXPECT_TRUE(d.expedited && d.sized);
  EXPECT_EQ(d.size, 3u);
  EXPECT_EQ(d.index, 0x2000);
  EXPECT_EQ(d.sub, 3);
  EXPECT_EQ(d.data[2], 3);
  ASSERT_EQ(decode_initiate(bytes({0x22, 0x00, 0x20, 0x03, 1, 2, 3, 4}), d), FrameStatus::ok);
  EXPECT_TRUE(d.expedited && !d.sized);
  EXPECT_EQ(d.size, 4u);
}

TEST(SdoFrame, SegmentedInitiatesCarryTheSize) {
  Initiate m;
  m.index = 0x1008;
  m.sized = true;
  m.size = 300;
  EXPECT_EQ(encode_initiate_download(m), bytes({0x21, 0x08, 0x10, 0x00, 0x2C, 0x01, 0x00, 0x00}));
  EXPECT_EQ(encode_initiate_upload_response(m), bytes({0x41, 0x08, 0x10, 0x00, 0x2C, 0x01, 0x00, 0x00}));
  m.sized = false;
  EXPECT_EQ(encode_initiate_download(m), bytes({0x20, 0x08, 0x10, 0x00, 0, 0, 0, 0}));
  Initiate d;
  ASSERT_EQ(decode_initiate(bytes({0x41, 0x08, 0x10, 0x00, 0x2C, 0x01, 0x00, 0x00}), d), FrameStatus::ok);
  EXPECT_FALSE(d.expedited);
  EXPECT_TRUE(d.sized);
  EXPECT_EQ(d.size, 300u);
  EXPECT_EQ(decode_initiate(bytes({0x60, 0x08, 0x10}), d), FrameStatus::wrong_command);
}

TEST(SdoFrame, UploadRequestAndDownloadResponse) {
  EXPECT_EQ(encode_initiate_upload({0x1018, 0x02}), bytes({0x40, 0x18, 0x10, 0x02, 0, 0, 0, 0}));
  EXPECT_EQ(encode_initiate_download_response({0x1018, 0x02}), bytes({0x60, 0x18, 0x10, 0x02, 0, 0, 0, 0}));
  const ObjectRef o = object_of(bytes({0x40, 0x34, 0x12, 0x07}));
  EXPECT_EQ(o.index, 0x1234);
  EXPECT_EQ(o.sub, 7);
}

TEST(SdoFrame, SegmentsAndTheirToggles) {
  Segment s;
  s.toggle = true;
  s.last = true;
  s.len = 3;
  s.data = {'a', 'b', 'c', 'x', 'x', 'x', 'x'};
  EXPECT_EQ(encode_segment(s), bytes({0x19, 'a', 'b', 'c', 0, 0, 0, 0}));  // t=1, n=4, c=1
  s.toggle = false;
  s.last = false;
  s.len = 7;
  EXPECT_EQ(encode_segment(s)[0], 0x00);
  Segment d;
  ASSERT_EQ(decode_segment(bytes({0x1B, 1, 2}), d), FrameStatus::ok);  // t=1, n=5, c=1
  EXPECT_TRUE(d.toggle && d.last);
  EXPECT_EQ(d.len, 2);
  EXPECT_EQ(decode_segment(bytes({0x60}), d), FrameStatus::wrong_command);
  EXPECT_EQ(encode_upload_segment_request(false)[0], 0x60);
  EXPECT_EQ(encode_upload_segment_request(true)[0], 0x70);
  EXPECT_EQ(encode_download_segment_response(false)[0], 0x20);
  EXPECT_EQ(encode_download_segment_response(true)[0], 0x30);
}

TEST(SdoFrame, AbortCarriesTheCodeLittleEndian) {
  const Payload p = encode_abort({0x6060, 0x00, SdoAbort::no_object});
  EXPECT_EQ(p, bytes({0x80, 0x60, 0x60, 0x00, 0x00, 0x00, 0x02, 0x06}));
  Abort a;
  ASSERT_EQ(decode_abort(bytes({0x80, 0x00, 0x20, 0x01, 0x04, 0x00, 0x04, 0x05}), a), FrameStatus::ok);
  EXPECT_EQ(a.index, 0x2000);
  EXPECT_EQ(a.sub, 1);
  EXPECT_EQ(a.code, abort_crc);
  EXPECT_EQ(decode_abort(bytes({0x60}), a), FrameStatus::wrong_command);
  EXPECT_STREQ(abort_text(abort_crc), "CRC error");
  EXPECT_STREQ(abort_text(abort_invalid_seqno), "invalid sequence number");
  EXPECT_EQ(static_cast<std::uint32_t>(abort_invalid_seqno), 0x05040003u);
}

TEST(SdoFrame, BlockDownloadServices) {
  BlockInitiate m;
  m.index = 0x1F50;
  m.sub = 1;
  m.crc = true;
  m.sized = true;
  m.size = 0x01020304;
  EXPECT_EQ(encode_block_download_initiate(m), bytes({0xC6, 0x50, 0x1F, 0x01, 0x04, 0x03, 0x02, 0x01}));
  m.blksize = 127;
  EXPECT_EQ(encode_block_download_initiate_response(m), bytes({0xA4, 0x50, 0x1F, 0x01, 127, 0, 0, 0}));
  BlockInitiate d;
  ASSERT_EQ(decode_block_download_initiate(bytes({0xC2, 0x50, 0x1F, 0x01, 10, 0, 0, 0}), d), FrameStatus::ok);
  EXPECT_FALSE(d.crc);
  EXPECT_TRUE(d.sized);
  EXPECT_EQ(d.size, 10u);
  EXPECT_EQ(decode_block_download_initiate(bytes({0xC1}), d), FrameStatus::wrong_command);  // that is an end
  ASSERT_EQ(decode_block_download_initiate_response(bytes({0xA4, 0x50, 0x1F, 0x01, 5}), d), FrameStatus::ok);
  EXPECT_TRUE(d.crc);
  EXPECT_EQ(d.blksize, 5);
  EXPECT_EQ(decode_block_download_initiate_response(bytes({0xA0, 0x50, 0x1F, 0x01, 0}), d), FrameStatus::bad_block_size);
  EXPECT_EQ(decode_block_download_initiate_response(bytes({0xA0, 0, 0, 0, 128}), d), FrameStatus::bad_block_size);
  EXPECT_EQ(encode_block_end({3, 0xBEEF}), bytes({0xCD, 0xEF, 0xBE, 0, 0, 0, 0, 0}));
  BlockEnd e;
  ASSERT_EQ(decode_block_end(bytes({0xD9, 0x34, 0x12}), e), FrameStatus::ok);  // n = 6
  EXPECT_EQ(e.unused, 6);
  EXPECT_EQ(e.crc, 0x1234);
  EXPECT_EQ(decode_block_end(bytes({0xC6}), e), FrameStatus::wrong_command);
  EXPECT_EQ(encode_block_end_response(), bytes({0xA1, 0, 0, 0, 0, 0, 0, 0}));
  EXPECT_TRUE(is_block_end_response(bytes({0xA1})));
  EXPECT_FALSE(is_block_end_response(bytes({0xA2})));
}

TEST(SdoFrame, BlockUploadServices) {
  BlockInitiate m;
  m.index = 0x2003;
  m.crc = true;
  m.blksize = 64;
  m.pst = 4;
  EXPECT_EQ(encode_block_upload_initiate(m), bytes({0xA4, 0x03, 0x20, 0x00, 64, 4, 0, 0}));
  m.sized = true;
  m.size = 300;
  EXPECT_EQ(encode_block_upload_initiate_response(m), bytes({0xC6, 0x03, 0x20, 0x00, 0x2C, 0x01, 0, 0}));
  EXPECT_EQ(encode_block_upload_start(), bytes({0xA3, 0, 0, 0, 0, 0, 0, 0}));
  BlockInitiate d;
  ASSERT_EQ(decode_block_upload_initiate(bytes({0xA0, 0x03, 0x20, 0x00, 20, 9}), d), FrameStatus::ok);
  EXPECT_FALSE(d.crc);
  EXPECT_EQ(d.blksize, 20);
  EXPECT_EQ(d.pst, 9);
  EXPECT_EQ(decode_block_upload_initiate(bytes({0xA4, 0x03, 0x20, 0x00, 0}), d), FrameStatus::bad_block_size);
  EXPECT_EQ(decode_block_upload_initiate(bytes({0xA3}), d), FrameStatus::wrong_command);
  ASSERT_EQ(decode_block_upload_initiate_response(bytes({0xC6, 0x03, 0x20, 0x00, 0x2C, 0x01}), d), FrameStatus::ok);
  EXPECT_TRUE(d.crc && d.sized);
  EXPECT_EQ(d.size, 300u);
}

TEST(SdoFrame, BlockSegmentsAndAcks) {
  BlockSegment s;
  s.seqno = 127;
  s.last = true;
  s.data = {1, 2, 3, 4, 5, 6, 7};
  EXPECT_EQ(encode_block_segment(s), bytes({0xFF, 1, 2, 3, 4, 5, 6, 7}));
  BlockSegment d;
  ASSERT_EQ(decode_block_segment(bytes({0x05, 9}), d), FrameStatus::ok);
  EXPECT_FALSE(d.last);
  EXPECT_EQ(d.seqno, 5);
  EXPECT_EQ(d.data[0], 9);
  EXPECT_EQ(decode_block_segment(bytes({0x80}), d), FrameStatus::bad_seqno);
  EXPECT_EQ(decode_block_segment(bytes({0x00}), d), FrameStatus::bad_seqno);
  EXPECT_EQ(encode_block_ack({12, 40}), bytes({0xA2, 12, 40, 0, 0, 0, 0, 0}));
  BlockAck a;
  ASSERT_EQ(decode_block_ack(bytes({0xA2, 3, 127}), a), FrameStatus::ok);
  EXPECT_EQ(a.ackseq, 3);
  EXPECT_EQ(a.blksize, 127);
  EXPECT_EQ(decode_block_ack(bytes({0xA2, 3, 0}), a), FrameStatus::bad_block_size);
  EXPECT_EQ(decode_block_ack(bytes({0xA1, 3, 5}), a), FrameStatus::wrong_command);
}

TEST(SdoFrame, UnusedBytesOfTheLastBlockSegment) {
  EXPECT_EQ(block_unused(0), 7);
  EXPECT_EQ(block_unused(1), 6);
  EXPECT_EQ(block_unused(7), 0);
  EXPECT_EQ(block_unused(8), 6);
  EXPECT_EQ(block_unused(300), 1);  // 43 segments = 301 bytes
}

}  // namespace
}  // namespace omnitwin::canopen::sdo
