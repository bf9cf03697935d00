// Tests bus_emulators/ethercat/device/ec_od: the object dictionary built from the shipped drive
// ESI — defaults, binding to application storage, access rights per state, length and range
// checks with their SDO abort codes, check/after-write hooks, complete access layout, and
// entries without a default value (zero, never a copy from an empty default).
#include "bus_emulators/ethercat/device/ec_od.hpp"

#include <gtest/gtest.h>

#include <array>
#include <string>

namespace omnitwin::ethercat {
namespace {

class EcOd : public ::testing::Test {
 protected:
  void SetUp() override {
    od.add_from_esi(load_esi(std::string(OMNITWIN_SOURCE_DIR) + "/models/ethercat/omnitwin_drive.xml").at(0));
  }
  ObjectDictionary od;
  std::array<std::uint8_t, 256> buf{};
  std::size_t len = 0;
};

TEST_F(EcOd, DefaultsFromEsi) {
  ASSERT_EQ(od.read(0x6065, 0, OdState::preop, buf, len), SdoAbort::none);
  EXPECT_EQ(len, 4u);
  EXPECT_EQ(buf[0] | buf[1] << 8, 10000);
  const OdEntry* e = od.entry(0x1018, 2);
  ASSERT_NE(e, nullptr);
  EXPECT_EQ(e->as_int(), 0x402);
  EXPECT_EQ(e->data_type, coe_type::uint32);
  EXPECT_EQ(od.find(0x1018)->object_code, 9);
  EXPECT_EQ(od.find(0x1C12)->object_code, 8);
  EXPECT_EQ(od.find(0x1C12)->data_type, coe_type::uint16);
  EXPECT_EQ(od.entry(0x6098, 0)->as_int(), 35);
  EXPECT_EQ(od.entry(0x6060, 0)->data_type, coe_type::int8);
}

TEST_F(EcOd, BoundStorageIsTheValue) {
  std::uint16_t controlword = 0x1111;
  std::uint32_t window = 0;
  ASSERT_TRUE(od.bind(0x6040, 0, controlword));
  ASSERT_TRUE(od.bind(0x6065, 0, window));
  EXPECT_EQ(window, 10000u);        // writable entry: the ESI default is taken over
  EXPECT_EQ(controlword, 0u);       // default 0 given in the ESI
  const std::uint8_t v[2] = {0x0F, 0x00};
  ASSERT_EQ(od.write(0x6040, 0, OdState::op, v), SdoAbort::none);
  EXPECT_EQ(controlword, 0x000F);
  controlword = 0x0080;
  ASSERT_EQ(od.read(0x6040, 0, OdState::op, buf, len), SdoAbort::none);
  EXPECT_EQ(buf[0], 0x80);
  std::int32_t statusword_wrong_size = 0;
  EXPECT_FALSE(od.bind(0x6041, 0, statusword_wrong_size));
  EXPECT_FALSE(od.bind(0x7777, 0, window));
}

TEST_F(EcOd, AbortCodes) {
  const std::uint8_t two[2] = {1, 0}, four[4] = {1, 0, 0, 0}, one[1] = {1};
  EXPECT_EQ(od.write(0x5555, 0, OdState::preop, two), SdoAbort::no_object);
  EXPECT_EQ(od.write(0x6040, 1, OdState::preop, two), SdoAbort::no_subindex);
  EXPECT_EQ(od.write(0x6041, 0, OdState::preop, two), SdoAbort::read_only);
  EXPECT_EQ(od.write(0x6040, 0, OdState::preop, four), SdoAbort::too_long);
  EXPECT_EQ(od.write(0x6040, 0, OdState::preop, one), SdoAbort::too_short);
  // 0x1600 is writable in PRE-OP only.
  EXPECT_EQ(od.write(0x1600, 0, OdState::safeop, one), SdoAbort::state);
  EXPECT_EQ(od.read(0x5555, 0, OdState::preop, buf, len), SdoAbort::no_object);
  EXPECT_EQ(od.read(0x6041, 9, OdState::preop, buf, len), SdoAbort::no_subindex);
  // Write-only entry and limits on a hand-made object.
  OdObject o;
  o.index = 0x2001;
  o.name = "test";
  OdEntry e;
  e.data_type = coe_type::int16;
  e.bits = 16;
  e.access = od_access::write_all;
  e.min = -10;
  e.max = 10;
  o.entries.push_back(e);
  od.add(o);
  EXPECT_EQ(od.read(0x2001, 0, OdState::op, buf, len), SdoAbort::write_only);
  const std::uint8_t minus5[2] = {0xFB, 0xFF}, minus11[2] = {0xF5, 0xFF}, eleven[2] = {11, 0};
  EXPECT_EQ(od.write(0x2001, 0, OdState::op, minus5), SdoAbort::none);
  EXPECT_EQ(od.entry(0x2001, 0)->as_int(), -5);
  EXPECT_EQ(od.write(0x2001, 0, OdState::op, minus11), SdoAbort::value_range);
  EXPECT_EQ(od.write(0x2001, 0, OdState::op, eleven), SdoAbort::value_range);
}

TEST_F(EcOd, HooksVetAndObserve) {
  int seen = -1;
  OdObject* o = od.find(0x6098);
  o->check = [](const OdObject&, std::uint8_t, std::span<const std::uint8_t> d) {
    return d[0] == 99 ? SdoAbort::value_range : SdoAbort::none;
  };
  o->after_write = [&](OdObject&, std::uint8_t sub) { seen = sub; };
  const std::uint8_t bad[1] = {99}, good[1] = {17};
  EXPECT_EQ(od.write(0x6098, 0, OdState::preop, bad), SdoAbort::value_range);
  EXPECT_EQ(seen, -1);
  EXPECT_EQ(od.entry(0x6098, 0)->as_int(), 35);
  EXPECT_EQ(od.write(0x6098, 0, OdState::preop, good), SdoAbort::none);
  EXPECT_EQ(seen, 0);
  EXPECT_EQ(od.entry(0x6098, 0)->as_int(), 17);
}

TEST_F(EcOd, StringsAcceptShorterData) {
  const std::string s = "x";
  OdObject o;
  o.index = 0x2002;
  OdEntry e;
  e.data_type = coe_type::visible_string;
  e.bits = 32;
  e.access = od_access::rw;
  o.entries.push_back(e);
  od.add(o);
  ASSERT_EQ(od.write(0x2002, 0, OdState::preop, {reinterpret_cast<const std::uint8_t*>(s.data()), 1}), SdoAbort::none);
  ASSERT_EQ(od.read(0x2002, 0, OdState::preop, buf, len), SdoAbort::none);
  EXPECT_EQ(len, 4u);
  EXPECT_EQ(buf[0], 'x');
  EXPECT_EQ(buf[1], 0);
}

TEST_F(EcOd, CompleteAccessLayout) {
  // 0x1C12: subindex 0 (1 entry) padded to 16 bits, then the assigned PDO index.
  ASSERT_EQ(od.read_complete(0x1C12, 0, OdState::preop, buf, len), SdoAbort::none);
  ASSERT_EQ(len, 4u);
  EXPECT_EQ(buf[0], 1);
  EXPECT_EQ(buf[1], 0);
  EXPECT_EQ(buf[2] | buf[3] << 8, 0x1600);
  // Write a new assignment with complete access: 0x1601 only.
  const std::uint8_t ca[4] = {1, 0, 0x01, 0x16};
  ASSERT_EQ(od.write_complete(0x1C12, 0, OdState::preop, ca), SdoAbort::none);
  EXPECT_EQ(od.entry(0x1C12, 1)->as_int(), 0x1601);
  EXPECT_EQ(od.entry(0x1C12, 0)->as_int(), 1);
  EXPECT_EQ(od.write_complete(0x1C12, 0, OdState::safeop, ca), SdoAbort::state);
  EXPECT_EQ(od.read_complete(0x1C12, 2, OdState::preop, buf, len), SdoAbort::unsupported_access);
  EXPECT_EQ(od.complete_size(0x1018, 0), 2u + 16u);
}

// Complete access addresses all entries of an ARRAY or RECORD. A VAR (object code 7) is refused
// with 0x06010000: its upload was cut to 2 bytes, a download wrote the size byte into it.
TEST_F(EcOd, CompleteAccessToAVarIsRefused) {
  ASSERT_EQ(od.find(0x1000)->object_code, 7);
  EXPECT_EQ(od.read_complete(0x1000, 0, OdState::preop, buf, len), SdoAbort::unsupported_access);
  EXPECT_EQ(od.read_complete(0x6081, 0, OdState::preop, buf, len), SdoAbort::unsupported_access);
  const auto profile_velocity = od.entry(0x6081, 0)->as_int();
  const std::uint8_t four[4] = {0x10, 0x27, 0, 0};
  EXPECT_EQ(od.write_complete(0x6081, 0, OdState::preop, four), SdoAbort::unsupported_access);
  EXPECT_EQ(od.entry(0x6081, 0)->as_int(), profile_velocity);
  const auto mode = od.entry(0x6060, 0)->as_int();
  const std::uint8_t two[2] = {8, 0};
  EXPECT_EQ(od.write_complete(0x6060, 0, OdState::preop, two), SdoAbort::unsupported_access);
  EXPECT_EQ(od.entry(0x6060, 0)->as_int(), mode);
}

// Entries without a default (empty default_value, whose data() may be null): added, bound and
// restored without copying from it — the value is zero and bound storage keeps its value.
TEST(EcOdNoDefault, EntriesWithoutADefaultStartAtZero) {
  ObjectDictionary od;
  OdObject o;
  o.index = 0x2100;
  o.object_code = 7;
  OdEntry e;
  e.subindex = 0;
  e.data_type = coe_type::uint32;
  e.bits = 32;
  e.access = od_access::read_all | od_access::write_all;
  ASSERT_TRUE(e.default_value.empty());
  o.entries.push_back(e);
  od.add(o);
  ASSERT_NE(od.entry(0x2100, 0), nullptr);
  EXPECT_EQ(od.entry(0x2100, 0)->as_int(), 0);
  std::uint32_t storage = 0xA5A5A5A5u;
  ASSERT_TRUE(od.bind(0x2100, 0, storage));
  EXPECT_EQ(storage, 0xA5A5A5A5u);  // nothing to take over
  od.restore_defaults();
  EXPECT_EQ(storage, 0xA5A5A5A5u);  // bound without a default: left as it is
  const std::uint8_t v[4] = {1, 2, 3, 4};
  std::array<std::uint8_t, 8> buf{};
  std::size_t len = 0;
  ASSERT_EQ(od.write(0x2100, 0, OdState::preop, v), SdoAbort::none);
  ASSERT_EQ(od.read(0x2100, 0, OdState::preop, buf, len), SdoAbort::none);
  EXPECT_EQ(len, 4u);
  EXPECT_EQ(storage, 0x04030201u);
}

}  // namespace
}  // namespace omnitwin::ethercat
