// bus_emulators/tml — the protocol-independent TML message of Technosoft IDM drives (seed 003,
// chapter 2; facts/tml.md).
//
// Every TML link (RS-232, RS-485, TMLCAN, TechCAN) carries the same thing: a 16-bit axis/group
// ID code, a 16-bit operation code and 0–4 16-bit data words. This file holds that value type,
// the ID-code helpers, the opcodes the seed defines (GiveMeData, TakeData, GiveMeData2,
// TakeData2, synchronisation, set master time, PVT) and the immediate assignments
// `VAR = value`, the named builders, a classifier that says what a message is, a small symbol
// table of the registers/variables the seed gives addresses for, and a parser for the text the
// vendor's Binary Code Viewer accepts (`KPP=5`, `?POSERR`, `??SRL`). The link codecs
// (tml_serial, tml_can) only pack and unpack this type; nothing here knows a link or a clock.
//
// Seed versus our choice (also in docs/protocols/tml.md):
//   - 16-bit assignment opcode 0x2000 | (address & 0x1FF) — from the seed's only example
//     (KPP at 0x025E → 205E). The seed gives nothing more.
//   - OUR CHOICE (not in seed 003; follows the vendor's published TML_LIB sources): the 32-bit
//     assignment family 0x2400, and bit 0x0200 in the opcode for addresses 0x0800–0x09FF.
//     Assignments are only formed for 0x0200–0x03FF and 0x0800–0x09FF; other addresses give
//     no opcode (std::nullopt) rather than a guessed one.
//   - 32-bit values travel low word first (seed: TakeData data 3 = 16 LSB, data 4 = 16 MSB).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

namespace omnitwin::tml {

// ---- Axis/group ID code: bits 15–13 zero, 12 GROUP, 11–4 ID7..ID0, 3–1 zero, 0 HOST ------------
inline constexpr std::uint16_t kGroupBit = 0x1000;
inline constexpr std::uint16_t kHostBit = 0x0001;
inline constexpr std::uint16_t kIdCodeMask = 0x1FF1;  // the bits that may be set

// ID code of an axis (1–255; 0 is accepted by every drive), HOST bit as given. RT-safe.
constexpr std::uint16_t axis_id_code(std::uint8_t axis, bool host = false) {
  return static_cast<std::uint16_t>(axis << 4 | (host ? kHostBit : 0));
}
// ID code of a group ID (a mask: bit n-1 = group n; 0 = broadcast to every drive). RT-safe.
constexpr std::uint16_t group_id_code(std::uint8_t group_mask) {
  return static_cast<std::uint16_t>(kGroupBit | group_mask << 4);
}
// ID code of a host that shares `axis` with its relay drive (RS-232, HOST bit set). RT-safe.
constexpr std::uint16_t host_id_code(std::uint8_t axis) { return axis_id_code(axis, true); }
// Group ID mask of group number 1–8 (0 → 0, the broadcast). RT-safe.
constexpr std::uint8_t group_mask(int group_number) {
  return group_number <= 0 || group_number > 8 ? 0 : static_cast<std::uint8_t>(1u << (group_number - 1));
}
// MASTERID, the destination of unsolicited TakeData2: host axis ID · 16 + 1. RT-safe.
constexpr std::uint16_t master_id(std::uint8_t host_axis) { return static_cast<std::uint16_t>(host_axis * 16 + 1); }

constexpr std::uint8_t id_of(std::uint16_t id_code) { return static_cast<std::uint8_t>(id_code >> 4); }
constexpr bool is_group(std::uint16_t id_code) { return (id_code & kGroupBit) != 0; }
constexpr bool is_host(std::uint16_t id_code) { return (id_code & kHostBit) != 0; }
constexpr bool is_broadcast(std::uint16_t id_code) { return is_group(id_code) && id_of(id_code) == 0; }
// A group code or axis 0: every drive that hears it may take it (seed ch. 2), so on a shared
// RS-485 line none acknowledges or answers it (their transmissions would collide).
constexpr bool to_many(std::uint16_t id_code) { return is_group(id_code) || id_of(id_code) == 0; }
// Only the GROUP, ID and HOST bits are set. RT-safe.
constexpr bool id_code_valid(std::uint16_t id_code) { return (id_code & ~kIdCodeMask) == 0; }

// ---- Operation codes ---------------------------------------------------------------------------
namespace op {
inline constexpr std::uint16_t give_me_data16 = 0xB004, give_me_data32 = 0xB005;    // seed ch. 3
inline constexpr std::uint16_t take_data16 = 0xB404, take_data32 = 0xB405;          // seed ch. 3
inline constexpr std::uint16_t give_me_data2_16 = 0xB204, give_me_data2_32 = 0xB205;  // seed ch. 4 (B204)
inline constexpr std::uint16_t take_data2_16 = 0xD400, take_data2_32 = 0xD500;      // + 8-bit sender axis
inline constexpr std::uint16_t sync = 0x1000;                                        // seed ch. 5
inline constexpr std::uint16_t set_master_time = 0x1401;                             // seed ch. 5
inline constexpr std::uint16_t pvt = 0x1800;                                         // + 7-bit counter
inline constexpr std::uint16_t assign16 = 0x2000;         // seed: KPP=5 → 205E
inline constexpr std::uint16_t assign32 = 0x2400;         // OUR CHOICE (vendor TML_LIB), not in seed
inline constexpr std::uint16_t assign_page800 = 0x0200;   // OUR CHOICE (vendor TML_LIB), not in seed
}  // namespace op

// Opcode of `address = value` (16- or 32-bit immediate), or nullopt when the address is outside
// 0x0200–0x03FF and 0x0800–0x09FF (no formula known). RT-safe.
std::optional<std::uint16_t> assign_opcode(std::uint16_t address, bool wide);

// ---- The message -------------------------------------------------------------------------------
inline constexpr std::size_t kMaxDataWords = 4;

struct Message {
  std::uint16_t id_code = 0;  // destination axis/group ID code
  std::uint16_t opcode = 0;
  std::uint8_t count = 0;     // data words used, 0–4
  std::array<std::uint16_t, kMaxDataWords> data{};

  std::span<const std::uint16_t> words() const { return {data.data(), count > kMaxDataWords ? kMaxDataWords : count}; }
  bool valid() const { return count <= kMaxDataWords && id_code_valid(id_code); }
};
bool operator==(const Message& a, const Message& b);  // compares the used words only

// Message types (seed ch. 3): A needs no answer, B asks for data, C is sent by a drive unasked.
// TakeData (and a TakeData2 that answers a GiveMeData2) are answers.
enum class MessageType : std::uint8_t { a, b, c, answer };

// What a message is, as far as the seed says. Unknown opcodes are `generic` (never an error).
enum class Kind : std::uint8_t {
  assign16, assign32, give_me_data, take_data, give_me_data2, take_data2, sync, set_master_time, pvt, generic
};

struct Classified {
  Kind kind = Kind::generic;
  bool wide = false;            // 32-bit data
  std::uint16_t address = 0;    // register/variable address (assignments, data requests/answers)
  std::uint32_t value = 0;      // assigned or returned value (32-bit: high word | low word)
  std::uint16_t sender = 0;     // sender ID code (GiveMeData/TakeData/GiveMeData2); axis (TakeData2)
  bool complete = true;         // the data words the kind needs are all there
};
// Classifies by opcode and word count. RT-safe.
Classified classify(const Message& m);
MessageType type_of(const Message& m);

// ---- Builders (RT-safe; dest/sender are ID codes) ----------------------------------------------
// `address = value`: 16-bit (one data word) or 32-bit (low word, high word). nullopt: see
// assign_opcode.
std::optional<Message> assign16(std::uint16_t dest, std::uint16_t address, std::uint16_t value);
std::optional<Message> assign32(std::uint16_t dest, std::uint16_t address, std::uint32_t value);
Message give_me_data(std::uint16_t dest, std::uint16_t sender, std::uint16_t address, bool wide);
Message take_data(std::uint16_t dest, std::uint16_t sender, std::uint16_t address, std::uint32_t value, bool wide);
Message give_me_data2(std::uint16_t dest, std::uint16_t sender, std::uint16_t address, bool wide);
// Sent by `sender_axis` to `dest` (MASTERID for unsolicited ones, else the requester's ID code).
Message take_data2(std::uint16_t dest, std::uint8_t sender_axis, std::uint16_t address, std::uint32_t value, bool wide);
Message sync_message();                                  // broadcast, opcode 0x1000, no data
Message set_master_time(std::uint32_t time);             // broadcast, opcode 0x1401, time low, high

// One PVT point (TML `PVTP p, v, t, counter`). position: 24-bit signed [IU]; velocity: 32-bit
// 16.16 fixed point [IU], its low 8 bits are not transmitted; time: 9 bits [IU]; counter: 7
// bits. Words (our reading of seed ch. 5): opcode 0x1800 | counter, data 1 = position[15:0],
// data 2 = position[23:16] << 8 | velocity[15:8], data 3 = velocity[31:16], data 4 = time.
struct PvtPoint {
  std::int32_t position = 0;
  std::int32_t velocity = 0;
  std::uint16_t time = 0;
  std::uint8_t counter = 0;
};
bool operator==(const PvtPoint& a, const PvtPoint& b);
Message pvt(std::uint16_t dest, const PvtPoint& p);
// The PVT point of a PVT message (velocity's low 8 bits read as 0). nullopt if not PVT. RT-safe.
std::optional<PvtPoint> pvt_point(const Message& m);

// ---- Symbols the seed names --------------------------------------------------------------------
struct Symbol {
  std::string_view name;
  std::uint16_t address;
  bool wide;                // 32-bit variable
  std::string_view origin;  // where the address comes from
};
std::span<const Symbol> symbols();
const Symbol* find_symbol(std::string_view name);        // case-insensitive; nullptr if unknown
const Symbol* find_symbol(std::uint16_t address, bool wide);

// ---- Binary Code Viewer text -------------------------------------------------------------------
// `NAME=VALUE` (assignment; VALUE decimal, 0x hex, or negative), `?NAME` (GiveMeData),
// `??NAME` (GiveMeData2). NAME is a symbol or a hex address 0xNNNN (16-bit; `0xNNNN:32` for
// 32-bit). Not for real-time use (text).
enum class TextForm : std::uint8_t { assign, give_me_data, give_me_data2 };
struct TextInstruction {
  TextForm form = TextForm::assign;
  std::string name;           // as written (upper-cased for symbols)
  std::uint16_t address = 0;
  bool wide = false;
  std::int64_t value = 0;
};
// Empty string on success, else what is wrong.
std::string parse_text(std::string_view text, TextInstruction& out);
// The message of a parsed instruction. Empty string on success, else what is wrong.
std::string build_text(const TextInstruction& t, std::uint16_t dest, std::uint16_t sender, Message& out);

// ---- Text for logs and tools -------------------------------------------------------------------
std::string describe_id_code(std::uint16_t id_code);   // "axis 255 (host)", "group 0x01", "broadcast"
// One line in words; with_destination false: the ID code is unknown (not carried), left out.
std::string describe(const Message& m, bool with_destination = true);
std::string to_string(const Message& m);               // "0FF0 205E 0005"
const char* to_string(Kind k);
const char* to_string(MessageType t);

}  // namespace omnitwin::tml
