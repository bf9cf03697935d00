// Tests bus_emulators/tml/tml_can: TMLCAN and TechCAN against every CAN golden vector of
// facts/tml.md in both directions (encode gives the frame byte for byte; decoding the frame
// gives the message back), the TechCAN COB-ID ranges and packed layouts (TakeData, PVT,
// TakeData2/PONG), and the status codes for frames that are not valid TML (CANopen COB-IDs,
// wrong identifier format, remote frames, bad lengths, out-of-range axes and groups).
#include "bus_emulators/tml/tml_can.hpp"

#include <gtest/gtest.h>

#include <array>

namespace omnitwin::tml {
namespace {

Message msg(std::uint16_t id, std::uint16_t opcode, std::initializer_list<std::uint16_t> words) {
  Message m;
  m.id_code = id, m.opcode = opcode;
  for (auto w : words) m.data[m.count++] = w;
  return m;
}

void expect_tmlcan(const Message& m, std::uint32_t id, std::initializer_list<std::uint8_t> data) {
  const can::Frame want = can::make_data(id, data, true);
  can::Frame f;
  ASSERT_EQ(encode_tmlcan(m, f), CanStatus::ok);
  EXPECT_EQ(f, want) << can::to_string(f);
  Message back;
  ASSERT_EQ(decode_tmlcan(want, back), CanStatus::ok);
  EXPECT_EQ(back, m);
}

// Encodes m to exactly (id, data); decodes that frame to `kind` and the message (with the
// destination ID code only where TechCAN carries it).
void expect_techcan(const Message& m, std::uint32_t id, std::initializer_list<std::uint8_t> data, TechCanKind kind) {
  const can::Frame want = can::make_data(id, data);
  can::Frame f;
  ASSERT_EQ(encode_techcan(m, f), CanStatus::ok);
  EXPECT_EQ(f, want) << can::to_string(f);
  TechCanMessage back;
  ASSERT_EQ(decode_techcan(want, back), CanStatus::ok);
  EXPECT_EQ(back.kind, kind);
  Message expected = m;
  if (!back.destination_known) expected.id_code = 0;
  EXPECT_EQ(back.message, expected) << to_string(back.message);
}

// ---- TMLCAN ------------------------------------------------------------------------------------

TEST(TmlCan, GoldenKppToAxis5) {
  EXPECT_EQ(tmlcan_identifier(axis_id_code(5), 0x205E), 0x0400A05Eu);
  expect_tmlcan(msg(0x0050, 0x205E, {0x1234}), 0x0400A05E, {0x34, 0x12});
}

TEST(TmlCan, GoldenGiveMeData2ToGroup1) {
  expect_tmlcan(give_me_data2(group_id_code(1), axis_id_code(3), 0x022A, false), 0x16602004, {0x30, 0x00, 0x2A, 0x02});
}

TEST(TmlCan, GoldenTakeData2FromAxes5And7) {
  expect_tmlcan(take_data2(axis_id_code(3), 5, 0x022A, 2, false), 0x1A806005, {0x2A, 0x02, 0x02, 0x00});
  expect_tmlcan(take_data2(axis_id_code(3), 7, 0x022A, 1, false), 0x1A806007, {0x2A, 0x02, 0x01, 0x00});
  // Both answer the same group request: the lower axis wins arbitration.
  EXPECT_LT(tmlcan_identifier(0x0030, 0xD405), tmlcan_identifier(0x0030, 0xD407));
}

TEST(TmlCan, GoldenTakeData2ToHost255) {
  expect_tmlcan(take_data2(master_id(255), 1, 0x090E, 0x02018400, true), 0x1A9FE301,
                {0x0E, 0x09, 0x00, 0x84, 0x01, 0x02});
}

TEST(TmlCan, FourWordsFillEightBytes) {
  expect_tmlcan(msg(0x1FF1, 0xFFFF, {0x0102, 0x0304, 0x0506, 0x0708}), 0x1FFFE3FF,
                {0x02, 0x01, 0x04, 0x03, 0x06, 0x05, 0x08, 0x07});
  can::Frame f;
  EXPECT_EQ(encode_tmlcan(msg(0x2000, 0x205E, {}), f), CanStatus::bad_identifier);
}

TEST(TmlCan, RejectsFramesThatAreNotTml) {
  Message m;
  EXPECT_EQ(decode_tmlcan(can::make_data(0x125, {0x5E, 0x20}), m), CanStatus::wrong_format);
  EXPECT_EQ(decode_tmlcan(can::make_remote(0x0400A05E, 2, true), m), CanStatus::not_data_frame);
  EXPECT_EQ(decode_tmlcan(can::make_data(0x0400A45E, {0x34, 0x12}, true), m), CanStatus::bad_identifier);  // bit 10
  EXPECT_EQ(decode_tmlcan(can::make_data(0x0400A05E, {0x34}, true), m), CanStatus::bad_length);
  // An opcode outside the seed's set is still a message.
  ASSERT_EQ(decode_tmlcan(can::make_data(0x1234A123, {1, 0}, true), m), CanStatus::ok);
  EXPECT_EQ(classify(m).kind, Kind::generic);
}

// ---- TechCAN -----------------------------------------------------------------------------------

TEST(TechCan, GoldenKppToAxis5) {
  expect_techcan(msg(0x0050, 0x205E, {0x1234}), 0x125, {0x5E, 0x20, 0x34, 0x12}, TechCanKind::normal);
}

TEST(TechCan, GoldenGiveMeDataFromHost3) {
  expect_techcan(give_me_data(axis_id_code(5), axis_id_code(3), 0x022A, false), 0x125,
                 {0x04, 0xB0, 0x30, 0x00, 0x2A, 0x02}, TechCanKind::normal);
}

TEST(TechCan, GoldenTakeDataPacksTenBytesIntoSix) {
  // Opcode B404 (not the seed's "D404"): only B4xx has 0x2D as its 6 MSB.
  const Message answer = take_data(axis_id_code(3), axis_id_code(5), 0x022A, 2, false);
  expect_techcan(answer, 0x165, {0x04, 0x28, 0x2A, 0x02, 0x02, 0x00}, TechCanKind::take_data);
  TechCanMessage back;
  ASSERT_EQ(decode_techcan(can::make_data(0x165, {0x04, 0x28, 0x2A, 0x02, 0x02, 0x00}), back), CanStatus::ok);
  EXPECT_FALSE(back.destination_known);
  EXPECT_EQ(back.cob_number, 5);
  EXPECT_EQ(classify(back.message).sender, 0x0050);
  // 32-bit, from a sender with the HOST bit (bit 2 of byte 1); opcode[9:8] of B4xx are 0.
  expect_techcan(take_data(axis_id_code(3), axis_id_code(31, true), 0x090E, 0x02018400, true), 0x17F,
                 {0x05, 0xFC, 0x0E, 0x09, 0x00, 0x84, 0x01, 0x02}, TechCanKind::take_data);
}

TEST(TechCan, GoldenPvtPoint) {
  const Message m = pvt(axis_id_code(5), PvtPoint{-1000, -10 * 65536, 500, 0});
  expect_techcan(m, 0x045, {0x18, 0xFC, 0x00, 0xFF, 0xF6, 0xFF, 0xF4, 0x01}, TechCanKind::pvt);
  // The counter rides in byte 7 above time bit 8.
  const Message counted = pvt(axis_id_code(5), PvtPoint{1, 0, 0x100, 0x55});
  can::Frame f;
  ASSERT_EQ(encode_techcan(counted, f), CanStatus::ok);
  EXPECT_EQ(f.data[7], 0x55 << 1 | 1);
  TechCanMessage back;
  ASSERT_EQ(decode_techcan(f, back), CanStatus::ok);
  EXPECT_EQ(pvt_point(back.message)->counter, 0x55);
}

TEST(TechCan, GoldenSyncAndSetMasterTime) {
  expect_techcan(sync_message(), 0x020, {}, TechCanKind::sync);
  expect_techcan(set_master_time(0x0246C46F), 0x200, {0x01, 0x14, 0x6F, 0xC4, 0x46, 0x02}, TechCanKind::broadcast);
}

// Found by fuzz.tml_decode: a broadcast frame carrying the SYNC opcode with data words must
// re-encode as that broadcast, not as the data-less synchronisation frame 0x020.
TEST(TechCan, SyncOpcodeWithDataStaysABroadcast) {
  TechCanMessage t;
  ASSERT_EQ(decode_techcan(can::make_data(0x200, {0x00, 0x10, 0x24, 0xEB, 0x00, 0x00}), t), CanStatus::ok);
  can::Frame g;
  ASSERT_EQ(encode_techcan(t.message, g), CanStatus::ok);
  EXPECT_EQ(g, can::make_data(0x200, {0x00, 0x10, 0x24, 0xEB, 0x00, 0x00}));
  ASSERT_EQ(encode_techcan(sync_message(), g), CanStatus::ok);
  EXPECT_EQ(g, can::make_data(0x020, {}));
}

// Found by fuzz.tml_decode (fuzz/corpus/tml_decode/techcan-takedata-sender-0x2124): a TakeData
// whose sender word is no axis ID code (0x2124: bits beyond the axis and HOST bit) cannot be
// packed into the TakeData layout, which would send it back as 0x0120; it is refused as a bad
// identifier, like a sender axis TechCAN cannot address.
TEST(TechCan, ATakeDataSenderThePackedLayoutCannotCarryIsRefused) {
  TechCanMessage t;
  ASSERT_EQ(decode_techcan(can::make_data(0x001, {0x04, 0xB4, 0x24, 0x21}), t), CanStatus::ok);
  can::Frame g;
  EXPECT_EQ(encode_techcan(t.message, g), CanStatus::bad_identifier);
  Message odd = take_data(axis_id_code(3), axis_id_code(5), 0x022A, 2, false);
  odd.data[0] = 0x2124;
  EXPECT_EQ(encode_techcan(odd, g), CanStatus::bad_identifier);
  odd.data[0] = axis_id_code(5, true);  // the HOST bit is carried
  EXPECT_EQ(encode_techcan(odd, g), CanStatus::ok);
}

TEST(TechCan, GoldenTakeData2WithMer) {
  // The seed prints byte 3 as 40h; MER = 0x0008 makes it 08h.
  expect_techcan(take_data2(master_id(3), 2, 0x08FC, 0x0008, false), 0x102, {0x00, 0xFC, 0x08, 0x08, 0x00},
                 TechCanKind::take_data2);
  expect_techcan(take_data2(master_id(3), 1, 0x090E, 0x02018400, true), 0x101,
                 {0x80, 0x0E, 0x09, 0x00, 0x84, 0x01, 0x02}, TechCanKind::take_data2);
}

TEST(TechCan, PongHasThePBit) {
  const std::array<std::uint16_t, 2> words{0x0001, 0x0203};
  can::Frame f;
  ASSERT_EQ(encode_techcan_pong(4, words, f), CanStatus::ok);
  EXPECT_EQ(f, can::make_data(0x104, {0x40, 0x01, 0x00, 0x03, 0x02}));
  TechCanMessage back;
  ASSERT_EQ(decode_techcan(f, back), CanStatus::ok);
  EXPECT_EQ(back.kind, TechCanKind::pong);
  EXPECT_EQ(back.message.count, 2);
  EXPECT_EQ(back.message.data[1], 0x0203);
  EXPECT_EQ(encode_techcan_pong(32, words, f), CanStatus::axis_out_of_range);
}

TEST(TechCan, GroupHostAndBroadcastRanges) {
  expect_techcan(msg(group_id_code(0x1F), 0x205E, {1}), 0x01F, {0x5E, 0x20, 0x01, 0x00}, TechCanKind::group);
  expect_techcan(msg(axis_id_code(7, true), 0x1234, {}), 0x147, {0x34, 0x12}, TechCanKind::host);
  expect_techcan(msg(group_id_code(0), 0x205E, {9}), 0x200, {0x5E, 0x20, 0x09, 0x00}, TechCanKind::broadcast);
  can::Frame f;
  EXPECT_EQ(encode_techcan(msg(group_id_code(0x20), 0x205E, {1}), f), CanStatus::group_out_of_range);
  EXPECT_EQ(encode_techcan(msg(axis_id_code(32), 0x205E, {1}), f), CanStatus::axis_out_of_range);
  EXPECT_EQ(encode_techcan(msg(axis_id_code(0), 0x205E, {1}), f), CanStatus::axis_out_of_range);
  EXPECT_EQ(encode_techcan(msg(axis_id_code(1), 0x205E, {1, 2, 3, 4}), f), CanStatus::too_many_words);
  EXPECT_EQ(encode_techcan(take_data(axis_id_code(3), axis_id_code(40), 0x022A, 2, false), f),
            CanStatus::axis_out_of_range);
}

TEST(TechCan, CanopenAndOtherFramesAreNotTechCan) {
  TechCanMessage m;
  for (const std::uint32_t id : {0x000u, 0x021u, 0x060u, 0x080u, 0x081u, 0x0FFu, 0x100u, 0x120u, 0x181u, 0x201u,
                                 0x581u, 0x601u, 0x701u, 0x7FFu}) {
    EXPECT_EQ(decode_techcan(can::make_data(id, {0, 0}), m), CanStatus::unknown_cob_id) << std::hex << id;
  }
  EXPECT_EQ(decode_techcan(can::make_data(0x125, {0x5E, 0x20}, true), m), CanStatus::wrong_format);
  EXPECT_EQ(decode_techcan(can::make_remote(0x125, 2), m), CanStatus::not_data_frame);
  EXPECT_EQ(decode_techcan(can::make_data(0x125, {0x5E}), m), CanStatus::bad_length);
  EXPECT_EQ(decode_techcan(can::make_data(0x020, {1}), m), CanStatus::bad_length);
  EXPECT_EQ(decode_techcan(can::make_data(0x045, {1, 2, 3}), m), CanStatus::bad_length);
  EXPECT_EQ(decode_techcan(can::make_data(0x102, {0, 1}), m), CanStatus::bad_length);
  // An unknown opcode in a normal frame is a generic message.
  ASSERT_EQ(decode_techcan(can::make_data(0x121, {0x77, 0x77, 1, 0}), m), CanStatus::ok);
  EXPECT_EQ(classify(m.message).kind, Kind::generic);
}

}  // namespace
}  // namespace omnitwin::tml
