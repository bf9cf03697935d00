// bus_emulators/tml — TML over CAN (seed 003 chapters 4 and 5; facts/tml.md): TMLCAN (CAN 2.0B,
// 29-bit identifiers) and TechCAN (CAN 2.0A, 11-bit COB-IDs beside CANopen).
//
// Pure codecs between a tml::Message and an omnitwin::can::Frame: no state, no clock, no
// allocation. Decoding never throws; a frame that is not valid TML gets a CanStatus.
//
// TMLCAN identifier: bits 28–22 opcode[15:9], 21 GROUP, 20–13 axis/group ID, 12–10 zero, 9 HOST,
// 8–0 opcode[8:0]; data words little-endian in bytes 0–7.
// TechCAN COB-IDs: group 0x001–0x01F (the group mask, groups 1–5), sync 0x020, PVT 0x040+axis,
// TakeData2/PONG 0x100+sender axis, normal 0x120+axis, host 0x140+axis, TakeData 0x160+axis,
// broadcast 0x200; axes 1–31. Normal/host/group/broadcast: opcode then data words, low byte
// first, unused bytes not sent. TakeData, PVT and TakeData2 have their own packings.
// Readings of the seed that are ours (docs/protocols/tml.md):
//   - TakeData's COB-ID carries the ANSWERING axis (the seed's only example: 0x165 from axis 5
//     to host 3), and byte 1 carries data 1 (the sender ID code) bits 8–4 and its HOST bit
//     (bit 0) in bit 2. The destination is not carried; decoding reports it unknown.
//   - TakeData2 carries no destination either (it goes to the host / MASTERID).
//   - A message to an axis with the HOST bit set (other than TakeData/TakeData2) is a "host"
//     message; the PONG payload is not described by the seed and is kept as raw words.
#pragma once

#include <cstdint>
#include <span>

#include "bus_emulators/can/can_frame.hpp"
#include "bus_emulators/tml/tml_message.hpp"

namespace omnitwin::tml {

enum class CanStatus : std::uint8_t {
  ok,
  wrong_format,        // TMLCAN needs a 29-bit identifier, TechCAN an 11-bit one
  not_data_frame,      // remote or error frame
  bad_identifier,      // TMLCAN bits 12-10 set; an ID code that cannot be encoded
  bad_length,          // DLC does not fit the message's layout
  too_many_words,      // more data words than the layout carries
  axis_out_of_range,   // TechCAN: axes 1-31
  group_out_of_range,  // TechCAN: group masks 1-31 (groups 1-5)
  unknown_cob_id,      // TechCAN: not in a TechCAN range (e.g. a CANopen frame)
};
const char* to_string(CanStatus s);

// ---- TMLCAN ------------------------------------------------------------------------------------
// The 29-bit identifier of an ID code and opcode. RT-safe.
constexpr std::uint32_t tmlcan_identifier(std::uint16_t id_code, std::uint16_t opcode) {
  return static_cast<std::uint32_t>(opcode >> 9) << 22 | static_cast<std::uint32_t>(id_code & kIdCodeMask) << 9 |
         (opcode & 0x1FFu);
}
// RT-safe; fails on an invalid ID code or more than 4 words.
CanStatus encode_tmlcan(const Message& m, can::Frame& out);
// RT-safe, never throws.
CanStatus decode_tmlcan(const can::Frame& f, Message& out);

// ---- TechCAN -----------------------------------------------------------------------------------
enum class TechCanKind : std::uint8_t { group, sync, pvt, take_data2, pong, normal, host, take_data, broadcast };
const char* to_string(TechCanKind k);

namespace techcan {
inline constexpr std::uint16_t group_base = 0x000, sync_id = 0x020, pvt_base = 0x040, take_data2_base = 0x100,
                               normal_base = 0x120, host_base = 0x140, take_data_base = 0x160, broadcast_id = 0x200;
inline constexpr std::uint8_t max_axis = 31, max_group_mask = 0x1F;
inline constexpr std::uint8_t take_data_opcode_msb = 0x2D;  // opcode[15:10] of TakeData, not sent
inline constexpr std::uint8_t vt_bit = 0x80, p_bit = 0x40;  // TakeData2 byte 0
}  // namespace techcan

struct TechCanMessage {
  TechCanKind kind = TechCanKind::normal;
  Message message{};               // pong: opcode 0, the raw words
  bool destination_known = true;   // false for TakeData, TakeData2 and PONG (not carried)
  std::uint8_t cob_number = 0;     // the axis or group mask in the COB-ID
};

// The TechCAN frame of a message. RT-safe.
CanStatus encode_techcan(const Message& m, can::Frame& out);
// A PONG from `axis` (answer to a PING broadcast) with up to 3 raw words. RT-safe.
CanStatus encode_techcan_pong(std::uint8_t axis, std::span<const std::uint16_t> words, can::Frame& out);
// RT-safe, never throws.
CanStatus decode_techcan(const can::Frame& f, TechCanMessage& out);

}  // namespace omnitwin::tml
