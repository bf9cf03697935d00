// bus_emulators/canopen — CiA 306 EDS parser and object dictionary builder (see co_eds.hpp).
//
// Two passes: the INI text is split into sections of keys (with their line numbers, so that
// every error can name the line), then the sections are read as CiA 306 objects.
#include "bus_emulators/canopen/co_eds.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <string_view>
#include <unordered_map>
#include <utility>

namespace omnitwin::canopen {

const char* to_string(EdsAccess a) {
  switch (a) {
    case EdsAccess::ro: return "ro";
    case EdsAccess::wo: return "wo";
    case EdsAccess::rw: return "rw";
    case EdsAccess::rwr: return "rwr";
    case EdsAccess::rww: return "rww";
    case EdsAccess::const_: return "const";
  }
  return "?";
}

const EdsEntry* EdsObject::entry(std::uint8_t sub) const {
  for (const auto& e : entries)
    if (e.subindex == sub) return &e;
  return nullptr;
}

bool EdsDeviceInfo::supports_baud(int kbit_s) const {
  for (int i = 0; i < 8; ++i)
    if (kBaudRates[i] == kbit_s) return (baud_rates >> i) & 1u;
  return false;
}

const EdsObject* EdsDevice::object(std::uint16_t index) const {
  auto it = std::lower_bound(objects.begin(), objects.end(), index,
                             [](const EdsObject& o, std::uint16_t i) { return o.index < i; });
  return it != objects.end() && it->index == index ? &*it : nullptr;
}

namespace {

std::string lower(std::string_view s) {
  std::string out(s);
  for (char& ch : out) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  return out;
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
  return s;
}

// A number as written: magnitude, sign and whether it was decimal (signed types read hex and
// octal as bit patterns).
struct RawNumber {
  std::uint64_t magnitude = 0;
  bool negative = false, decimal = true;
};

std::optional<RawNumber> parse_raw(std::string_view t) {
  t = trim(t);
  RawNumber r;
  if (!t.empty() && t.front() == '-') {
    r.negative = true;
    t.remove_prefix(1);
  }
  int base = 10;
  if (t.size() > 2 && t[0] == '0' && (t[1] == 'x' || t[1] == 'X')) {
    base = 16;
    t.remove_prefix(2);
  } else if (t.size() > 1 && t[0] == '0') {
    base = 8;
    t.remove_prefix(1);
  }
  if (t.empty()) return std::nullopt;
  // from_chars accepts neither signs nor prefixes here, and must consume every digit.
  if (!std::isxdigit(static_cast<unsigned char>(t.front()))) return std::nullopt;
  auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), r.magnitude, base);
  if (ec != std::errc() || end != t.data() + t.size()) return std::nullopt;
  r.decimal = base == 10;
  return r;
}

}  // namespace

std::optional<std::int64_t> parse_eds_number(const std::string& text) {
  const auto r = parse_raw(text);
  if (!r) return std::nullopt;
  constexpr auto kMax = static_cast<std::uint64_t>(std::numeric_limits<std::int64_t>::max());
  if (r->negative) {
    if (r->magnitude > kMax + 1) return std::nullopt;
    return static_cast<std::int64_t>(0 - r->magnitude);
  }
  if (r->magnitude > kMax) return std::nullopt;
  return static_cast<std::int64_t>(r->magnitude);
}

std::uint16_t eds_type_bits(std::uint16_t t) {
  switch (t) {
    case data_type::boolean: return 1;
    case data_type::int8: case data_type::uint8: return 8;
    case data_type::int16: case data_type::uint16: return 16;
    case 0x0010: case 0x0016: return 24;     // INTEGER24, UNSIGNED24
    case data_type::int32: case data_type::uint32: case data_type::real32: return 32;
    case 0x0012: case 0x0018: return 40;     // INTEGER40, UNSIGNED40
    case 0x000C: case 0x000D: case 0x0013: case 0x0019: return 48;  // TIME_OF_DAY, TIME_DIFFERENCE, (U)INTEGER48
    case 0x0014: case 0x001A: return 56;     // INTEGER56, UNSIGNED56
    case data_type::int64: case data_type::uint64: case 0x0011: return 64;  // REAL64
    default: return 0;
  }
}

std::uint16_t eds_od_access(EdsAccess a, bool pdo_mapping) {
  std::uint16_t bits = 0;
  switch (a) {
    case EdsAccess::ro: case EdsAccess::const_: bits = od_access::read_all; break;
    case EdsAccess::wo: bits = od_access::write_all; break;
    case EdsAccess::rw: case EdsAccess::rwr: case EdsAccess::rww: bits = od_access::rw; break;
  }
  if (!pdo_mapping) return bits;
  switch (a) {
    case EdsAccess::rww: case EdsAccess::wo: return bits | od_access::rxpdo;
    case EdsAccess::rwr: case EdsAccess::ro: case EdsAccess::const_: return bits | od_access::txpdo;
    case EdsAccess::rw: return bits | od_access::rxpdo | od_access::txpdo;
  }
  return bits;
}

namespace {

constexpr std::uint16_t kVisibleString = data_type::visible_string, kOctetString = data_type::octet_string,
                        kUnicodeString = 0x000B, kDomain = 0x000F, kReal64 = 0x0011;

bool is_string_type(std::uint16_t t) {
  return t == kVisibleString || t == kOctetString || t == kUnicodeString || t == kDomain;
}
bool is_real_type(std::uint16_t t) { return t == data_type::real32 || t == kReal64; }
bool is_signed_type(std::uint16_t t) {
  return t == data_type::int8 || t == data_type::int16 || t == data_type::int32 || t == data_type::int64 ||
         (t >= 0x0010 && t <= 0x0014 && t != kReal64);
}
bool known_type(std::uint16_t t) { return eds_type_bits(t) != 0 || is_string_type(t); }

// ---- INI layer -----------------------------------------------------------------------------

struct IniKey {
  std::string name, value;
  int line = 0;
};

struct IniSection {
  std::string name;  // as written
  int line = 0;
  std::vector<IniKey> keys;
  std::unordered_map<std::string, std::size_t> by_name{};  // lower-case key → its place in keys
};

// Context of one parse: the name used in messages.
struct Ctx {
  const std::string& name;

  [[noreturn]] void fail(int line, const std::string& what) const {
    throw EdsError(fmt::format("{}:{}: {}", name, line, what));
  }
  [[noreturn]] void fail(int line, const std::string& section, const std::string& key, const std::string& what) const {
    if (key.empty()) fail(line, fmt::format("[{}]: {}", section, what));
    fail(line, fmt::format("[{}] {}: {}", section, key, what));
  }
};

// Adds one key=value line to the current section (errors: no section yet, no '=', duplicates).
void add_key(const Ctx& c, std::vector<IniSection>& out, std::string_view t, int line) {
  const auto eq = t.find('=');
  if (out.empty()) c.fail(line, fmt::format("'{}' before the first [section]", t));
  IniSection& s = out.back();
  if (eq == std::string_view::npos) c.fail(line, s.name, "", fmt::format("'{}' is not key=value", t));
  IniKey k{std::string(trim(t.substr(0, eq))), std::string(trim(t.substr(eq + 1))), line};
  if (k.name.empty()) c.fail(line, s.name, "", fmt::format("'{}' has no key before '='", t));
  // A hash of the lower-case names: a section of N keys costs N lookups, not N² comparisons.
  if (auto [it, fresh] = s.by_name.emplace(lower(k.name), s.keys.size()); !fresh)
    c.fail(line, s.name, k.name, fmt::format("given twice (first at line {})", s.keys[it->second].line));
  s.keys.push_back(std::move(k));
}

// Splits the text into sections; ';' lines are comments.
std::vector<IniSection> split_ini(const Ctx& c, std::string_view text) {
  std::vector<IniSection> out;
  std::map<std::string, int> seen;  // lower-case name → line
  if (text.substr(0, 3) == "\xEF\xBB\xBF") text.remove_prefix(3);  // UTF-8 byte order mark
  int line = 0;
  while (!text.empty()) {
    const auto nl = text.find('\n');
    const std::string_view raw = text.substr(0, nl);
    text.remove_prefix(nl == std::string_view::npos ? text.size() : nl + 1);
    ++line;
    const std::string_view t = trim(raw);
    if (t.empty() || t.front() == ';') continue;
    if (t.front() != '[') {
      add_key(c, out, t, line);
      continue;
    }
    if (t.back() != ']') c.fail(line, fmt::format("section header '{}' lacks ']'", t));
    const std::string name(trim(t.substr(1, t.size() - 2)));
    if (name.empty()) c.fail(line, "empty section name '[]'");
    if (auto [it, fresh] = seen.emplace(lower(name), line); !fresh)
      c.fail(line, name, "", fmt::format("section given twice (first at line {})", it->second));
    out.push_back(IniSection{name, line, {}});
  }
  return out;
}

// One section's keys with typed, checked accessors.
struct Sec {
  const Ctx& c;
  const IniSection& s;

  const IniKey* get(std::string_view key) const {
    const auto it = s.by_name.find(lower(key));
    return it == s.by_name.end() ? nullptr : &s.keys[it->second];
  }
  const IniKey& need(std::string_view key) const {
    if (const IniKey* k = get(key)) return *k;
    c.fail(s.line, s.name, std::string(key), "missing (required)");
  }
  [[noreturn]] void fail(const IniKey& k, const std::string& what) const { c.fail(k.line, s.name, k.name, what); }
  std::int64_t number(const IniKey& k, std::int64_t lo, std::int64_t hi) const {
    const auto v = parse_eds_number(k.value);
    if (!v) fail(k, fmt::format("'{}' is not a number", k.value));
    if (*v < lo || *v > hi) fail(k, fmt::format("{} outside {}..{}", *v, lo, hi));
    return *v;
  }
  std::int64_t number_or(std::string_view key, std::int64_t lo, std::int64_t hi, std::int64_t dflt) const {
    const IniKey* k = get(key);
    return k ? number(*k, lo, hi) : dflt;
  }
  bool flag(std::string_view key) const { return number_or(key, 0, 1, 0) != 0; }
  std::string text(std::string_view key) const {
    const IniKey* k = get(key);
    return k ? k->value : std::string();
  }
};

// ---- values ----------------------------------------------------------------------------------

// Largest value of an integer type as int64 (UNSIGNED64 capped at INT64_MAX).
std::int64_t int_max(std::uint16_t type, std::uint16_t bits) {
  if (bits >= 64) return std::numeric_limits<std::int64_t>::max();
  if (is_signed_type(type)) return (std::int64_t{1} << (bits - 1)) - 1;
  return static_cast<std::int64_t>((std::uint64_t{1} << bits) - 1);
}

// A number that fits an integer type of `bits`; hex/octal are bit patterns for signed types.
std::optional<std::int64_t> fit_integer(const RawNumber& r, std::uint16_t type, std::uint16_t bits) {
  const std::uint64_t all = bits >= 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << bits) - 1;
  if (!is_signed_type(type)) {
    if (r.negative && r.magnitude != 0) return std::nullopt;
    if (r.magnitude > all) return std::nullopt;
    return static_cast<std::int64_t>(r.magnitude);
  }
  const std::uint64_t half = std::uint64_t{1} << (bits - 1);
  if (r.negative) {
    if (r.magnitude > half) return std::nullopt;
    return static_cast<std::int64_t>(0 - r.magnitude);
  }
  if (r.decimal) {
    if (r.magnitude >= half) return std::nullopt;
    return static_cast<std::int64_t>(r.magnitude);
  }
  if (r.magnitude > all) return std::nullopt;
  if (r.magnitude >= half) return static_cast<std::int64_t>(r.magnitude | ~all);  // sign-extend the pattern
  return static_cast<std::int64_t>(r.magnitude);
}

// Strips "$NODEID" from "$NODEID+n" / "n+$NODEID" / "$NODEID"; false when absent.
bool strip_node_id(const Sec& s, const IniKey& k, std::string& number) {
  const std::string l = lower(k.value);
  const auto at = l.find("$nodeid");
  if (at == std::string::npos) return false;
  std::string rest = std::string(trim(k.value.substr(0, at))) + std::string(trim(k.value.substr(at + 7)));
  if (rest.empty()) rest = "0";
  else if (rest.front() == '+' && at == 0) rest.erase(0, 1);
  else if (rest.back() == '+' && at != 0) rest.pop_back();
  else s.fail(k, fmt::format("'{}': only $NODEID, $NODEID+n and n+$NODEID are supported", k.value));
  number = rest;
  return true;
}

void parse_integer_value(const Sec& s, const IniKey& k, const EdsEntry& e, EdsValue& v) {
  std::string number = k.value;
  v.plus_node_id = strip_node_id(s, k, number);
  const auto raw = parse_raw(number);
  if (!raw) s.fail(k, fmt::format("'{}' is not a number", k.value));
  const auto fit = fit_integer(*raw, e.data_type, e.bits);
  if (!fit) s.fail(k, fmt::format("'{}' does not fit data type {:#06x} ({} bits{})", k.value, e.data_type, e.bits,
                                  is_signed_type(e.data_type) ? ", signed" : ""));
  v.number = *fit;
  if (!v.plus_node_id) return;
  // Every node ID 1..127 must give a value of the type.
  if (v.number > int_max(e.data_type, e.bits) - 127)
    s.fail(k, fmt::format("'{}' does not fit data type {:#06x} for every node ID 1..127", k.value, e.data_type));
}

void parse_real_value(const Sec& s, const IniKey& k, const EdsEntry& e, EdsValue& v) {
  const std::string_view t = trim(k.value);
  if (t.size() > 2 && t[0] == '0' && (t[1] == 'x' || t[1] == 'X')) {  // the IEEE bit pattern
    const auto raw = parse_raw(t);
    if (!raw || (e.bits == 32 && raw->magnitude > 0xFFFFFFFFu))
      s.fail(k, fmt::format("'{}' is not a {}-bit pattern", k.value, e.bits));
    v.number = static_cast<std::int64_t>(raw->magnitude);
    return;
  }
  double d = 0;
  auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), d);
  if (t.empty() || ec != std::errc() || end != t.data() + t.size())
    s.fail(k, fmt::format("'{}' is not a number", k.value));
  if (e.bits == 32) {
    if (std::abs(d) > std::numeric_limits<float>::max()) s.fail(k, fmt::format("'{}' does not fit REAL32", k.value));
    v.number = std::bit_cast<std::uint32_t>(static_cast<float>(d));
  } else {
    v.number = std::bit_cast<std::int64_t>(d);
  }
}

void parse_string_value(const Sec& s, const IniKey& k, const EdsEntry& e, EdsValue& v) {
  if (e.data_type == kVisibleString || e.data_type == kUnicodeString) {
    for (char ch : k.value) {
      const auto u = static_cast<unsigned char>(ch);
      if (u < 0x20 || u == 0x7F) s.fail(k, "control character in a string value");
      v.bytes.push_back(u);
      if (e.data_type == kUnicodeString) v.bytes.push_back(0);  // UTF-16LE of 8-bit text
    }
    return;
  }
  // OCTET_STRING / DOMAIN: hex digits, spaces allowed between bytes.
  std::string hex;
  for (char ch : k.value)
    if (!std::isspace(static_cast<unsigned char>(ch))) hex.push_back(ch);
  if (hex.size() % 2 != 0) s.fail(k, fmt::format("'{}' has an odd number of hex digits", k.value));
  for (std::size_t i = 0; i < hex.size(); i += 2) {
    unsigned b = 0;
    auto [end, ec] = std::from_chars(hex.data() + i, hex.data() + i + 2, b, 16);
    if (ec != std::errc() || end != hex.data() + i + 2) s.fail(k, fmt::format("'{}' is not hex bytes", k.value));
    v.bytes.push_back(static_cast<std::uint8_t>(b));
  }
}

// DefaultValue / LowLimit / HighLimit of entry `e` (type and size already known).
std::optional<EdsValue> parse_value(const Sec& s, const IniKey* k, const EdsEntry& e, bool limit) {
  if (!k || (k->value.empty() && !is_string_type(e.data_type))) return std::nullopt;
  if (limit && (is_string_type(e.data_type) || is_real_type(e.data_type)))
    s.fail(*k, "limits are supported for integer data types only");
  EdsValue v;
  v.text = k->value;
  if (is_string_type(e.data_type)) parse_string_value(s, *k, e, v);
  else if (is_real_type(e.data_type)) parse_real_value(s, *k, e, v);
  else parse_integer_value(s, *k, e, v);
  return v;
}

// The default must lie within the limits (integer types, values without $NODEID).
void check_limits(const Sec& s, const EdsEntry& e) {
  const auto& lo = e.low_limit;
  const auto& hi = e.high_limit;
  const bool u64 = e.data_type == data_type::uint64;
  auto usable = [&](const std::optional<EdsValue>& v) { return v && !v->plus_node_id && !(u64 && v->number < 0); };
  if (usable(lo) && usable(hi) && lo->number > hi->number)
    s.fail(s.need("HighLimit"), fmt::format("{} is below LowLimit {}", hi->text, lo->text));
  const auto& d = e.default_value;
  if (!usable(d) || is_real_type(e.data_type)) return;
  if ((usable(lo) && d->number < lo->number) || (usable(hi) && d->number > hi->number))
    s.fail(s.need("DefaultValue"), fmt::format("{} outside LowLimit..HighLimit", d->text));
}

// ---- objects ---------------------------------------------------------------------------------

EdsAccess parse_access(const Sec& s) {
  const IniKey& k = s.need("AccessType");
  const std::string a = lower(k.value);
  if (a == "ro") return EdsAccess::ro;
  if (a == "wo") return EdsAccess::wo;
  if (a == "rw") return EdsAccess::rw;
  if (a == "rwr") return EdsAccess::rwr;
  if (a == "rww") return EdsAccess::rww;
  if (a == "const") return EdsAccess::const_;
  s.fail(k, fmt::format("'{}' is not ro, wo, rw, rwr, rww or const", k.value));
}

// One entry from a VAR object section or a sub-object section.
EdsEntry parse_entry(const Sec& s, std::uint8_t sub) {
  EdsEntry e;
  e.subindex = sub;
  e.line = s.s.line;
  e.name = s.need("ParameterName").value;
  const IniKey& dt = s.need("DataType");
  e.data_type = static_cast<std::uint16_t>(s.number(dt, 0, 0xFFFF));
  if (!known_type(e.data_type)) s.fail(dt, fmt::format("unknown data type {:#06x}", e.data_type));
  e.access = parse_access(s);
  e.pdo_mapping = s.flag("PDOMapping");
  e.bits = eds_type_bits(e.data_type);
  e.default_value = parse_value(s, s.get("DefaultValue"), e, false);
  if (is_string_type(e.data_type) && e.default_value) e.bits = static_cast<std::uint16_t>(
      std::min<std::size_t>(e.default_value->bytes.size() * 8, 0xFFF8));
  e.low_limit = parse_value(s, s.get("LowLimit"), e, true);
  e.high_limit = parse_value(s, s.get("HighLimit"), e, true);
  check_limits(s, e);
  return e;
}

struct SubSection {
  std::uint8_t sub = 0;
  const IniSection* sec = nullptr;
};

// Sub-object sections of an ARRAY/RECORD: count = SubNumber, sub 0 present and UNSIGNED8.
void parse_subs(const Ctx& c, const Sec& s, EdsObject& o, const std::vector<SubSection>& subs) {
  const IniKey& sn = s.need("SubNumber");
  const auto count = s.number(sn, 1, 255);
  if (static_cast<std::size_t>(count) != subs.size())
    s.fail(sn, fmt::format("{} but {} sub-object sections [{:04X}subN]", count, subs.size(), o.index));
  for (const auto& ss : subs) {
    const Sec sub{c, *ss.sec};
    if (const IniKey* ot = sub.get("ObjectType"); ot && sub.number(*ot, 0, 255) != 7)
      sub.fail(*ot, "a sub-object must be a VAR (0x7)");
    if (o.object_type == 8 && ss.sub >= count)
      c.fail(ss.sec->line, ss.sec->name, "", fmt::format("subindex {} out of range: the ARRAY has SubNumber={}", ss.sub, count));
    o.entries.push_back(parse_entry(sub, ss.sub));
  }
  std::sort(o.entries.begin(), o.entries.end(), [](const EdsEntry& a, const EdsEntry& b) { return a.subindex < b.subindex; });
  if (o.entries.front().subindex != 0) c.fail(s.s.line, s.s.name, "", "sub-object section for subindex 0 missing");
  if (o.entries.front().data_type != data_type::uint8)
    c.fail(o.entries.front().line, fmt::format("[{:04X}sub0] DataType: subindex 0 must be UNSIGNED8 (0x0005)", o.index));
}

EdsObject parse_object(const Ctx& c, const IniSection& sec, std::uint16_t index, const std::vector<SubSection>& subs) {
  const Sec s{c, sec};
  EdsObject o;
  o.index = index;
  o.line = sec.line;
  o.name = s.need("ParameterName").value;
  const IniKey* ot = s.get("ObjectType");
  o.object_type = static_cast<std::uint8_t>(ot ? s.number(*ot, 0, 255) : 7);
  if (ot && o.object_type != 2 && (o.object_type < 5 || o.object_type > 9))
    s.fail(*ot, fmt::format("{:#x} is not 0x2 DOMAIN, 0x5 DEFTYPE, 0x6 DEFSTRUCT, 0x7 VAR, 0x8 ARRAY or 0x9 RECORD", o.object_type));
  if (const IniKey* cs = s.get("CompactSubObj"); cs && s.number(*cs, 0, 255) != 0)
    s.fail(*cs, "compact sub-objects are not supported: write [XXXXsubN] sections");
  const bool has_subs = o.object_type == 6 || o.object_type == 8 || o.object_type == 9;
  if (!has_subs) {
    if (!subs.empty())
      c.fail(subs.front().sec->line, subs.front().sec->name, "",
             fmt::format("subindex {} out of range: object {:#06x} is not an ARRAY or RECORD", subs.front().sub, index));
    if (const IniKey* sn = s.get("SubNumber"); sn && s.number(*sn, 0, 255) != 0) s.fail(*sn, "a VAR has no sub-objects");
    o.entries.push_back(parse_entry(s, 0));
    o.data_type = o.entries.front().data_type;
    return o;
  }
  if (const IniKey* dt = s.get("DataType")) o.data_type = static_cast<std::uint16_t>(s.number(*dt, 0, 0xFFFF));
  if (o.object_type == 8 && o.data_type != 0 && !known_type(o.data_type))
    s.fail(s.need("DataType"), fmt::format("unknown data type {:#06x}", o.data_type));
  parse_subs(c, s, o, subs);
  return o;
}

// ---- file-level sections -----------------------------------------------------------------------

void parse_file_info(const Sec& s, EdsFileInfo& f) {
  f.file_name = s.text("FileName");
  f.description = s.text("Description");
  f.created_by = s.text("CreatedBy");
  f.modified_by = s.text("ModifiedBy");
  f.eds_version = s.text("EDSVersion");
  f.creation_date = s.text("CreationDate");
  f.creation_time = s.text("CreationTime");
  f.modification_date = s.text("ModificationDate");
  f.modification_time = s.text("ModificationTime");
  f.file_version = static_cast<std::uint8_t>(s.number_or("FileVersion", 0, 255, 0));
  f.file_revision = static_cast<std::uint8_t>(s.number_or("FileRevision", 0, 255, 0));
}

void parse_device_info(const Sec& s, EdsDeviceInfo& d) {
  constexpr std::int64_t kU32 = 0xFFFFFFFF;
  d.vendor_name = s.need("VendorName").value;
  d.vendor_number = static_cast<std::uint32_t>(s.number(s.need("VendorNumber"), 0, kU32));
  d.product_name = s.need("ProductName").value;
  d.product_number = static_cast<std::uint32_t>(s.number(s.need("ProductNumber"), 0, kU32));
  d.revision_number = static_cast<std::uint32_t>(s.number_or("RevisionNumber", 0, kU32, 0));
  d.order_code = s.text("OrderCode");
  for (int i = 0; i < 8; ++i)
    if (s.flag(fmt::format("BaudRate_{}", EdsDeviceInfo::kBaudRates[i]))) d.baud_rates |= static_cast<std::uint8_t>(1u << i);
  d.simple_boot_up_master = s.flag("SimpleBootUpMaster");
  d.simple_boot_up_slave = s.flag("SimpleBootUpSlave");
  d.granularity = static_cast<std::uint8_t>(s.number_or("Granularity", 0, 64, 0));
  d.dynamic_channels_supported = s.number_or("DynamicChannelsSupported", 0, 255, 0) != 0;
  d.group_messaging = s.flag("GroupMessaging");
  d.nr_of_rx_pdo = static_cast<std::uint16_t>(s.number_or("NrOfRXPDO", 0, 512, 0));
  d.nr_of_tx_pdo = static_cast<std::uint16_t>(s.number_or("NrOfTXPDO", 0, 512, 0));
  d.lss_supported = s.flag("LSS_Supported");
}

void parse_dummy_usage(const Sec& s, std::uint8_t& mask) {
  for (int i = 1; i <= 7; ++i)
    if (s.flag(fmt::format("Dummy000{}", i))) mask |= static_cast<std::uint8_t>(1u << i);
}

void parse_comments(const Sec& s, std::vector<std::string>& out) {
  const auto n = s.number_or("Lines", 0, 0xFFFF, 0);
  for (std::int64_t i = 1; i <= n; ++i) out.push_back(s.text(fmt::format("Line{}", i)));
}

// A *Objects list: SupportedObjects=N and 1..N=index. `where` records each index's key line.
void parse_list(const Sec& s, std::vector<std::uint16_t>& out, std::map<std::uint16_t, const IniKey*>& where) {
  const auto n = s.number(s.need("SupportedObjects"), 0, 0xFFFF);
  for (std::int64_t i = 1; i <= n; ++i) {
    const IniKey* k = s.get(std::to_string(i));
    if (!k) s.c.fail(s.s.line, s.s.name, std::to_string(i), fmt::format("missing (SupportedObjects={})", n));
    const auto index = static_cast<std::uint16_t>(s.number(*k, 1, 0xFFFF));
    if (auto [it, fresh] = where.emplace(index, k); !fresh)
      s.fail(*k, fmt::format("object {:#06x} listed twice (first at line {})", index, it->second->line));
    out.push_back(index);
  }
}

// "1018" → 0x1018, "1018sub1" → 0x1018 sub 1 (is_sub); nullopt for other section names.
std::optional<std::uint16_t> object_section(const std::string& lname, bool& is_sub, std::uint8_t& sub) {
  auto hex = [](std::string_view t, std::size_t max) -> std::optional<unsigned> {
    if (t.empty() || t.size() > max) return std::nullopt;
    unsigned v = 0;
    auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), v, 16);
    if (ec != std::errc() || end != t.data() + t.size()) return std::nullopt;
    return v;
  };
  if (lname.size() < 4) return std::nullopt;
  const auto index = hex(std::string_view(lname).substr(0, 4), 4);
  if (!index || !std::isxdigit(static_cast<unsigned char>(lname[0]))) return std::nullopt;
  is_sub = false;
  if (lname.size() == 4) return static_cast<std::uint16_t>(*index);
  if (lname.compare(4, 3, "sub") != 0) return std::nullopt;
  const auto s = hex(std::string_view(lname).substr(7), 2);
  if (!s) return std::nullopt;
  is_sub = true;
  sub = static_cast<std::uint8_t>(*s);
  return static_cast<std::uint16_t>(*index);
}

struct Sections {
  std::map<std::string, const IniSection*> named;        // lower-case name → section
  std::map<std::uint16_t, const IniSection*> objects;    // [XXXX]
  std::map<std::uint16_t, std::vector<SubSection>> subs; // [XXXXsubY]
};

Sections classify(const Ctx& c, const std::vector<IniSection>& all) {
  Sections out;
  for (const auto& sec : all) {
    const std::string l = lower(sec.name);
    bool is_sub = false;
    std::uint8_t sub = 0;
    const auto index = object_section(l, is_sub, sub);
    if (!index) {
      out.named[l] = &sec;
      continue;
    }
    if (!is_sub) {
      out.objects[*index] = &sec;
      continue;
    }
    if (sub == 0xFF) c.fail(sec.line, sec.name, "", "subindex 0xFF out of range 0..0xFE");
    out.subs[*index].push_back(SubSection{sub, &sec});
  }
  return out;
}

// Every listed object from its section; every object or sub-object section must belong to one.
void parse_objects(const Ctx& c, const Sections& secs, const std::map<std::uint16_t, const IniKey*>& listed,
                   const std::map<const IniKey*, std::string>& list_of, EdsDevice& dev) {
  static const std::vector<SubSection> kNone;
  for (const auto& [index, key] : listed) {
    auto it = secs.objects.find(index);
    if (it == secs.objects.end())
      c.fail(key->line, list_of.at(key), key->name, fmt::format("object {:#06x} has no section [{:04X}]", index, index));
    auto sub = secs.subs.find(index);
    dev.objects.push_back(parse_object(c, *it->second, index, sub == secs.subs.end() ? kNone : sub->second));
  }
  for (const auto& [index, sec] : secs.objects)
    if (!listed.count(index))
      c.fail(sec->line, sec->name, "", "object not listed in [MandatoryObjects], [OptionalObjects] or [ManufacturerObjects]");
  for (const auto& [index, subs] : secs.subs)
    if (!secs.objects.count(index))
      c.fail(subs.front().sec->line, subs.front().sec->name, "", fmt::format("no object section [{:04X}]", index));
}

}  // namespace

EdsDevice parse_eds(const std::string& text, const std::string& name) {
  const Ctx c{name};
  const auto all = split_ini(c, text);
  const Sections secs = classify(c, all);
  EdsDevice dev;
  dev.source = name;
  auto section = [&](const char* lname) -> const IniSection* {
    auto it = secs.named.find(lname);
    return it == secs.named.end() ? nullptr : it->second;
  };
  if (const auto* s = section("fileinfo")) parse_file_info(Sec{c, *s}, dev.file_info);
  const auto* di = section("deviceinfo");
  if (!di) c.fail(all.empty() ? 1 : all.front().line, "section [DeviceInfo] missing (required)");
  parse_device_info(Sec{c, *di}, dev.device_info);
  if (const auto* s = section("dummyusage")) parse_dummy_usage(Sec{c, *s}, dev.dummy_usage);
  if (const auto* s = section("comments")) parse_comments(Sec{c, *s}, dev.comments);
  if (!section("mandatoryobjects")) c.fail(di->line, "section [MandatoryObjects] missing (required)");
  std::map<std::uint16_t, const IniKey*> listed;
  std::map<const IniKey*, std::string> list_of;  // key → the list section's name (for messages)
  const std::pair<const char*, std::vector<std::uint16_t>*> lists[] = {
      {"mandatoryobjects", &dev.mandatory}, {"optionalobjects", &dev.optional}, {"manufacturerobjects", &dev.manufacturer}};
  for (const auto& [lname, out] : lists) {
    const auto* s = section(lname);
    if (!s) continue;
    parse_list(Sec{c, *s}, *out, listed);
    for (const auto& k : s->keys) list_of[&k] = s->name;
  }
  parse_objects(c, secs, listed, list_of, dev);
  return dev;  // objects come out ascending: `listed` is ordered by index
}

EdsDevice load_eds(const std::string& path) {
  // A directory opens as a stream of nothing on Linux: name it, not its "missing" contents.
  if (std::filesystem::is_directory(path)) throw EdsError(fmt::format("{}:0: a directory, not a file", path));
  std::ifstream in(path, std::ios::binary);
  if (!in) throw EdsError(fmt::format("{}:0: cannot open the file", path));
  std::ostringstream ss;
  ss << in.rdbuf();
  return parse_eds(ss.str(), path);
}

// ---- object dictionary ---------------------------------------------------------------------------

namespace {

OdEntry make_entry(const EdsDevice& dev, const EdsObject& o, const EdsEntry& e, std::uint8_t node_id) {
  if (e.data_type == kDomain || o.object_type == 2)
    throw EdsError(fmt::format("{}:{}: [{:04X}{}] DataType: DOMAIN has no fixed size; the object dictionary cannot hold it",
                               dev.source, e.line, o.index, o.object_type == 7 ? "" : fmt::format("sub{:X}", e.subindex)));
  OdEntry out;
  out.subindex = e.subindex;
  out.name = e.name;
  out.data_type = e.data_type;
  out.bits = e.bits;
  out.access = eds_od_access(e.access, e.pdo_mapping);
  if (e.default_value && is_string_type(e.data_type)) {
    out.default_value = e.default_value->bytes;
  } else if (e.default_value) {
    const auto v = static_cast<std::uint64_t>(e.default_value->value(node_id));
    for (std::size_t i = 0; i < out.bytes(); ++i) out.default_value.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  // Limits on integer types only; an UNSIGNED64 limit above INT64_MAX cannot be expressed.
  const bool integer = !is_string_type(e.data_type) && !is_real_type(e.data_type);
  const bool u64 = e.data_type == data_type::uint64;
  if (integer && e.low_limit && !(u64 && e.low_limit->value(node_id) < 0)) out.min = e.low_limit->value(node_id);
  if (integer && e.high_limit && !(u64 && e.high_limit->value(node_id) < 0)) out.max = e.high_limit->value(node_id);
  return out;
}

}  // namespace

void add_to_od(const EdsDevice& dev, std::uint8_t node_id, ObjectDictionary& od) {
  if (!valid_node_id(node_id)) throw EdsError(fmt::format("{}:0: node ID {} outside 1..127", dev.source, node_id));
  for (const auto& o : dev.objects) {
    // Type definitions describe, they hold no value.
    if (o.object_type == 5 || o.object_type == 6) continue;
    OdObject obj;
    obj.index = o.index;
    obj.name = o.name;
    obj.object_code = o.object_type;
    for (const auto& e : o.entries) obj.entries.push_back(make_entry(dev, o, e, node_id));
    obj.data_type = o.data_type;
    if (o.object_type == 8 && obj.data_type == 0 && obj.entries.size() > 1) obj.data_type = obj.entries[1].data_type;
    od.add(std::move(obj));
  }
}

}  // namespace omnitwin::canopen
