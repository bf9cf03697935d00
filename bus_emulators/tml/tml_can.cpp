// bus_emulators/tml — TMLCAN and TechCAN codecs (see tml_can.hpp).
#include "bus_emulators/tml/tml_can.hpp"

namespace omnitwin::tml {

namespace {

constexpr std::uint32_t kTmlCanZeroBits = 0x7u << 10;  // identifier bits 12–10

std::uint8_t lo(std::uint16_t w) { return static_cast<std::uint8_t>(w & 0xFF); }
std::uint8_t hi(std::uint16_t w) { return static_cast<std::uint8_t>(w >> 8); }
std::uint16_t le16(const can::Frame& f, std::size_t i) { return static_cast<std::uint16_t>(f.data[i] | f.data[i + 1] << 8); }

can::Frame data_frame(std::uint32_t id, bool extended) {
  can::Frame f;
  f.id = id, f.extended = extended, f.kind = can::FrameKind::data;
  return f;
}

// Appends words little-endian from byte `at`; returns the next free byte.
std::size_t put_words(can::Frame& f, std::size_t at, std::span<const std::uint16_t> words) {
  for (const std::uint16_t w : words) f.data[at++] = lo(w), f.data[at++] = hi(w);
  return at;
}

// Reads the words of bytes [at, dlc) into m (dlc - at must be even).
void get_words(const can::Frame& f, std::size_t at, Message& m) {
  m.count = 0;
  for (std::size_t i = at; i + 1 < f.dlc && m.count < kMaxDataWords; i += 2) m.data[m.count++] = le16(f, i);
}

bool axis_ok(std::uint8_t axis) { return axis >= 1 && axis <= techcan::max_axis; }

// Normal, host, group and broadcast: opcode then data words, low byte first.
CanStatus encode_plain(const Message& m, std::uint32_t cob, can::Frame& out) {
  if (m.count > 3) return CanStatus::too_many_words;
  out = data_frame(cob, false);
  out.data[0] = lo(m.opcode), out.data[1] = hi(m.opcode);
  out.dlc = static_cast<std::uint8_t>(put_words(out, 2, m.words()));
  return CanStatus::ok;
}

// TakeData: opcode[7:0]; sender ID bits 8–4, its HOST bit, opcode[9:8]; data 2–4.
CanStatus encode_take_data(const Message& m, can::Frame& out) {
  if (m.count < 1) return CanStatus::bad_length;  // no sender word
  const std::uint16_t sender = m.data[0];
  const std::uint8_t axis = id_of(sender);
  if (!axis_ok(axis) || is_group(sender)) return CanStatus::axis_out_of_range;
  // The layout carries the axis and the HOST bit, nothing else: a sender code with other bits
  // set would come back as another code (fuzz.tml_decode: 0x2124 came back as 0x0120).
  if (sender != axis_id_code(axis, is_host(sender))) return CanStatus::bad_identifier;
  out = data_frame(techcan::take_data_base + axis, false);
  out.data[0] = lo(m.opcode);
  out.data[1] = static_cast<std::uint8_t>((axis & 0x1F) << 3 | (is_host(sender) ? 0x04 : 0) | (m.opcode >> 8 & 0x03));
  out.dlc = static_cast<std::uint8_t>(put_words(out, 2, m.words().subspan(1)));
  return CanStatus::ok;
}

// TakeData2: VT/P byte, data 1–3; the sender axis (opcode[7:0]) is in the COB-ID.
CanStatus encode_take_data2(const Message& m, can::Frame& out) {
  const auto axis = static_cast<std::uint8_t>(m.opcode & 0xFF);
  if (!axis_ok(axis)) return CanStatus::axis_out_of_range;
  if (m.count > 3) return CanStatus::too_many_words;
  out = data_frame(techcan::take_data2_base + axis, false);
  out.data[0] = (m.opcode & 0xFF00) == op::take_data2_32 ? techcan::vt_bit : 0;
  out.dlc = static_cast<std::uint8_t>(put_words(out, 1, m.words()));
  return CanStatus::ok;
}

// PVT: no opcode; the 4 words packed into 8 bytes with the counter in byte 7.
CanStatus encode_pvt(const Message& m, can::Frame& out) {
  const std::uint8_t axis = id_of(m.id_code);
  if (!axis_ok(axis) || is_group(m.id_code)) return CanStatus::axis_out_of_range;
  out = data_frame(techcan::pvt_base + axis, false);
  put_words(out, 0, m.words().first(3));
  out.data[6] = lo(m.data[3]);
  out.data[7] = static_cast<std::uint8_t>((m.opcode & 0x7F) << 1 | (m.data[3] >> 8 & 1));
  out.dlc = 8;
  return CanStatus::ok;
}

CanStatus decode_take_data(const can::Frame& f, TechCanMessage& out) {
  if (f.dlc < 2 || f.dlc % 2 != 0) return CanStatus::bad_length;
  out.kind = TechCanKind::take_data, out.destination_known = false;
  Message& m = out.message;
  const std::uint8_t b1 = f.data[1];
  m.opcode = static_cast<std::uint16_t>(techcan::take_data_opcode_msb << 10 | (b1 & 0x03) << 8 | f.data[0]);
  get_words(f, 2, m);  // data 2–4
  for (std::size_t i = m.count; i > 0; --i) m.data[i] = m.data[i - 1];
  m.data[0] = static_cast<std::uint16_t>((b1 >> 3) << 4 | (b1 >> 2 & 1));  // sender ID code
  ++m.count;
  return CanStatus::ok;
}

CanStatus decode_take_data2(const can::Frame& f, TechCanMessage& out) {
  if (f.dlc < 1 || f.dlc % 2 != 1) return CanStatus::bad_length;
  const bool pong = (f.data[0] & techcan::p_bit) != 0;
  const bool wide = (f.data[0] & techcan::vt_bit) != 0;
  out.kind = pong ? TechCanKind::pong : TechCanKind::take_data2;
  out.destination_known = false;
  out.message.opcode = pong ? 0 : static_cast<std::uint16_t>((wide ? op::take_data2_32 : op::take_data2_16) | out.cob_number);
  get_words(f, 1, out.message);
  return CanStatus::ok;
}

CanStatus decode_pvt(const can::Frame& f, TechCanMessage& out) {
  if (f.dlc != 8) return CanStatus::bad_length;
  out.kind = TechCanKind::pvt;
  Message& m = out.message;
  m.id_code = axis_id_code(out.cob_number);
  m.opcode = static_cast<std::uint16_t>(op::pvt | f.data[7] >> 1);
  m.count = 4;
  m.data = {le16(f, 0), le16(f, 2), le16(f, 4), static_cast<std::uint16_t>(f.data[6] | (f.data[7] & 1) << 8)};
  return CanStatus::ok;
}

// Normal, host, group, broadcast.
CanStatus decode_plain(const can::Frame& f, TechCanKind kind, std::uint16_t id_code, TechCanMessage& out) {
  if (f.dlc < 2 || f.dlc % 2 != 0) return CanStatus::bad_length;
  out.kind = kind;
  out.message.id_code = id_code;
  out.message.opcode = le16(f, 0);
  get_words(f, 2, out.message);
  return CanStatus::ok;
}

}  // namespace

const char* to_string(CanStatus s) {
  switch (s) {
    case CanStatus::ok: return "ok";
    case CanStatus::wrong_format: return "wrong identifier format (TMLCAN: 29-bit, TechCAN: 11-bit)";
    case CanStatus::not_data_frame: return "not a data frame";
    case CanStatus::bad_identifier: return "identifier not valid for TML (bits 12-10 must be 0; bad ID code)";
    case CanStatus::bad_length: return "data length does not fit the message layout";
    case CanStatus::too_many_words: return "too many data words for this layout";
    case CanStatus::axis_out_of_range: return "axis out of range (TechCAN: 1-31)";
    case CanStatus::group_out_of_range: return "group out of range (TechCAN: group mask 1-31, groups 1-5)";
    case CanStatus::unknown_cob_id: return "COB-ID outside the TechCAN ranges";
  }
  return "?";
}

const char* to_string(TechCanKind k) {
  switch (k) {
    case TechCanKind::group: return "group";
    case TechCanKind::sync: return "synchronisation";
    case TechCanKind::pvt: return "PVT";
    case TechCanKind::take_data2: return "TakeData2";
    case TechCanKind::pong: return "PONG";
    case TechCanKind::normal: return "normal";
    case TechCanKind::host: return "host";
    case TechCanKind::take_data: return "TakeData";
    case TechCanKind::broadcast: return "broadcast";
  }
  return "?";
}

// ---- TMLCAN ------------------------------------------------------------------------------------

CanStatus encode_tmlcan(const Message& m, can::Frame& out) {
  if (!id_code_valid(m.id_code)) return CanStatus::bad_identifier;
  if (m.count > kMaxDataWords) return CanStatus::too_many_words;
  out = data_frame(tmlcan_identifier(m.id_code, m.opcode), true);
  out.dlc = static_cast<std::uint8_t>(put_words(out, 0, m.words()));
  return CanStatus::ok;
}

CanStatus decode_tmlcan(const can::Frame& f, Message& out) {
  if (!f.extended) return CanStatus::wrong_format;
  if (f.kind != can::FrameKind::data) return CanStatus::not_data_frame;
  if (f.id > 0x1FFFFFFF || (f.id & kTmlCanZeroBits) != 0) return CanStatus::bad_identifier;
  if (f.dlc > 8 || f.dlc % 2 != 0) return CanStatus::bad_length;
  out = Message{};
  out.opcode = static_cast<std::uint16_t>((f.id >> 22) << 9 | (f.id & 0x1FF));
  out.id_code = static_cast<std::uint16_t>((f.id >> 9) & kIdCodeMask);
  get_words(f, 0, out);
  return CanStatus::ok;
}

// ---- TechCAN -----------------------------------------------------------------------------------

CanStatus encode_techcan(const Message& m, can::Frame& out) {
  if (!m.valid()) return CanStatus::bad_identifier;
  const Classified c = classify(m);
  // The packed layouts first.
  if (c.kind == Kind::take_data) return encode_take_data(m, out);
  if (c.kind == Kind::take_data2) return encode_take_data2(m, out);
  if (c.kind == Kind::pvt && c.complete && !is_group(m.id_code)) return encode_pvt(m, out);
  // The synchronisation frame carries no data: only a SYNC without data words takes that layout
  // (opcode 0x1000 with data goes as a plain broadcast, so decoding gives back what was sent).
  if (c.kind == Kind::sync && is_broadcast(m.id_code) && m.count == 0) {
    out = data_frame(techcan::sync_id, false);  // no data bytes
    return CanStatus::ok;
  }
  // Then by destination.
  const std::uint8_t id = id_of(m.id_code);
  if (is_broadcast(m.id_code)) return encode_plain(m, techcan::broadcast_id, out);
  if (is_group(m.id_code)) {
    if (id > techcan::max_group_mask) return CanStatus::group_out_of_range;
    return encode_plain(m, techcan::group_base + id, out);
  }
  if (!axis_ok(id)) return CanStatus::axis_out_of_range;
  return encode_plain(m, (is_host(m.id_code) ? techcan::host_base : techcan::normal_base) + id, out);
}

CanStatus encode_techcan_pong(std::uint8_t axis, std::span<const std::uint16_t> words, can::Frame& out) {
  if (!axis_ok(axis)) return CanStatus::axis_out_of_range;
  if (words.size() > 3) return CanStatus::too_many_words;
  out = data_frame(techcan::take_data2_base + axis, false);
  out.data[0] = techcan::p_bit;
  out.dlc = static_cast<std::uint8_t>(put_words(out, 1, words));
  return CanStatus::ok;
}

CanStatus decode_techcan(const can::Frame& f, TechCanMessage& out) {
  if (f.extended) return CanStatus::wrong_format;
  if (f.kind != can::FrameKind::data) return CanStatus::not_data_frame;
  if (f.dlc > 8) return CanStatus::bad_length;
  out = TechCanMessage{};
  const std::uint32_t id = f.id;
  const auto n = static_cast<std::uint8_t>(id & 0x1F);
  out.cob_number = n;
  // Dispatch on the COB-ID range.
  if (id >= 0x001 && id <= 0x01F) return decode_plain(f, TechCanKind::group, group_id_code(n), out);
  if (id == techcan::sync_id) {
    if (f.dlc != 0) return CanStatus::bad_length;
    out.kind = TechCanKind::sync, out.message = sync_message(), out.cob_number = 0;
    return CanStatus::ok;
  }
  if (id == techcan::broadcast_id) {
    out.cob_number = 0;
    return decode_plain(f, TechCanKind::broadcast, group_id_code(0), out);
  }
  if (n == 0 || id > 0x17F) return CanStatus::unknown_cob_id;
  switch (id & ~0x1Fu) {
    case techcan::pvt_base: return decode_pvt(f, out);
    case techcan::take_data2_base: return decode_take_data2(f, out);
    case techcan::normal_base: return decode_plain(f, TechCanKind::normal, axis_id_code(n), out);
    case techcan::host_base: return decode_plain(f, TechCanKind::host, axis_id_code(n, true), out);
    case techcan::take_data_base: return decode_take_data(f, out);
    default: return CanStatus::unknown_cob_id;
  }
}

}  // namespace omnitwin::tml
