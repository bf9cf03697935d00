// Tests bus_emulators/ethercat/device/ec_esi: parsing of the shipped ESI files (identity,
// SyncManagers, PDOs, CoE flags, DC op modes, EEPROM size, object dictionary with records,
// arrays, defaults and access rights) and the errors for a missing file, malformed XML (with its
// line), a missing Vendor Id and bad numbers.
#include "bus_emulators/ethercat/device/ec_esi.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>
#include <string>

namespace omnitwin::ethercat {
namespace {

std::string model(const std::string& name) { return std::string(OMNITWIN_SOURCE_DIR) + "/models/ethercat/" + name; }
std::string data(const std::string& name) { return std::string(OMNITWIN_SOURCE_DIR) + "/tests/data/ethercat/" + name; }

std::string error_of(const std::string& path) {
  try {
    load_esi(path);
  } catch (const EsiError& e) {
    return e.what();
  }
  return "";
}

TEST(EcEsi, ParsesNumbers) {
  EXPECT_EQ(parse_esi_number("#x1A00"), 0x1A00);
  EXPECT_EQ(parse_esi_number("0x10"), 16);
  EXPECT_EQ(parse_esi_number(" 42 "), 42);
  EXPECT_EQ(parse_esi_number("-5"), -5);
  EXPECT_FALSE(parse_esi_number("#x").has_value());
  EXPECT_FALSE(parse_esi_number("12a").has_value());
  EXPECT_EQ(esi_type_bits("UDINT"), 32);
  EXPECT_EQ(esi_type_bits("BIT3"), 3);
  EXPECT_EQ(esi_type_bits("STRING(8)"), 64);
  EXPECT_EQ(esi_type_bits("NOPE"), 0);
}

TEST(EcEsi, ShippedDriveFile) {
  const auto devs = load_esi(model("omnitwin_drive.xml"));
  ASSERT_EQ(devs.size(), 1u);
  const auto& d = devs[0];
  EXPECT_EQ(d.vendor_id, 0x00000F1Cu);
  EXPECT_EQ(d.product_code, 0x00000402u);
  EXPECT_EQ(d.revision, 0x00010000u);
  EXPECT_EQ(d.name, "omnitwin drive 1-axis");
  EXPECT_EQ(d.type_name, "OT-DRV1");
  EXPECT_EQ(d.group, "OmniDrive");
  EXPECT_EQ(d.profile, 402);
  EXPECT_EQ(d.axes, 1);
  EXPECT_EQ(d.eeprom_bytes, 2048u);
  ASSERT_EQ(d.sms.size(), 4u);
  EXPECT_EQ(d.sms[0].kind, SmKind::mbox_out);
  EXPECT_EQ(d.sms[0].start, 0x1000);
  EXPECT_EQ(d.sms[0].size, 128);
  EXPECT_EQ(d.sms[0].control, 0x26);
  EXPECT_TRUE(d.sms[0].enable);
  EXPECT_EQ(d.sms[1].kind, SmKind::mbox_in);
  EXPECT_EQ(d.sms[1].control, 0x22);
  EXPECT_EQ(d.sms[2].kind, SmKind::outputs);
  EXPECT_EQ(d.sms[2].control, 0x64);
  EXPECT_EQ(d.sms[3].kind, SmKind::inputs);
  EXPECT_EQ(d.sm_of_kind(SmKind::inputs), 3);
  ASSERT_EQ(d.rx_pdos.size(), 2u);
  const auto& rx = d.rx_pdos[0];
  EXPECT_EQ(rx.index, 0x1600);
  EXPECT_EQ(rx.sm, 2);
  EXPECT_FALSE(rx.fixed);
  ASSERT_EQ(rx.entries.size(), 7u);
  EXPECT_EQ(rx.entries[0].index, 0x6040);
  EXPECT_EQ(rx.entries[0].bit_length, 16);
  EXPECT_EQ(rx.entries[0].data_type, "UINT");
  EXPECT_EQ(rx.entries[5].index, 0);  // padding
  EXPECT_EQ(rx.bit_size(), 144u);
  EXPECT_EQ(d.rx_pdos[1].sm, -1);      // optional, not assigned
  ASSERT_EQ(d.tx_pdos.size(), 2u);
  EXPECT_EQ(d.tx_pdos[0].index, 0x1A00);
  EXPECT_EQ(d.tx_pdos[0].bit_size(), 192u);
  EXPECT_TRUE(d.coe.present);
  EXPECT_TRUE(d.coe.sdo_info);
  EXPECT_TRUE(d.coe.complete_access);
  EXPECT_TRUE(d.coe.pdo_assign);
  EXPECT_TRUE(d.coe.pdo_config);
  ASSERT_EQ(d.dc.size(), 2u);
  EXPECT_EQ(d.dc[0].assign_activate, 0x0300);
  EXPECT_EQ(d.dc[1].assign_activate, 0x0000);
  EXPECT_EQ(d.eeprom_config.size(), 6u);

  // Object dictionary: a VAR with default, a record, access and mapping flags.
  const EsiObject* cw = d.object(0x6040);
  ASSERT_NE(cw, nullptr);
  EXPECT_EQ(cw->object_code, 7);
  ASSERT_EQ(cw->entries.size(), 1u);
  EXPECT_EQ(cw->entries[0].bit_size, 16);
  EXPECT_EQ(cw->entries[0].access, od_access::rw | od_access::rxpdo);
  const EsiObject* sw = d.object(0x6041);
  ASSERT_NE(sw, nullptr);
  EXPECT_EQ(sw->entries[0].access, od_access::read_all | od_access::txpdo);
  const EsiObject* fe = d.object(0x6065);
  ASSERT_NE(fe, nullptr);
  EXPECT_EQ(fe->entries[0].default_data, (std::vector<std::uint8_t>{0x10, 0x27, 0, 0}));  // 10000
  const EsiObject* id = d.object(0x1018);
  ASSERT_NE(id, nullptr);
  EXPECT_EQ(id->object_code, 9);
  ASSERT_EQ(id->entries.size(), 5u);
  EXPECT_EQ(id->entries[2].name, "Product code");
  EXPECT_EQ(id->entries[2].default_data, (std::vector<std::uint8_t>{0x02, 0x04, 0, 0}));
  const EsiObject* map = d.object(0x1600);
  ASSERT_NE(map, nullptr);
  EXPECT_EQ(map->entries[1].default_data, (std::vector<std::uint8_t>{0x10, 0x00, 0x40, 0x60}));  // 0x60400010
  EXPECT_EQ(map->entries[1].access, od_access::read_all | od_access::write_preop);
  const EsiObject* name = d.object(0x1008);
  ASSERT_NE(name, nullptr);
  EXPECT_EQ(name->entries[0].bit_size, 8 * std::string("omnitwin drive 1-axis").size());
}

TEST(EcEsi, ShippedMultiAxisFile) {
  const auto devs = load_esi(model("omnitwin_multiaxis.xml"));
  ASSERT_EQ(devs.size(), 1u);
  const auto& d = devs[0];
  EXPECT_EQ(d.product_code, 0x00000801u);
  EXPECT_EQ(d.profile, 5001);
  EXPECT_EQ(d.axes, 8);
  ASSERT_EQ(d.rx_pdos.size(), 8u);
  ASSERT_EQ(d.tx_pdos.size(), 8u);
  for (int n = 0; n < 8; ++n) {
    EXPECT_EQ(d.rx_pdos[n].index, 0x1600 + n);
    EXPECT_TRUE(d.rx_pdos[n].fixed);
    EXPECT_EQ(d.rx_pdos[n].bit_size(), 96u);  // 12-byte command data module
    EXPECT_EQ(d.rx_pdos[n].entries[0].index, 0x7000 + 0x10 * n);
    EXPECT_EQ(d.tx_pdos[n].bit_size(), 96u);  // 12-byte status data module
    EXPECT_EQ(d.tx_pdos[n].entries[3].index, 0x6000 + 0x10 * n);
  }
  EXPECT_FALSE(d.coe.pdo_config);
  const EsiObject* map = d.object(0x1600);
  ASSERT_NE(map, nullptr);
  EXPECT_EQ(map->entries[1].access, od_access::read_all);  // fixed mapping
  EXPECT_EQ(d.sms[3].start, 0x1300);  // past SM2's three 96-byte buffers (0x1100 … 0x121F)
}

TEST(EcEsi, ArraysRestrictionsAndDecimalIds) {
  const auto devs = load_esi(data("small_io.xml"));
  ASSERT_EQ(devs.size(), 1u);
  const auto& d = devs[0];
  EXPECT_EQ(d.vendor_id, 3868u);
  EXPECT_EQ(d.revision, 2u);
  EXPECT_EQ(d.eeprom_bytes, 256u);
  EXPECT_FALSE(d.coe.complete_access);
  ASSERT_EQ(d.tx_pdos.size(), 1u);
  EXPECT_TRUE(d.tx_pdos[0].fixed);
  EXPECT_TRUE(d.tx_pdos[0].mandatory);
  EXPECT_EQ(d.tx_pdos[0].entries[0].bit_length, 1);
  const EsiObject* as = d.object(0x1C13);
  ASSERT_NE(as, nullptr);
  EXPECT_EQ(as->object_code, 8);
  ASSERT_EQ(as->entries.size(), 3u);
  EXPECT_EQ(as->entries[1].subindex, 1);
  EXPECT_EQ(as->entries[2].subindex, 2);
  EXPECT_EQ(as->entries[1].default_data, (std::vector<std::uint8_t>{0x00, 0x1A}));
  EXPECT_EQ(as->entries[1].access, od_access::read_all | od_access::write_preop);
  const EsiObject* secret = d.object(0x2000);
  ASSERT_NE(secret, nullptr);
  EXPECT_EQ(secret->entries[0].access,
            od_access::read_preop | od_access::read_safeop | od_access::write_all | od_access::txpdo);
}

// An array's elements become subindices: LBound + Elements past 256 is an error naming the
// line, not 5,000,000 entries (3.5 s, 1.6 GB) or wrapped, duplicate subindices (found in review).
TEST(EcEsi, AnArrayLargerThanTheSubindicesIsRefused) {
  std::ifstream in(data("small_io.xml"));
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string good = ss.str();
  for (const std::string& bad : {std::string("<LBound>1</LBound><Elements>5000000</Elements>"),
                                 std::string("<LBound>1</LBound><Elements>300</Elements>"),
                                 std::string("<LBound>-1</LBound><Elements>2</Elements>")}) {
    std::string text = good;
    const std::string was = "<LBound>1</LBound><Elements>2</Elements>";
    const auto at = text.find(was);
    ASSERT_NE(at, std::string::npos);
    text.replace(at, was.size(), bad);
    try {
      parse_esi(text, "big.xml");
      FAIL() << bad;
    } catch (const EsiError& e) {
      EXPECT_NE(std::string(e.what()).find("big.xml:28: ArrayInfo LBound"), std::string::npos) << e.what();
    }
  }
  std::string edge = good;
  edge.replace(edge.find("<Elements>2</Elements>"), 22, "<Elements>255</Elements>");
  EXPECT_NO_THROW(parse_esi(edge, "edge.xml"));
}

TEST(EcEsi, MissingFile) {
  const std::string e = error_of(data("does_not_exist.xml"));
  EXPECT_NE(e.find("does_not_exist.xml:0: cannot open"), std::string::npos) << e;
}

// Found in review: a directory read as an empty file ("malformed XML: No document element").
TEST(EcEsi, ADirectoryIsNamedAsOne) {
  const std::string e = error_of(data(""));
  EXPECT_NE(e.find(":0: a directory, not a file"), std::string::npos) << e;
}

TEST(EcEsi, MalformedXmlNamesTheLine) {
  const std::string e = error_of(data("malformed.xml"));
  EXPECT_NE(e.find("malformed.xml:10: malformed XML"), std::string::npos) << e;
}

TEST(EcEsi, MissingVendorId) {
  const std::string e = error_of(data("no_vendor_id.xml"));
  EXPECT_NE(e.find("no_vendor_id.xml:3: Vendor: Id missing"), std::string::npos) << e;
}

TEST(EcEsi, BadNumberNamesTheLine) {
  const std::string e = error_of(data("bad_values.xml"));
  EXPECT_NE(e.find("bad_values.xml:13: Entry BitLen: '#xZZ' is not a number"), std::string::npos) << e;
}

TEST(EcEsi, StructuralErrorsFromText) {
  EXPECT_THROW(parse_esi("<Other/>"), EsiError);
  EXPECT_THROW(parse_esi("<EtherCATInfo><Vendor><Id>1</Id></Vendor></EtherCATInfo>"), EsiError);
  try {
    parse_esi("<EtherCATInfo>\n<Vendor><Id>1</Id></Vendor>\n<Descriptions><Devices>\n<Device><Type>X</Type></Device>\n"
              "</Devices></Descriptions></EtherCATInfo>",
              "inline.xml");
    FAIL() << "no error";
  } catch (const EsiError& e) {
    EXPECT_STREQ(e.what(), "inline.xml:4: Type: ProductCode missing");
  }
  try {
    parse_esi("<EtherCATInfo><Vendor><Id>1</Id></Vendor><Descriptions><Devices><Device>"
              "<Type ProductCode='1'>X</Type><Sm StartAddress='#x1000'>Sideways</Sm></Device>"
              "</Devices></Descriptions></EtherCATInfo>");
    FAIL() << "no error";
  } catch (const EsiError& e) {
    EXPECT_NE(std::string(e.what()).find("Sm 'Sideways'"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace omnitwin::ethercat
