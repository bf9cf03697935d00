// bus_emulators/canopen — SDO frame layer (see co_sdo.hpp).
#include "bus_emulators/canopen/co_sdo.hpp"

#include <algorithm>

namespace omnitwin::canopen::sdo {

namespace {

constexpr std::uint8_t cmd(std::uint8_t specifier) { return static_cast<std::uint8_t>(specifier << 5); }
constexpr std::uint8_t cmd(Ccs c) { return cmd(static_cast<std::uint8_t>(c)); }
constexpr std::uint8_t cmd(Scs s) { return cmd(static_cast<std::uint8_t>(s)); }

void put_object(Payload& p, std::uint16_t index, std::uint8_t sub) {
  put_u16(p.data() + 1, index);
  p[3] = sub;
}

bool valid_blksize(std::uint8_t n) { return n >= 1 && n <= kMaxBlockSize; }

// The CRC table of the CCITT polynomial 0x1021 (MSB first), built at compile time.
constexpr std::array<std::uint16_t, 256> make_crc_table() {
  std::array<std::uint16_t, 256> t{};
  for (unsigned i = 0; i < 256; ++i) {
    unsigned c = i << 8;
    for (int b = 0; b < 8; ++b) c = (c & 0x8000u) ? ((c << 1) ^ 0x1021u) : (c << 1);
    t[i] = static_cast<std::uint16_t>(c);
  }
  return t;
}
constexpr auto kCrcTable = make_crc_table();

}  // namespace

const char* abort_text(SdoAbort a) {
  if (a == abort_invalid_seqno) return "invalid sequence number";
  if (a == abort_crc) return "CRC error";
  return ethercat::to_string(a);
}

const char* to_string(FrameStatus s) {
  switch (s) {
    case FrameStatus::ok: return "ok";
    case FrameStatus::not_sdo: return "not an 8-byte data frame";
    case FrameStatus::wrong_command: return "wrong command specifier";
    case FrameStatus::bad_seqno: return "invalid sequence number";
    case FrameStatus::bad_block_size: return "invalid block size";
  }
  return "?";
}

FrameStatus payload_of(const can::Frame& f, Payload& out) {
  if (f.extended || f.kind != can::FrameKind::data || f.dlc != 8) return FrameStatus::not_sdo;
  out = f.data;
  return FrameStatus::ok;
}

can::Frame make_frame(std::uint32_t cob_id, const Payload& p) {
  can::Frame f = frame11(cob_id, 8);
  f.data = p;
  return f;
}

// ---- expedited / segmented ---------------------------------------------------------------

namespace {
Payload encode_initiate(std::uint8_t c, const Initiate& m) {
  Payload p{};
  const std::uint32_t n = m.expedited && m.sized ? std::clamp<std::uint32_t>(m.size, 1, 4) : 4;
  p[0] = static_cast<std::uint8_t>(c | (m.expedited ? 0x02 : 0) | (m.sized ? 0x01 : 0) |
                                   (m.expedited && m.sized ? (4 - n) << 2 : 0));
  put_object(p, m.index, m.sub);
  if (m.expedited) std::copy_n(m.data.begin(), n, p.begin() + 4);
  else if (m.sized) put_u32(p.data() + 4, m.size);
  return p;
}
}  // namespace

Payload encode_initiate_download(const Initiate& m) { return encode_initiate(cmd(Ccs::initiate_download), m); }
Payload encode_initiate_upload_response(const Initiate& m) { return encode_initiate(cmd(Scs::initiate_upload), m); }

FrameStatus decode_initiate(const Payload& p, Initiate& m) {
  const std::uint8_t s = specifier(p[0]);
  if (s != 1 && s != 2) return FrameStatus::wrong_command;
  m.index = get_u16(p.data() + 1);
  m.sub = p[3];
  m.expedited = (p[0] & 0x02) != 0;
  m.sized = (p[0] & 0x01) != 0;
  m.data = {};
  if (m.expedited) {
    m.size = m.sized ? 4u - ((p[0] >> 2) & 3u) : 4u;
    std::copy_n(p.begin() + 4, 4, m.data.begin());
  } else {
    m.size = m.sized ? get_u32(p.data() + 4) : 0;
  }
  return FrameStatus::ok;
}

ObjectRef object_of(const Payload& p) { return {get_u16(p.data() + 1), p[3]}; }

Payload encode_initiate_upload(ObjectRef o) {
  Payload p{};
  p[0] = cmd(Ccs::initiate_upload);
  put_object(p, o.index, o.sub);
  return p;
}

Payload encode_initiate_download_response(ObjectRef o) {
  Payload p{};
  p[0] = cmd(Scs::initiate_download);
  put_object(p, o.index, o.sub);
  return p;
}

Payload encode_segment(const Segment& s) {
  Payload p{};
  const std::uint8_t n = std::min<std::uint8_t>(s.len, 7);
  p[0] = static_cast<std::uint8_t>((s.toggle ? 0x10 : 0) | ((7 - n) << 1) | (s.last ? 0x01 : 0));
  std::copy_n(s.data.begin(), n, p.begin() + 1);
  return p;
}

FrameStatus decode_segment(const Payload& p, Segment& s) {
  if (specifier(p[0]) != 0) return FrameStatus::wrong_command;
  s.toggle = toggle_of(p[0]);
  s.last = (p[0] & 0x01) != 0;
  s.len = static_cast<std::uint8_t>(7 - ((p[0] >> 1) & 7));
  std::copy_n(p.begin() + 1, 7, s.data.begin());
  return FrameStatus::ok;
}

Payload encode_upload_segment_request(bool toggle) {
  Payload p{};
  p[0] = static_cast<std::uint8_t>(cmd(Ccs::upload_segment) | (toggle ? 0x10 : 0));
  return p;
}

Payload encode_download_segment_response(bool toggle) {
  Payload p{};
  p[0] = static_cast<std::uint8_t>(cmd(Scs::download_segment) | (toggle ? 0x10 : 0));
  return p;
}

Payload encode_abort(const Abort& a) {
  Payload p{};
  p[0] = cmd(Ccs::abort);
  put_object(p, a.index, a.sub);
  put_u32(p.data() + 4, static_cast<std::uint32_t>(a.code));
  return p;
}

FrameStatus decode_abort(const Payload& p, Abort& a) {
  if (specifier(p[0]) != 4) return FrameStatus::wrong_command;
  a.index = get_u16(p.data() + 1);
  a.sub = p[3];
  a.code = static_cast<SdoAbort>(get_u32(p.data() + 4));
  return FrameStatus::ok;
}

// ---- block ----------------------------------------------------------------------------------

Payload encode_block_download_initiate(const BlockInitiate& m) {
  Payload p{};
  p[0] = static_cast<std::uint8_t>(cmd(Ccs::block_download) | (m.crc ? 0x04 : 0) | (m.sized ? 0x02 : 0));
  put_object(p, m.index, m.sub);
  if (m.sized) put_u32(p.data() + 4, m.size);
  return p;
}

Payload encode_block_download_initiate_response(const BlockInitiate& m) {
  Payload p{};
  p[0] = static_cast<std::uint8_t>(cmd(Scs::block_download) | (m.crc ? 0x04 : 0));
  put_object(p, m.index, m.sub);
  p[4] = m.blksize;
  return p;
}

Payload encode_block_upload_initiate(const BlockInitiate& m) {
  Payload p{};
  p[0] = static_cast<std::uint8_t>(cmd(Ccs::block_upload) | (m.crc ? 0x04 : 0));
  put_object(p, m.index, m.sub);
  p[4] = m.blksize;
  p[5] = m.pst;
  return p;
}

Payload encode_block_upload_initiate_response(const BlockInitiate& m) {
  Payload p{};
  p[0] = static_cast<std::uint8_t>(cmd(Scs::block_upload) | (m.crc ? 0x04 : 0) | (m.sized ? 0x02 : 0));
  put_object(p, m.index, m.sub);
  if (m.sized) put_u32(p.data() + 4, m.size);
  return p;
}

namespace {
// Fields common to every block initiate; which of size/blksize/pst count is the caller's.
void decode_block_common(const Payload& p, BlockInitiate& m) {
  m.index = get_u16(p.data() + 1);
  m.sub = p[3];
  m.crc = (p[0] & 0x04) != 0;
  m.sized = false;
  m.size = 0;
  m.blksize = 0;
  m.pst = 0;
}
}  // namespace

FrameStatus decode_block_download_initiate(const Payload& p, BlockInitiate& m) {
  if (specifier(p[0]) != 6 || (p[0] & 0x01) != block_cs::initiate) return FrameStatus::wrong_command;
  decode_block_common(p, m);
  m.sized = (p[0] & 0x02) != 0;
  m.size = m.sized ? get_u32(p.data() + 4) : 0;
  return FrameStatus::ok;
}

FrameStatus decode_block_download_initiate_response(const Payload& p, BlockInitiate& m) {
  if (specifier(p[0]) != 5 || (p[0] & 0x03) != block_cs::initiate) return FrameStatus::wrong_command;
  decode_block_common(p, m);
  m.blksize = p[4];
  return valid_blksize(m.blksize) ? FrameStatus::ok : FrameStatus::bad_block_size;
}

FrameStatus decode_block_upload_initiate(const Payload& p, BlockInitiate& m) {
  if (specifier(p[0]) != 5 || (p[0] & 0x03) != block_cs::initiate) return FrameStatus::wrong_command;
  decode_block_common(p, m);
  m.blksize = p[4];
  m.pst = p[5];
  return valid_blksize(m.blksize) ? FrameStatus::ok : FrameStatus::bad_block_size;
}

FrameStatus decode_block_upload_initiate_response(const Payload& p, BlockInitiate& m) {
  if (specifier(p[0]) != 6 || (p[0] & 0x01) != block_cs::initiate) return FrameStatus::wrong_command;
  decode_block_common(p, m);
  m.sized = (p[0] & 0x02) != 0;
  m.size = m.sized ? get_u32(p.data() + 4) : 0;
  return FrameStatus::ok;
}

Payload encode_block_upload_start() {
  Payload p{};
  p[0] = static_cast<std::uint8_t>(cmd(Ccs::block_upload) | block_cs::start);
  return p;
}

Payload encode_block_segment(const BlockSegment& s) {
  Payload p{};
  p[0] = static_cast<std::uint8_t>((s.last ? 0x80 : 0) | (s.seqno & 0x7F));
  std::copy_n(s.data.begin(), 7, p.begin() + 1);
  return p;
}

FrameStatus decode_block_segment(const Payload& p, BlockSegment& s) {
  s.last = (p[0] & 0x80) != 0;
  s.seqno = static_cast<std::uint8_t>(p[0] & 0x7F);
  std::copy_n(p.begin() + 1, 7, s.data.begin());
  return s.seqno == 0 ? FrameStatus::bad_seqno : FrameStatus::ok;
}

Payload encode_block_ack(const BlockAck& a) {
  Payload p{};
  p[0] = static_cast<std::uint8_t>(cmd(Scs::block_download) | block_cs::ack);
  p[1] = a.ackseq;
  p[2] = a.blksize;
  return p;
}

FrameStatus decode_block_ack(const Payload& p, BlockAck& a) {
  if (specifier(p[0]) != 5 || (p[0] & 0x03) != block_cs::ack) return FrameStatus::wrong_command;
  a.ackseq = p[1];
  a.blksize = p[2];
  return valid_blksize(a.blksize) ? FrameStatus::ok : FrameStatus::bad_block_size;
}

Payload encode_block_end(const BlockEnd& e) {
  Payload p{};
  p[0] = static_cast<std::uint8_t>(cmd(Ccs::block_download) | ((e.unused & 7) << 2) | block_cs::end);
  put_u16(p.data() + 1, e.crc);
  return p;
}

FrameStatus decode_block_end(const Payload& p, BlockEnd& e) {
  if (specifier(p[0]) != 6 || (p[0] & 0x01) != block_cs::end) return FrameStatus::wrong_command;
  e.unused = static_cast<std::uint8_t>((p[0] >> 2) & 7);
  e.crc = get_u16(p.data() + 1);
  return FrameStatus::ok;
}

Payload encode_block_end_response() {
  Payload p{};
  p[0] = static_cast<std::uint8_t>(cmd(Scs::block_download) | block_cs::end);
  return p;
}

bool is_block_end_response(const Payload& p) { return specifier(p[0]) == 5 && (p[0] & 0x03) == block_cs::end; }

std::uint16_t crc16(std::span<const std::uint8_t> data, std::uint16_t crc) noexcept {
  for (const std::uint8_t b : data)
    crc = static_cast<std::uint16_t>((crc << 8) ^ kCrcTable[((crc >> 8) ^ b) & 0xFFu]);
  return crc;
}

}  // namespace omnitwin::canopen::sdo
