// Tests controller/ethercat/ec_sdo: the master's CoE SDO client frames, byte for byte —
// upload/download requests (expedited, normal, segmented), digesting expedited/normal/
// segmented replies, abort codes, mailbox error replies, and replies that belong to nobody.
#include "controller/ethercat/ec_sdo.hpp"

#include <gtest/gtest.h>

#include <vector>

using namespace omnitwin::controller::ethercat;
using Bytes = std::vector<std::uint8_t>;

namespace {
Bytes request(SdoTransfer& x, std::size_t mbx, std::uint8_t counter, std::size_t* used = nullptr) {
  Bytes out(mbx, 0xEE);
  const std::size_t n = x.next_request(out, counter);
  if (used) *used = n;
  return out;
}
// A CoE reply: mailbox header + CoE header (service) + the SDO bytes.
Bytes reply(std::uint8_t service, Bytes sdo, std::uint8_t counter = 1) {
  Bytes m(6, 0);
  const auto len = static_cast<std::uint16_t>(2 + sdo.size());
  m[0] = static_cast<std::uint8_t>(len);
  m[1] = static_cast<std::uint8_t>(len >> 8);
  m[5] = static_cast<std::uint8_t>(0x03 | (counter << 4));
  m.push_back(0x00);
  m.push_back(static_cast<std::uint8_t>(service << 4));
  m.insert(m.end(), sdo.begin(), sdo.end());
  m.resize(128, 0);
  return m;
}
// An upload of 0x1008 whose initiate reply announced 20 bytes in segments, the first segment
// request sent (toggle 0).
void begin_segments_of_20(SdoTransfer& x) {
  x.begin(SdoRequest{true, 0x1008, 0, {}}, 32);
  request(x, 32, 1);
  x.on_reply(reply(3, {0x41, 0x08, 0x10, 0x00, 20, 0, 0, 0}));
  request(x, 32, 2);
}
}  // namespace

TEST(EcSdo, UploadRequestGoldenBytes) {
  SdoTransfer x;
  x.begin(SdoRequest{true, 0x6041, 0, {}}, 128);
  std::size_t used = 0;
  const Bytes out = request(x, 128, 1, &used);
  EXPECT_EQ(used, 16u);
  const Bytes golden{0x0A, 0x00, 0x00, 0x00, 0x00, 0x13, 0x00, 0x20, 0x40, 0x41, 0x60, 0x00, 0x00, 0x00, 0x00, 0x00};
  EXPECT_EQ(Bytes(out.begin(), out.begin() + 16), golden);
  EXPECT_EQ(out[16], 0x00);  // rest of the mailbox zeroed
  EXPECT_EQ(out[127], 0x00);
}

TEST(EcSdo, ExpeditedDownloadGoldenBytesAndAck) {
  SdoTransfer x;
  x.begin(SdoRequest{false, 0x6060, 0, {9}}, 128);
  const Bytes out = request(x, 128, 3);
  const Bytes golden{0x0A, 0x00, 0x00, 0x00, 0x00, 0x33, 0x00, 0x20, 0x2F, 0x60, 0x60, 0x00, 0x09, 0x00, 0x00, 0x00};
  EXPECT_EQ(Bytes(out.begin(), out.begin() + 16), golden);
  EXPECT_EQ(x.on_reply(reply(3, {0x60, 0x60, 0x60, 0x00, 0, 0, 0, 0})), SdoTransfer::ReplyOutcome::finished);
  EXPECT_EQ(x.status(), SdoStatus::done);
}

TEST(EcSdo, ExpeditedUploadReplySizes) {
  SdoTransfer x;
  x.begin(SdoRequest{true, 0x6041, 0, {}}, 128);
  request(x, 128, 1);
  EXPECT_EQ(x.on_reply(reply(3, {0x4B, 0x41, 0x60, 0x00, 0x37, 0x02, 0xAA, 0xBB})), SdoTransfer::ReplyOutcome::finished);
  EXPECT_EQ(x.status(), SdoStatus::done);
  EXPECT_EQ(x.data(), (Bytes{0x37, 0x02}));
  EXPECT_EQ(bytes_value(x.data(), false), 0x0237);
}

TEST(EcSdo, ReplyForAnotherObjectIsIgnored) {
  SdoTransfer x;
  x.begin(SdoRequest{true, 0x6041, 0, {}}, 128);
  request(x, 128, 1);
  EXPECT_EQ(x.on_reply(reply(3, {0x4B, 0x40, 0x60, 0x00, 1, 0, 0, 0})), SdoTransfer::ReplyOutcome::ignored);
  EXPECT_EQ(x.on_reply(reply(1, {0x00, 0x81, 0x10, 0, 0, 0, 0, 0})), SdoTransfer::ReplyOutcome::ignored);  // emergency
  EXPECT_EQ(x.status(), SdoStatus::pending);
}

TEST(EcSdo, AbortCodeReported) {
  SdoTransfer x;
  x.begin(SdoRequest{true, 0x2345, 1, {}}, 128);
  request(x, 128, 1);
  EXPECT_EQ(x.on_reply(reply(2, {0x80, 0x45, 0x23, 0x01, 0x00, 0x00, 0x02, 0x06})), SdoTransfer::ReplyOutcome::finished);
  EXPECT_EQ(x.status(), SdoStatus::aborted);
  EXPECT_EQ(x.abort_code(), 0x06020000u);
  EXPECT_STREQ(sdo_abort_text(x.abort_code()), "object does not exist in the object dictionary");
}

TEST(EcSdo, MailboxErrorReply) {
  SdoTransfer x;
  x.begin(SdoRequest{true, 0x1000, 0, {}}, 128);
  request(x, 128, 1);
  Bytes m{0x04, 0x00, 0x00, 0x00, 0x00, 0x00, 0x01, 0x00, 0x02, 0x00};
  m.resize(128, 0);
  EXPECT_EQ(x.on_reply(m), SdoTransfer::ReplyOutcome::finished);
  EXPECT_EQ(x.status(), SdoStatus::mailbox_error);
  EXPECT_EQ(x.abort_code(), 2u);
}

TEST(EcSdo, NormalUploadWithDataInInitiate) {
  SdoTransfer x;
  x.begin(SdoRequest{true, 0x1008, 0, {}}, 128);
  request(x, 128, 1);
  EXPECT_EQ(x.on_reply(reply(3, {0x41, 0x08, 0x10, 0x00, 0x05, 0, 0, 0, 'd', 'r', 'i', 'v', 'e'})),
            SdoTransfer::ReplyOutcome::finished);
  EXPECT_EQ(x.status(), SdoStatus::done);
  EXPECT_EQ(std::string(x.data().begin(), x.data().end()), "drive");
}

TEST(EcSdo, SegmentedUpload) {
  SdoTransfer x;
  x.begin(SdoRequest{true, 0x1008, 0, {}}, 32);
  request(x, 32, 1);
  EXPECT_EQ(x.on_reply(reply(3, {0x41, 0x08, 0x10, 0x00, 10, 0, 0, 0})), SdoTransfer::ReplyOutcome::progress);
  Bytes r = request(x, 32, 2);
  EXPECT_EQ(r[8], 0x60);  // upload segment request, toggle 0
  EXPECT_EQ(r[5], 0x23);
  EXPECT_EQ(x.on_reply(reply(3, {0x00, '0', '1', '2', '3', '4', '5', '6'})), SdoTransfer::ReplyOutcome::progress);
  r = request(x, 32, 3);
  EXPECT_EQ(r[8], 0x70);  // toggle 1
  // last segment: 3 bytes (n = 4 unused), toggle 1, c = 1
  EXPECT_EQ(x.on_reply(reply(3, {0x19, '7', '8', '9', 0, 0, 0, 0})), SdoTransfer::ReplyOutcome::finished);
  EXPECT_EQ(x.status(), SdoStatus::done);
  EXPECT_EQ(std::string(x.data().begin(), x.data().end()), "0123456789");
}

TEST(EcSdo, SegmentedUploadToggleErrorAborts) {
  SdoTransfer x;
  begin_segments_of_20(x);
  EXPECT_EQ(x.on_reply(reply(3, {0x10, 'a', 'b', 'c', 'd', 'e', 'f', 'g'})), SdoTransfer::ReplyOutcome::finished);
  EXPECT_EQ(x.status(), SdoStatus::aborted);
  EXPECT_EQ(x.abort_code(), 0x05030000u);
}

// A segment reply shorter than the CoE header and 8 SDO bytes cannot hold the 7 bytes its
// command says: aborted (length does not match), not read from past the mailbox's length.
TEST(EcSdo, SegmentedUploadWithATooShortSegmentAborts) {
  SdoTransfer x;
  begin_segments_of_20(x);
  EXPECT_EQ(x.on_reply(reply(3, {0x00})), SdoTransfer::ReplyOutcome::finished);
  EXPECT_EQ(x.status(), SdoStatus::aborted);
  EXPECT_EQ(x.abort_code(), 0x06070010u);
  EXPECT_TRUE(x.data().empty());
}

TEST(EcSdo, SegmentedDownload) {
  Bytes data(40);
  for (std::size_t i = 0; i < data.size(); ++i) data[i] = static_cast<std::uint8_t>(i);
  SdoTransfer x;
  x.begin(SdoRequest{false, 0x2000, 0, data}, 32);
  std::size_t used = 0;
  Bytes r = request(x, 32, 1, &used);
  EXPECT_EQ(used, 32u);           // header 6 + CoE 26
  EXPECT_EQ(r[0], 26);
  EXPECT_EQ(r[8], 0x21);          // normal initiate, size indicated
  EXPECT_EQ(r[12], 40);           // complete size
  EXPECT_EQ(r[16], 0);            // first data byte
  EXPECT_EQ(r[31], 15);           // 16 bytes carried
  EXPECT_EQ(x.on_reply(reply(3, {0x60, 0x00, 0x20, 0x00, 0, 0, 0, 0})), SdoTransfer::ReplyOutcome::progress);
  r = request(x, 32, 2, &used);
  EXPECT_EQ(r[8], 0x00);          // segment, toggle 0, more follow
  EXPECT_EQ(r[9], 16);            // continues at byte 16
  EXPECT_EQ(r[0], 26);            // 3 + 23 bytes
  EXPECT_EQ(x.on_reply(reply(3, {0x20, 0, 0, 0, 0, 0, 0, 0})), SdoTransfer::ReplyOutcome::progress);
  r = request(x, 32, 3, &used);
  EXPECT_EQ(r[8], 0x1D);          // toggle 1, 6 unused bytes, last
  EXPECT_EQ(r[9], 39);
  EXPECT_EQ(r[0], 10);
  EXPECT_EQ(x.on_reply(reply(3, {0x30, 0, 0, 0, 0, 0, 0, 0})), SdoTransfer::ReplyOutcome::finished);
  EXPECT_EQ(x.status(), SdoStatus::done);
}

TEST(EcSdo, ValueBytesRoundTrip) {
  EXPECT_EQ(value_bytes(-2, 2), (Bytes{0xFE, 0xFF}));
  EXPECT_EQ(bytes_value(Bytes{0xFE, 0xFF}, true), -2);
  EXPECT_EQ(bytes_value(Bytes{0xFE, 0xFF}, false), 0xFFFE);
  EXPECT_EQ(bytes_value(value_bytes(-123456, 4), true), -123456);
}
