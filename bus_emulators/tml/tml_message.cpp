// bus_emulators/tml — the protocol-independent TML message (see tml_message.hpp).
#include "bus_emulators/tml/tml_message.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <charconv>

namespace omnitwin::tml {

namespace {

constexpr std::uint16_t kPage200 = 0x0200, kPage800 = 0x0800, kPageSpan = 0x0200;

// The seed's symbols (facts/tml.md) and the motion variables Technosoft's public TML_lib_light
// names (SRH's address is confirmed there too).
constexpr std::array<Symbol, 10> kSymbols{{
    {"KPP", 0x025E, false, "seed ch. 3 example 2"},
    {"POSERR", 0x022A, false, "seed ch. 4 example 2"},
    {"SRL", 0x090E, false, "seed ch. 3 example 3"},
    {"SRH", 0x090F, false, "high word of SR32 (seed: none; TML_lib_light: 0x090F)"},
    {"SR32", 0x090E, true, "seed ch. 3: SRL and SRH read as one 32-bit SR32 at SRL's address"},
    {"MER", 0x08FC, false, "seed ch. 5 example 5"},
    {"APOS", 0x0228, true, "TML_lib_light: actual position"},
    {"CPOS", 0x029E, true, "TML_lib_light: command position"},
    {"CSPD", 0x02A0, true, "TML_lib_light: command speed (16.16)"},
    {"CACC", 0x02A2, true, "TML_lib_light: command acceleration (16.16)"},
}};

std::uint32_t wide_value(std::uint16_t low, std::uint16_t high) { return static_cast<std::uint32_t>(high) << 16 | low; }

Message make(std::uint16_t dest, std::uint16_t opcode, std::initializer_list<std::uint16_t> words) {
  Message m;
  m.id_code = dest;
  m.opcode = opcode;
  for (const std::uint16_t w : words) m.data[m.count++] = w;
  return m;
}

// Classifies an assignment opcode (0x2000–0x27FF).
Classified classify_assign(const Message& m) {
  Classified c;
  c.wide = (m.opcode & 0x0400) != 0;  // 0x2400 family
  c.kind = c.wide ? Kind::assign32 : Kind::assign16;
  const bool page800 = (m.opcode & op::assign_page800) != 0;
  c.address = static_cast<std::uint16_t>((page800 ? kPage800 : kPage200) + (m.opcode & 0x1FF));
  c.complete = m.count == (c.wide ? 2 : 1);
  if (m.count >= 1) c.value = m.data[0];
  if (c.wide && m.count >= 2) c.value = wide_value(m.data[0], m.data[1]);
  return c;
}

// GiveMeData / GiveMeData2: data 1 sender ID code, data 2 address.
Classified classify_request(const Message& m, Kind kind) {
  Classified c;
  c.kind = kind;
  c.wide = (m.opcode & 1) != 0;
  c.sender = m.data[0];
  c.address = m.data[1];
  c.complete = m.count == 2;
  return c;
}

// TakeData: data 1 sender ID code, data 2 address, data 3 (and 4) value.
Classified classify_take_data(const Message& m) {
  Classified c;
  c.kind = Kind::take_data;
  c.wide = m.opcode == op::take_data32;
  c.sender = m.data[0];
  c.address = m.data[1];
  c.value = c.wide ? wide_value(m.data[2], m.data[3]) : m.data[2];
  c.complete = m.count == (c.wide ? 4 : 3);
  return c;
}

// TakeData2: sender axis in the opcode, data 1 address, data 2 (and 3) value.
Classified classify_take_data2(const Message& m) {
  Classified c;
  c.kind = Kind::take_data2;
  c.wide = (m.opcode & 0xFF00) == op::take_data2_32;
  c.sender = m.opcode & 0xFF;
  c.address = m.data[0];
  c.value = c.wide ? wide_value(m.data[1], m.data[2]) : m.data[1];
  c.complete = m.count == (c.wide ? 3 : 2);
  return c;
}

std::string upper(std::string_view s) {
  std::string u(s);
  for (char& ch : u) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
  return u;
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
  return s;
}

// A decimal, 0x-hex or negative integer filling the whole text.
bool parse_int(std::string_view s, std::int64_t& out) {
  s = trim(s);
  const bool neg = !s.empty() && s.front() == '-';
  if (neg) s.remove_prefix(1);
  int base = 10;
  if (s.size() > 2 && s[0] == '0' && (s[1] == 'x' || s[1] == 'X')) s.remove_prefix(2), base = 16;
  std::uint64_t v = 0;
  const auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v, base);
  if (s.empty() || ec != std::errc{} || p != s.data() + s.size() || v > 0xFFFFFFFFull) return false;
  out = neg ? -static_cast<std::int64_t>(v) : static_cast<std::int64_t>(v);
  return true;
}

// NAME: a symbol, or 0xNNNN with an optional :16 / :32 width.
std::string parse_name(std::string_view name, TextInstruction& out) {
  name = trim(name);
  if (name.empty()) return "no variable name";
  out.name = upper(name);
  if (const Symbol* s = find_symbol(name)) {
    out.address = s->address, out.wide = s->wide;
    return "";
  }
  std::string_view addr = name;
  out.wide = false;
  if (const auto colon = name.find(':'); colon != std::string_view::npos) {
    const std::string_view w = name.substr(colon + 1);
    if (w != "16" && w != "32") return fmt::format("width '{}' is not 16 or 32", w);
    out.wide = w == "32";
    addr = name.substr(0, colon);
  }
  std::int64_t a = 0;
  if (addr.size() < 3 || addr[0] != '0' || (addr[1] != 'x' && addr[1] != 'X') || !parse_int(addr, a) || a > 0xFFFF)
    return fmt::format("unknown variable '{}' (known: KPP POSERR SRL SRH SR32 MER APOS CPOS CSPD CACC, or an address 0xNNNN[:32])", name);
  out.address = static_cast<std::uint16_t>(a);
  return "";
}

std::string name_of(std::uint16_t address, bool wide) {
  const Symbol* s = find_symbol(address, wide);
  return s ? fmt::format("{} (0x{:04X}, {}-bit)", s->name, address, wide ? 32 : 16)
           : fmt::format("0x{:04X} ({}-bit)", address, wide ? 32 : 16);
}

std::string value_text(std::uint32_t v, bool wide) {
  return wide ? fmt::format("0x{:08X} ({})", v, static_cast<std::int32_t>(v))
              : fmt::format("0x{:04X} ({})", v, static_cast<std::int16_t>(v));
}

}  // namespace

std::optional<std::uint16_t> assign_opcode(std::uint16_t address, bool wide) {
  const std::uint16_t family = wide ? op::assign32 : op::assign16;
  // Only the two data pages whose 9 LSBs the opcode can carry.
  if (address >= kPage200 && address < kPage200 + kPageSpan) return static_cast<std::uint16_t>(family | (address & 0x1FF));
  if (address >= kPage800 && address < kPage800 + kPageSpan)
    return static_cast<std::uint16_t>(family | op::assign_page800 | (address & 0x1FF));
  return std::nullopt;
}

bool operator==(const Message& a, const Message& b) {
  if (a.id_code != b.id_code || a.opcode != b.opcode || a.count != b.count) return false;
  const auto wa = a.words(), wb = b.words();
  return std::equal(wa.begin(), wa.end(), wb.begin(), wb.end());
}

Classified classify(const Message& m) {
  const std::uint16_t o = m.opcode;
  switch (o) {
    case op::give_me_data16: case op::give_me_data32: return classify_request(m, Kind::give_me_data);
    case op::give_me_data2_16: case op::give_me_data2_32: return classify_request(m, Kind::give_me_data2);
    case op::take_data16: case op::take_data32: return classify_take_data(m);
    case op::sync: return {Kind::sync, false, 0, 0, 0, m.count == 0};
    case op::set_master_time:
      return {Kind::set_master_time, true, 0, wide_value(m.data[0], m.data[1]), 0, m.count == 2};
    default: break;
  }
  if ((o & 0xFE00) == op::take_data2_16) return classify_take_data2(m);  // D400–D5FF
  if ((o & 0xFF80) == op::pvt) return {Kind::pvt, false, 0, 0, 0, m.count == 4};
  if ((o & 0xF800) == op::assign16) return classify_assign(m);            // 2000–27FF
  return {};
}

MessageType type_of(const Message& m) {
  switch (classify(m).kind) {
    case Kind::give_me_data: case Kind::give_me_data2: return MessageType::b;
    case Kind::take_data: return MessageType::answer;
    case Kind::take_data2: return MessageType::c;
    default: return MessageType::a;
  }
}

std::optional<Message> assign16(std::uint16_t dest, std::uint16_t address, std::uint16_t value) {
  const auto o = assign_opcode(address, false);
  if (!o) return std::nullopt;
  return make(dest, *o, {value});
}

std::optional<Message> assign32(std::uint16_t dest, std::uint16_t address, std::uint32_t value) {
  const auto o = assign_opcode(address, true);
  if (!o) return std::nullopt;
  return make(dest, *o, {static_cast<std::uint16_t>(value), static_cast<std::uint16_t>(value >> 16)});
}

Message give_me_data(std::uint16_t dest, std::uint16_t sender, std::uint16_t address, bool wide) {
  return make(dest, wide ? op::give_me_data32 : op::give_me_data16, {sender, address});
}

Message take_data(std::uint16_t dest, std::uint16_t sender, std::uint16_t address, std::uint32_t value, bool wide) {
  const auto lo = static_cast<std::uint16_t>(value);
  if (!wide) return make(dest, op::take_data16, {sender, address, lo});
  return make(dest, op::take_data32, {sender, address, lo, static_cast<std::uint16_t>(value >> 16)});
}

Message give_me_data2(std::uint16_t dest, std::uint16_t sender, std::uint16_t address, bool wide) {
  return make(dest, wide ? op::give_me_data2_32 : op::give_me_data2_16, {sender, address});
}

Message take_data2(std::uint16_t dest, std::uint8_t sender_axis, std::uint16_t address, std::uint32_t value, bool wide) {
  const auto lo = static_cast<std::uint16_t>(value);
  if (!wide) return make(dest, static_cast<std::uint16_t>(op::take_data2_16 | sender_axis), {address, lo});
  return make(dest, static_cast<std::uint16_t>(op::take_data2_32 | sender_axis),
              {address, lo, static_cast<std::uint16_t>(value >> 16)});
}

Message sync_message() { return make(group_id_code(0), op::sync, {}); }

Message set_master_time(std::uint32_t time) {
  return make(group_id_code(0), op::set_master_time,
              {static_cast<std::uint16_t>(time), static_cast<std::uint16_t>(time >> 16)});
}

bool operator==(const PvtPoint& a, const PvtPoint& b) {
  return a.position == b.position && a.velocity == b.velocity && a.time == b.time && a.counter == b.counter;
}

Message pvt(std::uint16_t dest, const PvtPoint& p) {
  const auto pos = static_cast<std::uint32_t>(p.position);
  const auto vel = static_cast<std::uint32_t>(p.velocity);
  const auto d1 = static_cast<std::uint16_t>(pos & 0xFFFF);
  const auto d2 = static_cast<std::uint16_t>((pos >> 16 & 0xFF) << 8 | (vel >> 8 & 0xFF));
  const auto d3 = static_cast<std::uint16_t>(vel >> 16);
  const auto d4 = static_cast<std::uint16_t>(p.time & 0x1FF);
  return make(dest, static_cast<std::uint16_t>(op::pvt | (p.counter & 0x7F)), {d1, d2, d3, d4});
}

std::optional<PvtPoint> pvt_point(const Message& m) {
  if ((m.opcode & 0xFF80) != op::pvt || m.count != 4) return std::nullopt;
  PvtPoint p;
  // Position: 24 bits, sign-extended.
  const std::uint32_t pos = static_cast<std::uint32_t>(m.data[1] >> 8) << 16 | m.data[0];
  p.position = static_cast<std::int32_t>(pos << 8) >> 8;
  // Velocity: bits 31–8 as sent, bits 7–0 not transmitted.
  p.velocity = static_cast<std::int32_t>(static_cast<std::uint32_t>(m.data[2]) << 16 | (m.data[1] & 0xFFu) << 8);
  p.time = m.data[3] & 0x1FF;
  p.counter = m.opcode & 0x7F;
  return p;
}

std::span<const Symbol> symbols() { return kSymbols; }

const Symbol* find_symbol(std::string_view name) {
  const std::string u = upper(trim(name));
  for (const Symbol& s : kSymbols)
    if (s.name == u) return &s;
  return nullptr;
}

const Symbol* find_symbol(std::uint16_t address, bool wide) {
  const Symbol* any = nullptr;
  for (const Symbol& s : kSymbols) {
    if (s.address != address) continue;
    if (s.wide == wide) return &s;
    if (!any) any = &s;
  }
  return any;
}

std::string parse_text(std::string_view text, TextInstruction& out) {
  text = trim(text);
  out = TextInstruction{};
  if (text.starts_with("??")) {
    out.form = TextForm::give_me_data2;
    return parse_name(text.substr(2), out);
  }
  if (text.starts_with("?")) {
    out.form = TextForm::give_me_data;
    return parse_name(text.substr(1), out);
  }
  const auto eq = text.find('=');
  if (eq == std::string_view::npos) return fmt::format("'{}' is not NAME=VALUE, ?NAME or ??NAME", text);
  if (std::string e = parse_name(text.substr(0, eq), out); !e.empty()) return e;
  if (!parse_int(text.substr(eq + 1), out.value)) return fmt::format("value '{}' is not an integer", trim(text.substr(eq + 1)));
  const std::int64_t lo = out.wide ? -2147483648LL : -32768, hi = out.wide ? 0xFFFFFFFFLL : 0xFFFF;
  if (out.value < lo || out.value > hi)
    return fmt::format("value {} does not fit the {}-bit variable {}", out.value, out.wide ? 32 : 16, out.name);
  return "";
}

std::string build_text(const TextInstruction& t, std::uint16_t dest, std::uint16_t sender, Message& out) {
  switch (t.form) {
    case TextForm::give_me_data:
      if (is_group(dest)) return "GiveMeData (?NAME) goes to one axis only, not to a group (seed ch. 6)";
      out = give_me_data(dest, sender, t.address, t.wide);
      return "";
    case TextForm::give_me_data2:
      out = give_me_data2(dest, sender, t.address, t.wide);
      return "";
    case TextForm::assign: break;
  }
  const auto v = static_cast<std::uint32_t>(t.value);
  const auto m = t.wide ? assign32(dest, t.address, v) : assign16(dest, t.address, static_cast<std::uint16_t>(v));
  if (!m) return fmt::format("no assignment opcode known for address 0x{:04X} (only 0x0200-0x03FF, 0x0800-0x09FF)", t.address);
  out = *m;
  return "";
}

std::string describe_id_code(std::uint16_t c) {
  if (is_broadcast(c)) return "broadcast (group 0)";
  if (is_group(c)) return fmt::format("group ID 0x{:02X}{}", id_of(c), is_host(c) ? " (host)" : "");
  return fmt::format("axis {}{}", id_of(c), is_host(c) ? " (host)" : "");
}

std::string describe(const Message& m, bool with_destination) {
  const Classified c = classify(m);
  std::string what;
  switch (c.kind) {
    case Kind::assign16: case Kind::assign32:
      what = fmt::format("{} = {}", name_of(c.address, c.wide), value_text(c.value, c.wide)); break;
    case Kind::give_me_data: case Kind::give_me_data2:
      what = fmt::format("{} {} from {}", c.kind == Kind::give_me_data ? "GiveMeData" : "GiveMeData2",
                         name_of(c.address, c.wide), describe_id_code(c.sender)); break;
    case Kind::take_data:
      what = fmt::format("TakeData {} = {} from {}", name_of(c.address, c.wide), value_text(c.value, c.wide),
                         describe_id_code(c.sender)); break;
    case Kind::take_data2:
      what = fmt::format("TakeData2 {} = {} from axis {}", name_of(c.address, c.wide), value_text(c.value, c.wide),
                         c.sender); break;
    case Kind::sync: what = "synchronisation"; break;
    case Kind::set_master_time: what = fmt::format("set master time {}", value_text(c.value, true)); break;
    case Kind::pvt: {
      const auto p = pvt_point(m);
      what = p ? fmt::format("PVT position {} velocity {:.4f} time {} counter {}", p->position, p->velocity / 65536.0,
                             p->time, p->counter)
               : "PVT";
      break;
    }
    case Kind::generic: what = "instruction not in the seed's set"; break;
  }
  std::string s = fmt::format("{} [{}, type {}, {}]", what, to_string(c.kind), to_string(type_of(m)), to_string(m));
  if (with_destination) s += " to " + describe_id_code(m.id_code);
  if (!c.complete) s += fmt::format(" (unexpected word count {})", m.count);
  return s;
}

std::string to_string(const Message& m) {
  std::string s = fmt::format("{:04X} {:04X}", m.id_code, m.opcode);
  for (const std::uint16_t w : m.words()) s += fmt::format(" {:04X}", w);
  return s;
}

const char* to_string(Kind k) {
  switch (k) {
    case Kind::assign16: return "assign16";
    case Kind::assign32: return "assign32";
    case Kind::give_me_data: return "GiveMeData";
    case Kind::take_data: return "TakeData";
    case Kind::give_me_data2: return "GiveMeData2";
    case Kind::take_data2: return "TakeData2";
    case Kind::sync: return "sync";
    case Kind::set_master_time: return "set master time";
    case Kind::pvt: return "PVT";
    case Kind::generic: return "generic";
  }
  return "?";
}

const char* to_string(MessageType t) {
  switch (t) {
    case MessageType::a: return "A";
    case MessageType::b: return "B";
    case MessageType::c: return "C";
    case MessageType::answer: return "answer";
  }
  return "?";
}

}  // namespace omnitwin::tml
