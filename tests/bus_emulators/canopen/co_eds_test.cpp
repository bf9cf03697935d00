// Tests bus_emulators/canopen/co_eds: CiA 306 numbers and the AccessType → od_access mapping;
// the shipped models/canopen/omnitwin_drive.eds (identity, every object of drive::Objects with
// its size, signedness and default, PDO mapping rights, $NODEID defaults for node 5, the default
// PDO mapping, the segmented device name); the parser's INI rules (case, comments, CR LF),
// value forms and limits in the built dictionary; and the errors, each naming file, line,
// section and key: the bad files under tests/data/canopen and inline texts.
#include "bus_emulators/canopen/co_eds.hpp"

#include <gtest/gtest.h>

#include <chrono>

#include <algorithm>
#include <array>
#include <fstream>
#include <sstream>
#include <string>
#include <type_traits>

#include "bus_emulators/drive/cia402_drive.hpp"

namespace omnitwin::canopen {
namespace {

std::string model() { return std::string(OMNITWIN_SOURCE_DIR) + "/models/canopen/omnitwin_drive.eds"; }
std::string data(const std::string& name) { return std::string(OMNITWIN_SOURCE_DIR) + "/tests/data/canopen/" + name; }

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// 1-based line of the first (or last) line of `text` that starts with `needle` (0 when absent).
int line_of(const std::string& text, const std::string& needle, bool last = false) {
  std::istringstream in(text);
  std::string l;
  int found = 0;
  for (int n = 1; std::getline(in, l); ++n)
    if (l.rfind(needle, 0) == 0) {
      found = n;
      if (!last) break;
    }
  return found;
}

std::string error_of_file(const std::string& path) {
  try {
    load_eds(path);
  } catch (const EdsError& e) {
    return e.what();
  }
  return "no error";
}

std::string error_of_text(const std::string& text) {
  try {
    parse_eds(text, "t.eds");
  } catch (const EdsError& e) {
    return e.what();
  }
  return "no error";
}

// A valid device with objects 0x1000, 0x1001, 0x1018 and `optional` listed in [OptionalObjects]
// (given as "1=0x2000\n..." with its count) followed by `sections`.
std::string device(int count, const std::string& optional, const std::string& sections) {
  return "[DeviceInfo]\nVendorName=v\nVendorNumber=1\nProductName=p\nProductNumber=2\n\n"
         "[MandatoryObjects]\nSupportedObjects=3\n1=0x1000\n2=0x1001\n3=0x1018\n\n"
         "[1000]\nParameterName=Device type\nDataType=0x0007\nAccessType=ro\nDefaultValue=0x00020192\n\n"
         "[1001]\nParameterName=Error register\nDataType=0x0005\nAccessType=ro\n\n"
         "[1018]\nParameterName=Identity\nObjectType=0x9\nSubNumber=2\n"
         "[1018sub0]\nParameterName=n\nDataType=0x0005\nAccessType=ro\nDefaultValue=1\n"
         "[1018sub1]\nParameterName=Vendor-ID\nDataType=0x0007\nAccessType=ro\nDefaultValue=1\n\n"
         "[OptionalObjects]\nSupportedObjects=" + std::to_string(count) + "\n" + optional + "\n" + sections;
}

// One VAR 0x2000 with the given keys below its ParameterName.
std::string var2000(const std::string& keys) {
  return device(1, "1=0x2000", "[2000]\nParameterName=x\n" + keys);
}

TEST(CoEds, ParsesNumbers) {
  EXPECT_EQ(parse_eds_number("42"), 42);
  EXPECT_EQ(parse_eds_number(" 0x1A "), 0x1A);
  EXPECT_EQ(parse_eds_number("0X1a"), 0x1A);
  EXPECT_EQ(parse_eds_number("010"), 8);  // leading 0: octal
  EXPECT_EQ(parse_eds_number("0"), 0);
  EXPECT_EQ(parse_eds_number("-5"), -5);
  EXPECT_EQ(parse_eds_number("-0x10"), -16);
  EXPECT_FALSE(parse_eds_number("08").has_value());
  EXPECT_FALSE(parse_eds_number("0x").has_value());
  EXPECT_FALSE(parse_eds_number("").has_value());
  EXPECT_FALSE(parse_eds_number("12a").has_value());
  EXPECT_FALSE(parse_eds_number("0x10000000000000000").has_value());
  EXPECT_EQ(eds_type_bits(data_type::boolean), 1);
  EXPECT_EQ(eds_type_bits(data_type::int16), 16);
  EXPECT_EQ(eds_type_bits(0x0016), 24);  // UNSIGNED24
  EXPECT_EQ(eds_type_bits(data_type::uint64), 64);
  EXPECT_EQ(eds_type_bits(data_type::visible_string), 0);
  EXPECT_EQ(eds_type_bits(0x0099), 0);
}

TEST(CoEds, AccessMapping) {
  namespace a = od_access;
  EXPECT_EQ(eds_od_access(EdsAccess::ro, false), a::read_all);
  EXPECT_EQ(eds_od_access(EdsAccess::const_, false), a::read_all);
  EXPECT_EQ(eds_od_access(EdsAccess::wo, false), a::write_all);
  EXPECT_EQ(eds_od_access(EdsAccess::rw, false), a::rw);
  EXPECT_EQ(eds_od_access(EdsAccess::rwr, false), a::rw);
  EXPECT_EQ(eds_od_access(EdsAccess::rww, false), a::rw);
  EXPECT_EQ(eds_od_access(EdsAccess::rww, true), a::rw | a::rxpdo);
  EXPECT_EQ(eds_od_access(EdsAccess::wo, true), a::write_all | a::rxpdo);
  EXPECT_EQ(eds_od_access(EdsAccess::rwr, true), a::rw | a::txpdo);
  EXPECT_EQ(eds_od_access(EdsAccess::ro, true), a::read_all | a::txpdo);
  EXPECT_EQ(eds_od_access(EdsAccess::rw, true), a::rw | a::rxpdo | a::txpdo);
  EXPECT_STREQ(to_string(EdsAccess::rww), "rww");
  EXPECT_STREQ(to_string(EdsAccess::const_), "const");
}

TEST(CoEds, ShippedFileIdentity) {
  const EdsDevice d = load_eds(model());
  EXPECT_EQ(d.source, model());
  EXPECT_EQ(d.device_info.vendor_name, "omnitwin");
  EXPECT_EQ(d.device_info.vendor_number, 0x4F54574Eu);
  EXPECT_EQ(d.device_info.product_number, 0x402u);
  EXPECT_EQ(d.device_info.nr_of_rx_pdo, 4);
  EXPECT_EQ(d.device_info.nr_of_tx_pdo, 4);
  EXPECT_TRUE(d.device_info.supports_baud(1000));
  EXPECT_TRUE(d.device_info.supports_baud(125));
  EXPECT_FALSE(d.device_info.supports_baud(10));
  EXPECT_TRUE(d.device_info.simple_boot_up_slave);
  EXPECT_FALSE(d.device_info.lss_supported);
  EXPECT_EQ(d.device_info.granularity, 8);
  EXPECT_EQ(d.file_info.eds_version, "4.0");
  EXPECT_EQ(d.dummy_usage, 0xFC);  // Dummy0002..0007 (the PDO layer maps those)
  ASSERT_FALSE(d.comments.empty());
  EXPECT_NE(d.comments[1].find("fictitious"), std::string::npos);
  EXPECT_EQ(d.mandatory, (std::vector<std::uint16_t>{0x1000, 0x1001, 0x1018}));
  EXPECT_EQ(d.objects.size(), d.mandatory.size() + d.optional.size() + d.manufacturer.size());
  for (std::size_t i = 1; i < d.objects.size(); ++i) EXPECT_LT(d.objects[i - 1].index, d.objects[i].index);
  ASSERT_NE(d.object(0x1000), nullptr);
  EXPECT_EQ(d.object(0x1000)->entries[0].default_value->number, 0x00020192);
  // 0x1018 matches [DeviceInfo].
  const EdsObject* id = d.object(0x1018);
  ASSERT_NE(id, nullptr);
  EXPECT_EQ(id->object_type, 9);
  EXPECT_EQ(id->entry(1)->default_value->number, d.device_info.vendor_number);
  EXPECT_EQ(id->entry(2)->default_value->number, d.device_info.product_number);
  EXPECT_EQ(id->entry(3)->default_value->number, d.device_info.revision_number);
  // Communication objects the brief asks for.
  for (std::uint16_t i : {0x1003, 0x1005, 0x1006, 0x1007, 0x1008, 0x1009, 0x100A, 0x100C, 0x100D, 0x1012, 0x1014,
                          0x1015, 0x1016, 0x1017, 0x1019, 0x1029, 0x1200, 0x1400, 0x1403, 0x1600, 0x1603, 0x1800, 0x1803,
                          0x1A00, 0x1A03})
    EXPECT_NE(d.object(i), nullptr) << std::hex << i;
  EXPECT_EQ(d.object(0x1003)->entries.size(), 9u);  // sub 0 + 8 error fields
  EXPECT_EQ(d.object(0x1016)->entries.size(), 2u);
  // Error behaviour, which the node reads on a communication error (found by a walkthrough:
  // the doc listed it, the EDS lacked it, an SDO upload got abort 0x06020000).
  ASSERT_NE(d.object(0x1029), nullptr);
  EXPECT_EQ(d.object(0x1029)->entries.size(), 2u);
}

// One field of drive::Objects: where it lives in the dictionary and its default there.
struct DriveField {
  std::uint16_t index;
  std::uint8_t sub;
  std::size_t bytes;
  bool is_signed;
  std::int64_t value;
  void* field;
};

#define F(idx, sub, name) \
  DriveField { idx, sub, sizeof(o.name), std::is_signed_v<decltype(o.name)>, static_cast<std::int64_t>(o.name), &o.name }

std::vector<DriveField> drive_fields(drive::Objects& o) {
  return {F(0x603F, 0, error_code), F(0x6040, 0, controlword), F(0x6041, 0, statusword),
          F(0x605A, 0, quick_stop_option), F(0x605D, 0, halt_option), F(0x605E, 0, fault_reaction_option),
          F(0x6060, 0, mode), F(0x6061, 0, mode_display), F(0x6062, 0, position_demand),
          F(0x6064, 0, position_actual), F(0x6065, 0, following_error_window), F(0x6066, 0, following_error_timeout),
          F(0x6067, 0, position_window), F(0x6068, 0, position_window_time), F(0x606B, 0, velocity_demand),
          F(0x606C, 0, velocity_actual), F(0x606D, 0, velocity_window), F(0x606E, 0, velocity_window_time),
          F(0x606F, 0, velocity_threshold), F(0x6071, 0, target_torque), F(0x6072, 0, max_torque),
          F(0x6074, 0, torque_demand), F(0x6077, 0, torque_actual), F(0x607A, 0, target_position),
          F(0x607C, 0, home_offset), F(0x607D, 1, sw_limit_min), F(0x607D, 2, sw_limit_max), F(0x607E, 0, polarity),
          F(0x607F, 0, max_profile_velocity), F(0x6080, 0, max_motor_speed), F(0x6081, 0, profile_velocity),
          F(0x6082, 0, end_velocity), F(0x6083, 0, profile_acceleration), F(0x6084, 0, profile_deceleration),
          F(0x6085, 0, quick_stop_deceleration), F(0x6087, 0, torque_slope), F(0x6098, 0, homing_method),
          F(0x6099, 1, homing_speed_switch), F(0x6099, 2, homing_speed_zero), F(0x609A, 0, homing_acceleration),
          F(0x60B1, 0, velocity_offset), F(0x60B2, 0, torque_offset), F(0x60F4, 0, following_error_actual),
          F(0x60FD, 0, digital_inputs), F(0x60FE, 1, digital_outputs), F(0x60FE, 2, digital_outputs_mask),
          F(0x60FF, 0, target_velocity), F(0x6502, 0, supported_modes)};
}
#undef F

TEST(CoEds, ShippedFileHasEveryDriveObject) {
  const EdsDevice d = load_eds(model());
  ObjectDictionary od;
  add_to_od(d, 5, od);
  drive::Objects o;
  const auto fields = drive_fields(o);
  EXPECT_EQ(fields.size(), 48u);
  for (const auto& f : fields) {
    SCOPED_TRACE(::testing::Message() << std::hex << f.index << ":" << int(f.sub));
    const OdEntry* e = od.entry(f.index, f.sub);
    ASSERT_NE(e, nullptr);
    EXPECT_EQ(e->bits, f.bytes * 8);
    EXPECT_EQ(e->is_signed(), f.is_signed);
    // 0x6502 advertises DriveConfig's default modes (drive::Objects starts it at 0).
    EXPECT_EQ(e->as_int(), f.index == 0x6502 ? std::int64_t{drive::kAllModes} : f.value);
    // The drive's field can back the entry (what the CANopen node binds).
    EXPECT_TRUE(od.bind(f.index, f.sub, f.field, f.bytes));
  }
  // Arrays carry their element type and sub 0 = number of entries.
  EXPECT_EQ(od.find(0x607D)->object_code, 8);
  EXPECT_EQ(od.find(0x607D)->data_type, data_type::int32);
  EXPECT_EQ(od.entry(0x6099, 0)->as_int(), 2);
}

TEST(CoEds, ShippedFilePdoRights) {
  ObjectDictionary od;
  add_to_od(load_eds(model()), 5, od);
  auto access = [&](std::uint16_t i, std::uint8_t s) { return od.entry(i, s)->access; };
  for (std::uint16_t i : {0x6040, 0x6060, 0x607A, 0x60FF, 0x6071, 0x60B1}) {
    EXPECT_EQ(access(i, 0), od_access::rw | od_access::rxpdo) << std::hex << i;
  }
  for (std::uint16_t i : {0x6041, 0x6061, 0x6064, 0x606C, 0x6077, 0x603F, 0x60FD}) {
    EXPECT_EQ(access(i, 0), od_access::read_all | od_access::txpdo) << std::hex << i;
  }
  EXPECT_EQ(access(0x60FE, 1), od_access::rw | od_access::rxpdo);
  EXPECT_EQ(access(0x6065, 0), od_access::rw);             // parameter: SDO only
  EXPECT_EQ(access(0x6502, 0), od_access::read_all);
  EXPECT_EQ(access(0x1008, 0), od_access::read_all);       // const
  std::array<std::uint8_t, 4> buf{};
  std::size_t len = 0;
  EXPECT_EQ(od.write(0x6041, 0, OdState::preop, std::span<const std::uint8_t>(buf.data(), 2)), SdoAbort::read_only);
  EXPECT_EQ(od.write(0x6065, 0, OdState::op, buf), SdoAbort::none);
  EXPECT_EQ(od.read(0x6065, 0, OdState::op, buf, len), SdoAbort::none);
  EXPECT_EQ(len, 4u);
}

TEST(CoEds, NodeIdDefaultsForNode5) {
  const EdsDevice d = load_eds(model());
  EXPECT_TRUE(d.object(0x1014)->entries[0].default_value->plus_node_id);
  EXPECT_EQ(d.object(0x1014)->entries[0].default_value->value(5), 0x85);
  ObjectDictionary od;
  add_to_od(d, 5, od);
  auto v = [&](std::uint16_t i, std::uint8_t s) { return od.entry(i, s)->as_int(); };
  EXPECT_EQ(v(0x1014, 0), 0x85);
  EXPECT_EQ(v(0x1200, 1), 0x605);
  EXPECT_EQ(v(0x1200, 2), 0x585);
  EXPECT_EQ(v(0x1400, 1), 0x205);
  EXPECT_EQ(v(0x1401, 1), 0x305);
  EXPECT_EQ(v(0x1402, 1), 0x80000405);
  EXPECT_EQ(v(0x1403, 1), 0x80000505);
  EXPECT_EQ(v(0x1800, 1), 0x185);
  EXPECT_EQ(v(0x1801, 1), 0x285);
  EXPECT_EQ(v(0x1802, 1), 0x80000385);
  EXPECT_EQ(v(0x1803, 1), 0x80000485);
  EXPECT_EQ(v(0x1005, 0), 0x80);   // not node-relative
  EXPECT_EQ(v(0x1012, 0), 0x100);
  ObjectDictionary od127;
  add_to_od(d, 127, od127);
  EXPECT_EQ(od127.entry(0x1800, 1)->as_int(), 0x1FF);
  EXPECT_THROW(add_to_od(d, 0, od127), EdsError);
  EXPECT_THROW(add_to_od(d, 128, od127), EdsError);
}

TEST(CoEds, ShippedDefaultPdoMapping) {
  ObjectDictionary od;
  add_to_od(load_eds(model()), 5, od);
  struct Pdo {
    std::uint16_t map;
    std::vector<std::uint32_t> entries;
    int bytes;
    std::uint8_t transmission;
    bool tx;
  };
  const Pdo pdos[] = {{0x1600, {0x60400010, 0x60FF0020}, 6, 1, false}, {0x1601, {0x60400010, 0x60600008}, 3, 255, false},
                      {0x1A00, {0x60410010, 0x60640020}, 6, 1, true},  {0x1A01, {0x60410010, 0x606C0020}, 6, 1, true},
                      {0x1602, {}, 0, 255, false}, {0x1603, {}, 0, 255, false}, {0x1A02, {}, 0, 255, true},
                      {0x1A03, {}, 0, 255, true}};
  for (const auto& p : pdos) {
    SCOPED_TRACE(::testing::Message() << std::hex << p.map);
    const OdObject* m = od.find(p.map);
    ASSERT_NE(m, nullptr);
    EXPECT_EQ(m->max_subindex(), 8);
    ASSERT_EQ(m->entry(0)->as_int(), static_cast<std::int64_t>(p.entries.size()));
    int bits = 0;
    for (std::size_t k = 0; k < p.entries.size(); ++k) {
      const auto raw = static_cast<std::uint32_t>(m->entry(static_cast<std::uint8_t>(k + 1))->as_int());
      EXPECT_EQ(raw, p.entries[k]);
      // The mapped entry exists with that size and may be mapped in that direction.
      const OdEntry* e = od.entry(static_cast<std::uint16_t>(raw >> 16), static_cast<std::uint8_t>(raw >> 8));
      ASSERT_NE(e, nullptr);
      EXPECT_EQ(e->bits, raw & 0xFF);
      EXPECT_TRUE(e->access & (p.tx ? od_access::txpdo : od_access::rxpdo));
      bits += static_cast<int>(raw & 0xFF);
    }
    EXPECT_EQ(bits, p.bytes * 8);
    const auto comm = static_cast<std::uint16_t>(p.map - 0x200);
    EXPECT_EQ(od.entry(comm, 2)->as_int(), p.transmission);
    const bool disabled = od.entry(comm, 1)->as_int() & cob::invalid;
    EXPECT_EQ(disabled, p.entries.empty());
  }
  // TPDO communication: inhibit time (3), event timer (5), SYNC start value (6); no sub 4.
  for (std::uint8_t s : {3, 5, 6}) EXPECT_NE(od.entry(0x1800, s), nullptr);
  EXPECT_EQ(od.entry(0x1800, 4), nullptr);
  EXPECT_EQ(od.entry(0x1800, 0)->as_int(), 6);
}

TEST(CoEds, DeviceNameNeedsSegmentedSdo) {
  ObjectDictionary od;
  add_to_od(load_eds(model()), 5, od);
  std::size_t len = 0;
  ASSERT_EQ(od.read_size(0x1008, 0, OdState::preop, len), SdoAbort::none);
  EXPECT_GT(len, 4u);
  std::array<std::uint8_t, 64> buf{};
  ASSERT_EQ(od.read(0x1008, 0, OdState::preop, buf, len), SdoAbort::none);
  EXPECT_EQ(std::string(buf.begin(), buf.begin() + static_cast<std::ptrdiff_t>(len)), "omnitwin CiA 402 drive");
  EXPECT_EQ(od.entry(0x1008, 0)->data_type, data_type::visible_string);
  EXPECT_EQ(od.write(0x1008, 0, OdState::preop, std::span<const std::uint8_t>(buf.data(), 2)), SdoAbort::read_only);
}

TEST(CoEds, IniRulesCaseCommentsCrLf) {
  const std::string text =
      "; leading comment\r\n[deviceinfo]\r\nvendorname=v\r\nVENDORNUMBER=017\r\nProductName=p ; not a comment\r\n"
      "productnumber=0x2\r\n[MANDATORYOBJECTS]\r\nsupportedobjects=1\r\n1=0x1000\r\n"
      "  ; indented comment\r\n[1000]\r\nparametername=Device type\r\ndatatype=7\r\naccesstype=RO\r\n"
      "defaultvalue=0x192\r\n[Tools]\r\nAnything=goes\r\n";
  const EdsDevice d = parse_eds(text, "t.eds");
  EXPECT_EQ(d.device_info.vendor_number, 017u);  // octal
  EXPECT_EQ(d.device_info.product_name, "p ; not a comment");
  ASSERT_EQ(d.objects.size(), 1u);
  EXPECT_EQ(d.objects[0].name, "Device type");
  EXPECT_EQ(d.objects[0].entries[0].access, EdsAccess::ro);
  EXPECT_EQ(d.objects[0].entries[0].default_value->number, 0x192);
  EXPECT_TRUE(d.optional.empty());
}

TEST(CoEds, ValueFormsAndLimits) {
  const std::string text = device(
      7, "1=0x2000\n2=0x2001\n3=0x2002\n4=0x2003\n5=0x2004\n6=0x2005\n7=0x2006",
      "[2000]\nParameterName=a\nDataType=0x0003\nAccessType=rw\nDefaultValue=0xFFFE\nLowLimit=-100\nHighLimit=100\n"
      "[2001]\nParameterName=b\nDataType=0x0007\nAccessType=rw\nDefaultValue=0x180+$NODEID\n"
      "[2002]\nParameterName=c\nDataType=0x0005\nAccessType=ro\nDefaultValue=$nodeid\n"
      "[2003]\nParameterName=d\nDataType=0x0008\nAccessType=rw\nDefaultValue=1.5\n"
      "[2004]\nParameterName=e\nDataType=0x000A\nAccessType=ro\nDefaultValue=01 02 0A\n"
      "[2005]\nParameterName=f\nDataType=0x0002\nAccessType=wo\nPDOMapping=1\nDefaultValue=-128\n"
      "[2006]\nParameterName=g\nDataType=0x0001\nAccessType=rww\nPDOMapping=1\nDefaultValue=1\n");
  ObjectDictionary od;
  add_to_od(parse_eds(text, "t.eds"), 9, od);
  const OdEntry* a = od.entry(0x2000, 0);
  EXPECT_EQ(a->as_int(), -2);  // hex bit pattern of a signed type
  EXPECT_EQ(a->min, -100);
  EXPECT_EQ(a->max, 100);
  const std::uint8_t too_high[2] = {101, 0}, ok[2] = {100, 0};
  EXPECT_EQ(od.write(0x2000, 0, OdState::preop, too_high), SdoAbort::value_range);
  EXPECT_EQ(od.write(0x2000, 0, OdState::preop, ok), SdoAbort::none);
  EXPECT_EQ(od.entry(0x2001, 0)->as_int(), 0x189);
  EXPECT_EQ(od.entry(0x2002, 0)->as_int(), 9);
  const OdEntry* real = od.entry(0x2003, 0);
  EXPECT_EQ(real->as_int(), 0x3FC00000);  // 1.5f
  EXPECT_FALSE(real->min.has_value());
  const OdEntry* oct = od.entry(0x2004, 0);
  EXPECT_EQ(oct->default_value, (std::vector<std::uint8_t>{1, 2, 10}));
  EXPECT_EQ(oct->bits, 24);
  EXPECT_EQ(od.entry(0x2005, 0)->as_int(), -128);
  EXPECT_EQ(od.entry(0x2005, 0)->access, od_access::write_all | od_access::rxpdo);
  EXPECT_EQ(od.entry(0x2006, 0)->bits, 1);
  EXPECT_EQ(od.entry(0x2006, 0)->as_int(), 1);
}

TEST(CoEds, ObjectTypesInTheDictionary) {
  const std::string text = device(
      2, "1=0x2000\n2=0x2001",
      "[2000]\nParameterName=arr\nObjectType=0x8\nDataType=0x0006\nSubNumber=3\n"
      "[2000sub0]\nParameterName=n\nDataType=0x0005\nAccessType=ro\nDefaultValue=2\n"
      "[2000sub2]\nParameterName=y\nDataType=0x0006\nAccessType=rw\nDefaultValue=20\n"
      "[2000sub1]\nParameterName=x\nDataType=0x0006\nAccessType=rw\nDefaultValue=10\n"
      "[2001]\nParameterName=type\nObjectType=0x5\nDataType=0x0007\nAccessType=ro\nDefaultValue=32\n");
  const EdsDevice d = parse_eds(text, "t.eds");
  const EdsObject* arr = d.object(0x2000);
  ASSERT_NE(arr, nullptr);
  ASSERT_EQ(arr->entries.size(), 3u);
  EXPECT_EQ(arr->entries[1].name, "x");  // sorted by subindex
  EXPECT_EQ(d.object(0x2001)->object_type, 5);
  ObjectDictionary od;
  add_to_od(d, 1, od);
  EXPECT_EQ(od.find(0x2000)->object_code, 8);
  EXPECT_EQ(od.find(0x2000)->data_type, data_type::uint16);
  EXPECT_EQ(od.entry(0x2000, 2)->as_int(), 20);
  EXPECT_EQ(od.find(0x2001), nullptr);  // DEFTYPE: a definition, no value
}

// ---- errors -------------------------------------------------------------------------------------

struct BadFile {
  const char* file;
  const char* offending_line;  // start of the line the message must name
  const char* what;            // "[section] key: ..." part of the message
};

TEST(CoEds, BadFilesNameFileLineAndKey) {
  const BadFile cases[] = {
      {"bad_number.eds", "DefaultValue=0x1G", "[1017] DefaultValue: '0x1G' is not a number"},
      {"bad_access.eds", "AccessType=rx", "[1017] AccessType: 'rx' is not ro, wo, rw, rwr, rww or const"},
      {"bad_datatype.eds", "DataType=0x0099", "[1017] DataType: unknown data type 0x0099"},
      {"missing_section.eds", "1=0x1017", "[OptionalObjects] 1: object 0x1017 has no section [1017]"},
      {"missing_key.eds", "[1017]", "[1017] DataType: missing (required)"},
      {"bad_default.eds", "DefaultValue=70000", "[1017] DefaultValue: '70000' does not fit data type 0x0006"},
      {"bad_subindex.eds", "[1017sub1]", "[1017sub1]: subindex 1 out of range"},
      {"truncated.eds", "Acc", "[1017]: 'Acc' is not key=value"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.file);
    const std::string path = data(c.file);
    const std::string text = read_text(path);
    ASSERT_FALSE(text.empty());
    const int line = line_of(text, c.offending_line, true);
    ASSERT_GT(line, 0);
    const std::string msg = error_of_file(path);
    EXPECT_EQ(msg.rfind(path + ":" + std::to_string(line) + ": " + c.what, 0), 0u) << msg;
  }
}

// A section of many keys is parsed in linear time: the duplicate check used to compare each
// key with every earlier one (32,000 keys took 8.3 s, growing as N²; found in review). 100,000
// keys and a duplicate at the end: the duplicate is still found, in well under the old time.
TEST(CoEds, ASectionOfManyKeysIsParsedInLinearTime) {
  std::string keys = "DataType=0x0005\nAccessType=rw\n";
  for (int k = 0; k < 100'000; ++k) keys += "X" + std::to_string(k) + "=1\n";
  const auto start = std::chrono::steady_clock::now();
  EXPECT_NO_THROW(parse_eds(var2000(keys), "many.eds"));
  try {
    parse_eds(var2000(keys + "x77=2\n"), "many.eds");
    ADD_FAILURE() << "no error";
  } catch (const EdsError& e) {
    EXPECT_NE(std::string(e.what()).find("[2000] x77: given twice (first at line"), std::string::npos) << e.what();
  }
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(10));
}

TEST(CoEds, MissingFileIsLineZero) {
  EXPECT_EQ(error_of_file(data("no_such.eds")), data("no_such.eds") + ":0: cannot open the file");
}

// Found in review: a directory read as an empty file ("section [DeviceInfo] missing").
TEST(CoEds, ADirectoryIsNamedAsOne) {
  EXPECT_EQ(error_of_file(data("")), data("") + ":0: a directory, not a file");
}

TEST(CoEds, InlineErrors) {
  struct Case {
    std::string text, offending, what;
  };
  const Case cases[] = {
      {var2000("DataType=0x0005\nAccessType=rw\nDefaultValue=$NODEID+0x90\n"), "DefaultValue=",
       "[2000] DefaultValue: '$NODEID+0x90' does not fit data type 0x0005 for every node ID"},
      {var2000("DataType=0x0005\nAccessType=rw\nDefaultValue=$NODEID-1\n"), "DefaultValue=",
       "[2000] DefaultValue: '$NODEID-1': only $NODEID"},
      {var2000("DataType=0x0005\nAccessType=rw\nDefaultValue=50\nLowLimit=1\nHighLimit=10\n"), "DefaultValue=",
       "[2000] DefaultValue: 50 outside LowLimit..HighLimit"},
      {var2000("DataType=0x0005\nAccessType=rw\nLowLimit=10\nHighLimit=1\n"), "HighLimit=",
       "[2000] HighLimit: 1 is below LowLimit 10"},
      {var2000("DataType=0x0002\nAccessType=rw\nDefaultValue=128\n"), "DefaultValue=",
       "[2000] DefaultValue: '128' does not fit data type 0x0002 (8 bits, signed)"},
      {var2000("DataType=0x0005\nAccessType=rw\nPDOMapping=2\n"), "PDOMapping=", "[2000] PDOMapping: 2 outside 0..1"},
      {var2000("DataType=0x0009\nAccessType=ro\nLowLimit=1\n"), "LowLimit=",
       "[2000] LowLimit: limits are supported for integer data types only"},
      {var2000("ObjectType=0x3\nDataType=0x0005\nAccessType=rw\n"), "ObjectType=", "[2000] ObjectType: 0x3 is not"},
      {var2000("DataType=0x0005\nAccessType=rw\nAccessType=ro\n"), "AccessType=ro",
       "[2000] AccessType: given twice (first at line"},
      {var2000("ObjectType=0x8\nSubNumber=2\nCompactSubObj=3\n"), "CompactSubObj=",
       "[2000] CompactSubObj: compact sub-objects are not supported"},
      {var2000("ObjectType=0x9\nSubNumber=2\n[2000sub0]\nParameterName=n\nDataType=5\nAccessType=ro\n"), "SubNumber=",
       "[2000] SubNumber: 2 but 1 sub-object sections"},
      {var2000("ObjectType=0x9\nSubNumber=1\n[2000sub1]\nParameterName=n\nDataType=5\nAccessType=ro\n"), "[2000]",
       "[2000]: sub-object section for subindex 0 missing"},
      {var2000("ObjectType=0x8\nSubNumber=2\n[2000sub0]\nParameterName=n\nDataType=5\nAccessType=ro\n"
               "[2000sub5]\nParameterName=n\nDataType=5\nAccessType=ro\n"),
       "[2000sub5]", "[2000sub5]: subindex 5 out of range: the ARRAY has SubNumber=2"},
      {var2000("DataType=0x0005\nAccessType=rw\n[2001]\nParameterName=y\nDataType=5\nAccessType=ro\n"), "[2001]",
       "[2001]: object not listed in [MandatoryObjects], [OptionalObjects] or [ManufacturerObjects]"},
      {device(1, "1=0x1000", ""), "1=0x1000", "[OptionalObjects] 1: object 0x1000 listed twice"},
      {device(2, "1=0x2000", "[2000]\nParameterName=x\nDataType=5\nAccessType=ro\n"), "[OptionalObjects]",
       "[OptionalObjects] 2: missing (SupportedObjects=2)"},
      {var2000("DataType=0x0005\nAccessType=rw\n[2000]\nParameterName=again\n"), "[2000]\nParameterName=again",
       "[2000]: section given twice"},
      {var2000("DataType=0x0005\nAccessType=rw\n[2000sub\n"), "[2000sub", "section header '[2000sub' lacks ']'"},
      {"VendorName=x\n[DeviceInfo]\n", "VendorName=x", "'VendorName=x' before the first [section]"},
      {"[MandatoryObjects]\nSupportedObjects=0\n", "[MandatoryObjects]", "section [DeviceInfo] missing"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.what);
    // The line: the offending text's first occurrence in the part that varies (from
    // [OptionalObjects] on, or the whole text where there is none).
    const auto from = c.text.find("[OptionalObjects]");
    const auto at = c.text.find(c.offending, from == std::string::npos ? 0 : from);
    ASSERT_NE(at, std::string::npos);
    const int line = 1 + static_cast<int>(std::count(c.text.begin(), c.text.begin() + static_cast<std::ptrdiff_t>(at), '\n'));
    const std::string msg = error_of_text(c.text);
    EXPECT_EQ(msg.rfind("t.eds:" + std::to_string(line) + ": " + c.what, 0), 0u) << msg;
  }
}

TEST(CoEds, DomainCannotBeBuilt) {
  const EdsDevice d = parse_eds(var2000("DataType=0x000F\nAccessType=rw\nDefaultValue=0102\n"), "t.eds");
  EXPECT_EQ(d.object(0x2000)->entries[0].default_value->bytes, (std::vector<std::uint8_t>{1, 2}));
  ObjectDictionary od;
  try {
    add_to_od(d, 1, od);
    FAIL() << "DOMAIN accepted";
  } catch (const EdsError& e) {
    const std::string t = var2000("");
    EXPECT_EQ(std::string(e.what()).rfind("t.eds:" + std::to_string(line_of(t, "[2000]")) + ": [2000] DataType: DOMAIN", 0), 0u)
        << e.what();
  }
}

}  // namespace
}  // namespace omnitwin::canopen
