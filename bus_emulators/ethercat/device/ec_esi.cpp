// bus_emulators/ethercat/device — ESI XML parser (see ec_esi.hpp).
#include "bus_emulators/ethercat/device/ec_esi.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <map>
#include <pugixml.hpp>
#include <sstream>

namespace omnitwin::ethercat {

const char* to_string(SmKind k) {
  switch (k) {
    case SmKind::unused: return "unused";
    case SmKind::mbox_out: return "MBoxOut";
    case SmKind::mbox_in: return "MBoxIn";
    case SmKind::outputs: return "Outputs";
    case SmKind::inputs: return "Inputs";
  }
  return "?";
}

std::uint32_t EsiPdo::bit_size() const {
  std::uint32_t bits = 0;
  for (const auto& e : entries) bits += e.bit_length;
  return bits;
}

const EsiObject* DeviceDescription::object(std::uint16_t index) const {
  for (const auto& o : objects)
    if (o.index == index) return &o;
  return nullptr;
}

const EsiPdo* DeviceDescription::pdo(std::uint16_t index) const {
  for (const auto& p : rx_pdos)
    if (p.index == index) return &p;
  for (const auto& p : tx_pdos)
    if (p.index == index) return &p;
  return nullptr;
}

int DeviceDescription::sm_of_kind(SmKind k) const {
  for (std::size_t i = 0; i < sms.size(); ++i)
    if (sms[i].kind == k) return static_cast<int>(i);
  return -1;
}

std::optional<std::int64_t> parse_esi_number(const std::string& text) {
  std::size_t b = 0, e = text.size();
  while (b < e && std::isspace(static_cast<unsigned char>(text[b]))) ++b;
  while (e > b && std::isspace(static_cast<unsigned char>(text[e - 1]))) --e;
  if (b == e) return std::nullopt;
  bool neg = false;
  if (text[b] == '-') {
    neg = true;
    ++b;
  }
  int base = 10;
  if (e - b > 2 && text[b] == '#' && (text[b + 1] == 'x' || text[b + 1] == 'X')) {
    base = 16;
    b += 2;
  } else if (e - b > 2 && text[b] == '0' && (text[b + 1] == 'x' || text[b + 1] == 'X')) {
    base = 16;
    b += 2;
  }
  if (b == e) return std::nullopt;
  std::uint64_t v = 0;
  for (std::size_t i = b; i < e; ++i) {
    const char c = text[i];
    int d;
    if (c >= '0' && c <= '9') d = c - '0';
    else if (base == 16 && c >= 'a' && c <= 'f') d = c - 'a' + 10;
    else if (base == 16 && c >= 'A' && c <= 'F') d = c - 'A' + 10;
    else return std::nullopt;
    if (v > (UINT64_MAX - static_cast<std::uint64_t>(d)) / static_cast<std::uint64_t>(base)) return std::nullopt;
    v = v * static_cast<std::uint64_t>(base) + static_cast<std::uint64_t>(d);
  }
  return neg ? -static_cast<std::int64_t>(v) : static_cast<std::int64_t>(v);
}

std::uint16_t esi_type_bits(const std::string& type) {
  static const std::map<std::string, std::uint16_t> kBits = {
      {"BOOL", 1},   {"BIT", 1},     {"SINT", 8},    {"USINT", 8},   {"BYTE", 8},  {"INT", 16},
      {"UINT", 16},  {"WORD", 16},   {"DINT", 32},   {"UDINT", 32},  {"DWORD", 32}, {"REAL", 32},
      {"LINT", 64},  {"ULINT", 64},  {"LREAL", 64},  {"INT24", 24},  {"UINT24", 24}};
  if (auto it = kBits.find(type); it != kBits.end()) return it->second;
  if (type.size() >= 4 && type.compare(0, 3, "BIT") == 0) {
    auto n = parse_esi_number(type.substr(3));
    if (n && *n >= 1 && *n <= 8) return static_cast<std::uint16_t>(*n);
  }
  const auto open = type.find('(');
  if (open != std::string::npos && type.back() == ')') {
    auto n = parse_esi_number(type.substr(open + 1, type.size() - open - 2));
    if (n && *n > 0 && *n < 4096) return static_cast<std::uint16_t>(*n * 8);
  }
  return 0;
}

namespace {

// Context of one parse: the text (for line numbers) and the name used in messages.
struct Ctx {
  const std::string& xml;
  const std::string& name;

  int line_of(std::ptrdiff_t offset) const {
    if (offset < 0) return 0;
    const auto end = std::min<std::size_t>(static_cast<std::size_t>(offset), xml.size());
    return 1 + static_cast<int>(std::count(xml.begin(), xml.begin() + static_cast<std::ptrdiff_t>(end), '\n'));
  }
  [[noreturn]] void fail(const pugi::xml_node& n, const std::string& what) const {
    throw EsiError(fmt::format("{}:{}: {}", name, line_of(n.offset_debug()), what));
  }
  std::string text(const pugi::xml_node& n, const char* child) const {
    return n.child(child).text().as_string();
  }
  std::int64_t number(const pugi::xml_node& at, const std::string& s, const char* what) const {
    auto v = parse_esi_number(s);
    if (!v) fail(at, fmt::format("{}: '{}' is not a number", what, s));
    return *v;
  }
  std::int64_t child_number(const pugi::xml_node& n, const char* child, const char* what) const {
    auto c = n.child(child);
    if (!c) fail(n, fmt::format("{} missing", what));
    return number(c, c.text().as_string(), what);
  }
  std::int64_t attr_number(const pugi::xml_node& n, const char* attr, std::int64_t dflt) const {
    auto a = n.attribute(attr);
    if (!a) return dflt;
    return number(n, a.as_string(), attr);
  }
  bool attr_bool(const pugi::xml_node& n, const char* attr) const {
    auto a = n.attribute(attr);
    if (!a) return false;
    const std::string v = a.as_string();
    if (v == "1" || v == "true") return true;
    if (v == "0" || v == "false") return false;
    fail(n, fmt::format("attribute {}: '{}' is not a boolean", attr, v));
  }
  std::vector<std::uint8_t> hex_bytes(const pugi::xml_node& n) const {
    std::string s = n.text().as_string();
    s.erase(std::remove_if(s.begin(), s.end(), [](char c) { return std::isspace(static_cast<unsigned char>(c)); }), s.end());
    if (s.size() % 2 != 0) fail(n, fmt::format("DefaultData '{}' has an odd number of hex digits", s));
    std::vector<std::uint8_t> out;
    for (std::size_t i = 0; i < s.size(); i += 2) {
      auto v = parse_esi_number("#x" + s.substr(i, 2));
      if (!v) fail(n, fmt::format("DefaultData '{}' is not hex", s));
      out.push_back(static_cast<std::uint8_t>(*v));
    }
    return out;
  }
};

std::uint16_t parse_flags(const Ctx& c, const pugi::xml_node& flags, std::uint16_t dflt) {
  if (!flags) return dflt;
  std::uint16_t a = 0;
  auto acc = flags.child("Access");
  if (!acc) {
    a = dflt & (od_access::read_all | od_access::write_all);
  } else {
    const std::string t = acc.text().as_string();
    std::uint16_t rd = 0, wr = 0;
    if (t == "ro") rd = od_access::read_all;
    else if (t == "rw") rd = od_access::read_all, wr = od_access::write_all;
    else if (t == "wo") wr = od_access::write_all;
    else c.fail(acc, fmt::format("Access '{}' is not ro, rw or wo", t));
    auto restrict_to = [&](const char* attr, std::uint16_t bits_preop, std::uint16_t bits_safeop,
                           std::uint16_t bits_op, std::uint16_t& v) {
      auto r = acc.attribute(attr);
      if (!r) return;
      const std::string s = r.as_string();
      std::uint16_t keep = 0;
      if (s.find("PreOP") != std::string::npos) keep |= bits_preop;
      if (s.find("SafeOP") != std::string::npos) keep |= bits_safeop;
      if (s == "OP" || s.find("_OP") != std::string::npos) keep |= bits_op;
      v &= keep;
    };
    restrict_to("ReadRestrictions", od_access::read_preop, od_access::read_safeop, od_access::read_op, rd);
    restrict_to("WriteRestrictions", od_access::write_preop, od_access::write_safeop, od_access::write_op, wr);
    a = rd | wr;
  }
  if (auto pm = flags.child("PdoMapping")) {
    const std::string t = pm.text().as_string();
    for (char ch : t) {
      if (ch == 'R' || ch == 'r') a |= od_access::rxpdo;
      else if (ch == 'T' || ch == 't') a |= od_access::txpdo;
      else c.fail(pm, fmt::format("PdoMapping '{}' is not R, T or RT", t));
    }
  }
  if (flags.child("Backup")) a |= od_access::backup;
  if (flags.child("Setting")) a |= od_access::setting;
  return a;
}

struct DataTypeDef {
  pugi::xml_node node;
  std::string name;
  std::uint16_t bits = 0;
};

using TypeMap = std::map<std::string, DataTypeDef>;

std::uint16_t type_bits(const TypeMap& types, const std::string& t) {
  if (auto it = types.find(t); it != types.end() && it->second.bits) return it->second.bits;
  return esi_type_bits(t);
}

EsiObject parse_object(const Ctx& c, const pugi::xml_node& o, const TypeMap& types) {
  EsiObject obj;
  obj.index = static_cast<std::uint16_t>(c.child_number(o, "Index", "Object Index"));
  obj.name = c.text(o, "Name");
  obj.data_type = c.text(o, "Type");
  if (obj.data_type.empty()) c.fail(o, fmt::format("object {:#06x}: Type missing", obj.index));
  const std::uint16_t obj_access = parse_flags(c, o.child("Flags"), od_access::read_all);
  auto info = o.child("Info");
  auto dt = types.find(obj.data_type);
  const bool complex = dt != types.end() && (dt->second.node.child("SubItem") || dt->second.node.child("ArrayInfo"));
  if (!complex) {
    EsiObjectEntry e;
    e.subindex = 0;
    e.name = obj.name;
    e.data_type = obj.data_type;
    e.bit_size = o.child("BitSize") ? static_cast<std::uint16_t>(c.child_number(o, "BitSize", "BitSize"))
                                     : type_bits(types, obj.data_type);
    if (e.bit_size == 0) c.fail(o, fmt::format("object {:#06x}: unknown type '{}'", obj.index, obj.data_type));
    e.access = obj_access;
    if (info && info.child("DefaultData")) e.default_data = c.hex_bytes(info.child("DefaultData"));
    obj.object_code = 7;
    obj.entries.push_back(std::move(e));
    return obj;
  }
  // Record or array: sub-items from the DataType, defaults from Info/SubItem in order.
  std::vector<pugi::xml_node> info_subs;
  for (auto s : info.children("SubItem")) info_subs.push_back(s);
  auto info_for = [&](std::size_t pos, const std::string& name) -> pugi::xml_node {
    for (auto s : info_subs)
      if (name == s.child("Name").text().as_string()) return s;
    return pos < info_subs.size() ? info_subs[pos] : pugi::xml_node();
  };
  const auto& tn = dt->second.node;
  std::size_t pos = 0;
  for (auto si : tn.children("SubItem")) {
    const std::string sub_type = si.child("Type").text().as_string();
    const std::string sub_name = si.child("Name").text().as_string();
    auto sub_dt = types.find(sub_type);
    const bool is_array = sub_dt != types.end() && sub_dt->second.node.child("ArrayInfo");
    if (is_array) {
      // An array member (ETG style: "Elements" sub-item of an ARRAY type): one entry per element.
      obj.object_code = 8;
      auto ai = sub_dt->second.node.child("ArrayInfo");
      const auto lbound = c.child_number(ai, "LBound", "ArrayInfo LBound");
      const auto elements = c.child_number(ai, "Elements", "ArrayInfo Elements");
      const std::string base = sub_dt->second.node.child("BaseType").text().as_string();
      const std::uint16_t bits = type_bits(types, base);
      if (bits == 0) c.fail(sub_dt->second.node, fmt::format("unknown BaseType '{}'", base));
      // Each element is a subindex (1..255): a larger array cannot be an object's entries.
      if (lbound < 0 || elements < 0 || lbound + elements > 256)
        c.fail(ai, fmt::format("ArrayInfo LBound {} and Elements {} do not fit subindices 0..255", lbound, elements));
      for (std::int64_t k = 0; k < elements; ++k) {
        EsiObjectEntry e;
        e.subindex = static_cast<std::uint8_t>(lbound + k);
        e.name = fmt::format("{} {}", sub_name, k + 1);
        e.data_type = base;
        e.bit_size = bits;
        e.access = parse_flags(c, si.child("Flags"), obj_access);
        auto inf = info_for(pos, e.name);
        if (inf && inf.child("Info").child("DefaultData")) e.default_data = c.hex_bytes(inf.child("Info").child("DefaultData"));
        obj.entries.push_back(std::move(e));
        ++pos;
      }
      continue;
    }
    if (obj.object_code == 7) obj.object_code = 9;
    EsiObjectEntry e;
    auto subidx = si.child("SubIdx");
    e.subindex = subidx ? static_cast<std::uint8_t>(c.number(subidx, subidx.text().as_string(), "SubIdx"))
                        : static_cast<std::uint8_t>(pos);
    e.name = sub_name;
    e.data_type = sub_type;
    e.bit_size = si.child("BitSize") ? static_cast<std::uint16_t>(c.child_number(si, "BitSize", "BitSize"))
                                      : type_bits(types, sub_type);
    if (e.bit_size == 0) c.fail(si, fmt::format("sub-item '{}': unknown type '{}'", sub_name, sub_type));
    e.access = parse_flags(c, si.child("Flags"), obj_access);
    auto inf = info_for(pos, sub_name);
    if (inf && inf.child("Info").child("DefaultData")) e.default_data = c.hex_bytes(inf.child("Info").child("DefaultData"));
    obj.entries.push_back(std::move(e));
    ++pos;
  }
  if (obj.entries.empty()) c.fail(o, fmt::format("object {:#06x}: type '{}' has no sub-items", obj.index, obj.data_type));
  return obj;
}

EsiPdo parse_pdo(const Ctx& c, const pugi::xml_node& p) {
  EsiPdo pdo;
  pdo.index = static_cast<std::uint16_t>(c.child_number(p, "Index", "PDO Index"));
  pdo.name = c.text(p, "Name");
  pdo.sm = static_cast<int>(c.attr_number(p, "Sm", -1));
  pdo.fixed = c.attr_bool(p, "Fixed");
  pdo.mandatory = c.attr_bool(p, "Mandatory");
  for (auto en : p.children("Entry")) {
    EsiPdoEntry e;
    e.index = static_cast<std::uint16_t>(c.child_number(en, "Index", "Entry Index"));
    e.subindex = e.index ? static_cast<std::uint8_t>(c.child_number(en, "SubIndex", "Entry SubIndex")) : 0;
    const auto bits = c.child_number(en, "BitLen", "Entry BitLen");
    if (bits <= 0 || bits > 64) c.fail(en, fmt::format("Entry BitLen {} out of range 1..64", bits));
    e.bit_length = static_cast<std::uint8_t>(bits);
    e.name = c.text(en, "Name");
    e.data_type = c.text(en, "DataType");
    pdo.entries.push_back(std::move(e));
  }
  return pdo;
}

DeviceDescription parse_device(const Ctx& c, const pugi::xml_node& d, std::uint32_t vendor,
                               const std::string& vendor_name) {
  DeviceDescription dev;
  dev.vendor_id = vendor;
  dev.vendor_name = vendor_name;
  dev.source = c.name;
  auto type = d.child("Type");
  if (!type) c.fail(d, "Device: Type missing");
  if (!type.attribute("ProductCode")) c.fail(type, "Type: ProductCode missing");
  dev.product_code = static_cast<std::uint32_t>(c.attr_number(type, "ProductCode", 0));
  dev.revision = static_cast<std::uint32_t>(c.attr_number(type, "RevisionNo", 0));
  dev.type_name = type.text().as_string();
  dev.name = c.text(d, "Name");
  if (dev.name.empty()) dev.name = dev.type_name;
  dev.group = c.text(d, "GroupType");
  for (auto f : d.children("Fmmu")) {
    const std::string t = f.text().as_string();
    if (t == "Outputs") dev.fmmus.push_back(SmKind::outputs);
    else if (t == "Inputs") dev.fmmus.push_back(SmKind::inputs);
    else if (t == "MBoxState") dev.fmmus.push_back(SmKind::mbox_in);
    else c.fail(f, fmt::format("Fmmu '{}' is not Outputs, Inputs or MBoxState", t));
  }
  for (auto s : d.children("Sm")) {
    EsiSyncManager sm;
    sm.start = static_cast<std::uint16_t>(c.attr_number(s, "StartAddress", 0));
    sm.size = static_cast<std::uint16_t>(c.attr_number(s, "DefaultSize", 0));
    sm.control = static_cast<std::uint8_t>(c.attr_number(s, "ControlByte", 0));
    sm.enable = c.attr_number(s, "Enable", 0) != 0;
    const std::string t = s.text().as_string();
    if (t == "MBoxOut") sm.kind = SmKind::mbox_out;
    else if (t == "MBoxIn") sm.kind = SmKind::mbox_in;
    else if (t == "Outputs") sm.kind = SmKind::outputs;
    else if (t == "Inputs") sm.kind = SmKind::inputs;
    else if (t.empty()) sm.kind = SmKind::unused;
    else c.fail(s, fmt::format("Sm '{}' is not MBoxOut, MBoxIn, Outputs or Inputs", t));
    if (!s.attribute("StartAddress")) c.fail(s, "Sm: StartAddress missing");
    dev.sms.push_back(sm);
  }
  for (auto p : d.children("RxPdo")) dev.rx_pdos.push_back(parse_pdo(c, p));
  for (auto p : d.children("TxPdo")) dev.tx_pdos.push_back(parse_pdo(c, p));
  for (const auto& p : dev.rx_pdos)
    if (p.index < 0x1600 || p.index > 0x17FF) c.fail(d, fmt::format("RxPdo {:#06x} outside 0x1600..0x17FF", p.index));
  for (const auto& p : dev.tx_pdos)
    if (p.index < 0x1A00 || p.index > 0x1BFF) c.fail(d, fmt::format("TxPdo {:#06x} outside 0x1A00..0x1BFF", p.index));

  if (auto coe = d.child("Mailbox").child("CoE")) {
    dev.coe.present = true;
    dev.coe.sdo_info = c.attr_bool(coe, "SdoInfo");
    dev.coe.complete_access = c.attr_bool(coe, "CompleteAccess");
    dev.coe.pdo_assign = c.attr_bool(coe, "PdoAssign");
    dev.coe.pdo_config = c.attr_bool(coe, "PdoConfig");
    dev.coe.pdo_upload = c.attr_bool(coe, "PdoUpload");
    if (coe.attribute("SegmentedSdo")) dev.coe.segmented_sdo = c.attr_bool(coe, "SegmentedSdo");
  }
  for (auto m : d.child("Dc").children("OpMode")) {
    EsiDcOpMode op;
    op.name = c.text(m, "Name");
    op.desc = c.text(m, "Desc");
    if (m.child("AssignActivate")) op.assign_activate = static_cast<std::uint16_t>(c.child_number(m, "AssignActivate", "AssignActivate"));
    if (m.child("CycleTimeSync0")) op.cycle_time_sync0 = static_cast<std::uint32_t>(c.child_number(m, "CycleTimeSync0", "CycleTimeSync0"));
    if (m.child("ShiftTimeSync0")) op.shift_time_sync0 = static_cast<std::int32_t>(c.child_number(m, "ShiftTimeSync0", "ShiftTimeSync0"));
    if (m.child("CycleTimeSync1")) op.cycle_time_sync1 = static_cast<std::uint32_t>(c.child_number(m, "CycleTimeSync1", "CycleTimeSync1"));
    dev.dc.push_back(std::move(op));
  }
  if (auto ee = d.child("Eeprom"); ee && ee.child("ByteSize")) {
    const auto bytes = c.child_number(ee, "ByteSize", "Eeprom ByteSize");
    if (bytes < 128 || bytes > 65536 || (bytes & (bytes - 1)) != 0)
      c.fail(ee, fmt::format("Eeprom ByteSize {} is not a power of two in 128..65536", bytes));
    dev.eeprom_bytes = static_cast<std::uint32_t>(bytes);
  }
  if (auto cd = d.child("Eeprom").child("ConfigData")) {
    dev.eeprom_config = c.hex_bytes(cd);
    if (dev.eeprom_config.size() > 14) c.fail(cd, "Eeprom ConfigData longer than 14 bytes");
  }
  if (auto prof = d.child("Profile")) {
    if (prof.child("ProfileNo")) dev.profile = static_cast<int>(c.child_number(prof, "ProfileNo", "ProfileNo"));
    if (prof.child("ChannelCount")) {
      dev.axes = static_cast<int>(c.child_number(prof, "ChannelCount", "ChannelCount"));
      if (dev.axes < 1 || dev.axes > 8) c.fail(prof, fmt::format("ChannelCount {} outside 1..8", dev.axes));
    }
    auto dict = prof.child("Dictionary");
    TypeMap types;
    for (auto t : dict.child("DataTypes").children("DataType")) {
      DataTypeDef def;
      def.node = t;
      def.name = t.child("Name").text().as_string();
      if (def.name.empty()) c.fail(t, "DataType: Name missing");
      if (t.child("BitSize")) def.bits = static_cast<std::uint16_t>(c.child_number(t, "BitSize", "BitSize"));
      types[def.name] = def;
    }
    for (auto o : dict.child("Objects").children("Object")) {
      auto obj = parse_object(c, o, types);
      if (dev.object(obj.index)) c.fail(o, fmt::format("object {:#06x} defined twice", obj.index));
      dev.objects.push_back(std::move(obj));
    }
    std::sort(dev.objects.begin(), dev.objects.end(),
              [](const EsiObject& a, const EsiObject& b) { return a.index < b.index; });
  }
  return dev;
}

}  // namespace

std::vector<DeviceDescription> parse_esi(const std::string& xml, const std::string& name) {
  Ctx c{xml, name};
  pugi::xml_document doc;
  const auto res = doc.load_buffer(xml.data(), xml.size(), pugi::parse_default, pugi::encoding_auto);
  if (!res) throw EsiError(fmt::format("{}:{}: malformed XML: {}", name, c.line_of(res.offset), res.description()));
  auto root = doc.child("EtherCATInfo");
  if (!root) throw EsiError(fmt::format("{}:1: root element EtherCATInfo missing", name));
  auto vendor = root.child("Vendor");
  if (!vendor) c.fail(root, "Vendor missing");
  auto id = vendor.child("Id");
  if (!id) c.fail(vendor, "Vendor: Id missing");
  const auto vid = c.number(id, id.text().as_string(), "Vendor Id");
  const std::string vname = vendor.child("Name").text().as_string();
  auto devices = root.child("Descriptions").child("Devices");
  std::vector<DeviceDescription> out;
  for (auto d : devices.children("Device")) out.push_back(parse_device(c, d, static_cast<std::uint32_t>(vid), vname));
  if (out.empty()) c.fail(root, "no Descriptions/Devices/Device");
  return out;
}

std::vector<DeviceDescription> load_esi(const std::string& path) {
  // A directory opens as a stream of nothing on Linux: name it, not its "missing" contents.
  if (std::filesystem::is_directory(path)) throw EsiError(fmt::format("{}:0: a directory, not a file", path));
  std::ifstream in(path, std::ios::binary);
  if (!in) throw EsiError(fmt::format("{}:0: cannot open the file", path));
  std::ostringstream ss;
  ss << in.rdbuf();
  return parse_esi(ss.str(), path);
}

}  // namespace omnitwin::ethercat
