// Tests bus_emulators/tml/tml_message: ID codes, the seed's opcodes and the assignment opcode
// family, builders and the classifier (each golden-vector message of facts/tml.md built and
// classified back), PVT word packing, the symbol table, the Binary Code Viewer text parser, and
// that unknown opcodes classify as generic instead of failing.
#include "bus_emulators/tml/tml_message.hpp"

#include <gtest/gtest.h>

namespace omnitwin::tml {
namespace {

Message msg(std::uint16_t id, std::uint16_t opcode, std::initializer_list<std::uint16_t> words) {
  Message m;
  m.id_code = id, m.opcode = opcode;
  for (auto w : words) m.data[m.count++] = w;
  return m;
}

TEST(TmlIdCode, BitsFollowChapter2) {
  EXPECT_EQ(axis_id_code(255), 0x0FF0);
  EXPECT_EQ(host_id_code(255), 0x0FF1);
  EXPECT_EQ(axis_id_code(1), 0x0010);
  EXPECT_EQ(axis_id_code(3), 0x0030);
  EXPECT_EQ(group_id_code(group_mask(1)), 0x1010);
  EXPECT_EQ(group_id_code(0), 0x1000);
  EXPECT_EQ(group_mask(8), 0x80);
  EXPECT_EQ(group_mask(0), 0);
  EXPECT_EQ(master_id(255), 0x0FF1);  // 16 * 255 + 1 = 4081
  EXPECT_TRUE(is_host(0x0FF1));
  EXPECT_TRUE(is_broadcast(0x1000));
  EXPECT_FALSE(is_broadcast(0x1010));
  EXPECT_EQ(id_of(0x0FF0), 255);
  EXPECT_TRUE(id_code_valid(0x1FF1));
  EXPECT_FALSE(id_code_valid(0x2000));
  EXPECT_FALSE(id_code_valid(0x0002));
}

TEST(TmlMessage, KppAssignmentIsOpcode205E) {
  const auto m = assign16(axis_id_code(255), 0x025E, 5);
  ASSERT_TRUE(m);
  EXPECT_EQ(*m, msg(0x0FF0, 0x205E, {0x0005}));
  const Classified c = classify(*m);
  EXPECT_EQ(c.kind, Kind::assign16);
  EXPECT_EQ(c.address, 0x025E);
  EXPECT_EQ(c.value, 5u);
  EXPECT_EQ(type_of(*m), MessageType::a);
}

TEST(TmlMessage, AssignmentOpcodesOnlyForKnownPages) {
  EXPECT_EQ(assign_opcode(0x0200, false), 0x2000);
  EXPECT_EQ(assign_opcode(0x03FF, false), 0x21FF);
  EXPECT_EQ(assign_opcode(0x08FC, false), 0x22FC);  // our choice: page-800 bit 0x0200
  EXPECT_EQ(assign_opcode(0x025E, true), 0x245E);   // our choice: 32-bit family 0x2400
  EXPECT_FALSE(assign_opcode(0x0400, false));
  EXPECT_FALSE(assign_opcode(0x01FF, true));
  EXPECT_FALSE(assign_opcode(0x0A00, false));
  // Every encodable address classifies back to itself.
  for (std::uint32_t a = 0; a < 0x10000; a += 7) {
    for (const bool wide : {false, true}) {
      const auto o = assign_opcode(static_cast<std::uint16_t>(a), wide);
      if (!o) continue;
      const Message m = wide ? msg(0x0010, *o, {1, 2}) : msg(0x0010, *o, {1});
      const Classified c = classify(m);
      EXPECT_EQ(c.address, a);
      EXPECT_EQ(c.kind, wide ? Kind::assign32 : Kind::assign16);
    }
  }
}

TEST(TmlMessage, ThirtyTwoBitAssignmentSendsLowWordFirst) {
  const auto m = assign32(axis_id_code(5), 0x0300, 0x12345678);
  ASSERT_TRUE(m);
  EXPECT_EQ(*m, msg(0x0050, 0x2500, {0x5678, 0x1234}));
  EXPECT_EQ(classify(*m).value, 0x12345678u);
}

TEST(TmlMessage, GiveMeDataAndTakeDataOfExample2) {
  const Message q = give_me_data(axis_id_code(255), host_id_code(255), 0x025E, false);
  EXPECT_EQ(q, msg(0x0FF0, 0xB004, {0x0FF1, 0x025E}));
  EXPECT_EQ(type_of(q), MessageType::b);
  const Message a = take_data(host_id_code(255), axis_id_code(255), 0x025E, 0x0120, false);
  EXPECT_EQ(a, msg(0x0FF1, 0xB404, {0x0FF0, 0x025E, 0x0120}));
  const Classified c = classify(a);
  EXPECT_EQ(c.kind, Kind::take_data);
  EXPECT_EQ(c.sender, 0x0FF0);
  EXPECT_EQ(c.address, 0x025E);
  EXPECT_EQ(c.value, 0x0120u);
  EXPECT_EQ(type_of(a), MessageType::answer);
  EXPECT_EQ(take_data(1, 2, 3, 0xAABBCCDD, true), msg(1, 0xB405, {2, 3, 0xCCDD, 0xAABB}));
}

TEST(TmlMessage, TakeData2CarriesTheSenderAxisInTheOpcode) {
  const Message m = take_data2(master_id(255), 255, 0x090E, 0x02018400, true);
  EXPECT_EQ(m, msg(0x0FF1, 0xD5FF, {0x090E, 0x8400, 0x0201}));
  const Classified c = classify(m);
  EXPECT_EQ(c.kind, Kind::take_data2);
  EXPECT_TRUE(c.wide);
  EXPECT_EQ(c.sender, 255);
  EXPECT_EQ(c.value, 0x02018400u);
  EXPECT_EQ(type_of(m), MessageType::c);
  EXPECT_EQ(take_data2(0x0030, 5, 0x022A, 2, false), msg(0x0030, 0xD405, {0x022A, 0x0002}));
  EXPECT_EQ(give_me_data2(group_id_code(1), axis_id_code(3), 0x022A, false), msg(0x1010, 0xB204, {0x0030, 0x022A}));
}

TEST(TmlMessage, SyncAndSetMasterTimeAreBroadcasts) {
  EXPECT_EQ(sync_message(), msg(0x1000, 0x1000, {}));
  EXPECT_EQ(set_master_time(0x0246C46F), msg(0x1000, 0x1401, {0xC46F, 0x0246}));
  EXPECT_EQ(classify(set_master_time(0x0246C46F)).value, 0x0246C46Fu);
}

TEST(TmlMessage, PvtPointOfChapter5Example3) {
  // pvtp -1000L, -10, 500U, 0: velocity -10 IU as 16.16 fixed point.
  const PvtPoint p{-1000, -10 * 65536, 500, 0};
  const Message m = pvt(axis_id_code(5), p);
  EXPECT_EQ(m, msg(0x0050, 0x1800, {0xFC18, 0xFF00, 0xFFF6, 0x01F4}));
  EXPECT_EQ(classify(m).kind, Kind::pvt);
  ASSERT_TRUE(pvt_point(m));
  EXPECT_EQ(*pvt_point(m), p);
  // The counter goes into the opcode; velocity bits 7-0 are not carried.
  const PvtPoint q{0x7FFFFF, 0x123456FF, 0x1FF, 0x7F};
  const auto back = pvt_point(pvt(0x0050, q));
  ASSERT_TRUE(back);
  EXPECT_EQ(back->position, 0x7FFFFF);
  EXPECT_EQ(back->velocity, 0x12345600);
  EXPECT_EQ(back->time, 0x1FF);
  EXPECT_EQ(back->counter, 0x7F);
  EXPECT_FALSE(pvt_point(sync_message()));
}

TEST(TmlMessage, UnknownOpcodeIsGeneric) {
  const Message m = msg(0x0010, 0x7777, {1, 2, 3, 4});
  EXPECT_EQ(classify(m).kind, Kind::generic);
  EXPECT_EQ(type_of(m), MessageType::a);
  EXPECT_NE(describe(m).find("generic"), std::string::npos);
  // A known opcode with the wrong word count is flagged, not rejected.
  const Message short_take = msg(0x0FF1, 0xB404, {0x0FF0});
  EXPECT_FALSE(classify(short_take).complete);
  EXPECT_NE(describe(short_take).find("unexpected word count 1"), std::string::npos);
}

TEST(TmlSymbols, SeedAddresses) {
  ASSERT_NE(find_symbol("kpp"), nullptr);
  EXPECT_EQ(find_symbol("KPP")->address, 0x025E);
  EXPECT_EQ(find_symbol("POSERR")->address, 0x022A);
  EXPECT_EQ(find_symbol("SRL")->address, 0x090E);
  EXPECT_EQ(find_symbol("MER")->address, 0x08FC);
  EXPECT_TRUE(find_symbol("SR32")->wide);
  // The seed names APOS without an address; Technosoft's public TML_lib_light gives it.
  ASSERT_NE(find_symbol("apos"), nullptr);
  EXPECT_EQ(find_symbol("APOS")->address, 0x0228);
  EXPECT_TRUE(find_symbol("APOS")->wide);
  EXPECT_EQ(find_symbol("CSPD")->address, 0x02A0);
  EXPECT_EQ(find_symbol("nosuch"), nullptr);
  EXPECT_EQ(find_symbol(0x090E, true)->name, "SR32");
  EXPECT_EQ(find_symbol(0x090E, false)->name, "SRL");
}

TEST(TmlText, ParsesTheViewerForms) {
  TextInstruction t;
  ASSERT_EQ(parse_text("KPP=5", t), "");
  EXPECT_EQ(t.form, TextForm::assign);
  EXPECT_EQ(t.address, 0x025E);
  EXPECT_EQ(t.value, 5);
  ASSERT_EQ(parse_text(" kpp = 0x120 ", t), "");
  EXPECT_EQ(t.value, 0x120);
  ASSERT_EQ(parse_text("?POSERR", t), "");
  EXPECT_EQ(t.form, TextForm::give_me_data);
  ASSERT_EQ(parse_text("??SR32", t), "");
  EXPECT_EQ(t.form, TextForm::give_me_data2);
  EXPECT_TRUE(t.wide);
  ASSERT_EQ(parse_text("0x0300:32=-1", t), "");
  EXPECT_EQ(t.address, 0x0300);
  EXPECT_TRUE(t.wide);
  EXPECT_EQ(t.value, -1);
  EXPECT_NE(parse_text("FOO=1", t).find("unknown variable"), std::string::npos);
  EXPECT_NE(parse_text("KPP=70000", t).find("does not fit"), std::string::npos);
  EXPECT_NE(parse_text("KPP=five", t).find("not an integer"), std::string::npos);
  EXPECT_NE(parse_text("KPP", t), "");
  EXPECT_NE(parse_text("?", t), "");
}

TEST(TmlText, BuildsMessages) {
  TextInstruction t;
  Message m;
  ASSERT_EQ(parse_text("KPP=5", t), "");
  ASSERT_EQ(build_text(t, axis_id_code(255), host_id_code(255), m), "");
  EXPECT_EQ(m, msg(0x0FF0, 0x205E, {5}));
  ASSERT_EQ(parse_text("?KPP", t), "");
  ASSERT_EQ(build_text(t, axis_id_code(255), host_id_code(255), m), "");
  EXPECT_EQ(m, msg(0x0FF0, 0xB004, {0x0FF1, 0x025E}));
  EXPECT_NE(build_text(t, group_id_code(1), axis_id_code(3), m).find("one axis"), std::string::npos);
  ASSERT_EQ(parse_text("0x0500=1", t), "");
  EXPECT_NE(build_text(t, axis_id_code(1), 0, m).find("no assignment opcode"), std::string::npos);
  ASSERT_EQ(parse_text("SRL=-1", t), "");
  ASSERT_EQ(build_text(t, axis_id_code(1), 0, m), "");
  EXPECT_EQ(m, msg(0x0010, 0x230E, {0xFFFF}));
}

TEST(TmlText, DescribesInWords) {
  EXPECT_NE(describe(*assign16(0x0FF0, 0x025E, 5)).find("KPP"), std::string::npos);
  const std::string d = describe(take_data2(master_id(255), 255, 0x090E, 0x02018400, true));
  EXPECT_NE(d.find("TakeData2"), std::string::npos);
  EXPECT_NE(d.find("0x02018400"), std::string::npos);
  EXPECT_NE(d.find("axis 255 (host)"), std::string::npos);
  EXPECT_EQ(to_string(msg(0x0FF0, 0x205E, {5})), "0FF0 205E 0005");
}

}  // namespace
}  // namespace omnitwin::tml
