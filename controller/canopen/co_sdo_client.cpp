// controller/canopen — the SDO client core (see co_sdo_client.hpp).
#include "controller/canopen/co_sdo_client.hpp"

#include <algorithm>
#include <stdexcept>

namespace omnitwin::controller::canopen {

namespace cob = omnitwin::canopen::cob;
using namespace omnitwin::canopen::sdo;

const char* to_string(TransferMode m) {
  switch (m) {
    case TransferMode::automatic: return "automatic";
    case TransferMode::segmented: return "segmented";
    case TransferMode::block: return "block";
  }
  return "?";
}

const char* to_string(SdoStatus s) {
  switch (s) {
    case SdoStatus::idle: return "idle";
    case SdoStatus::busy: return "busy";
    case SdoStatus::done: return "done";
    case SdoStatus::aborted: return "aborted";
  }
  return "?";
}

const char* to_string(SdoStart s) {
  switch (s) {
    case SdoStart::ok: return "ok";
    case SdoStart::busy: return "a transfer to this node is running";
    case SdoStart::no_channel: return "no free SDO channel";
    case SdoStart::bad_node: return "invalid node ID";
    case SdoStart::too_long: return "data longer than the transfer buffer";
  }
  return "?";
}

SdoClient::SdoClient(SendFn send, SdoClientConfig cfg, SdoDoneFn done)
    : send_(std::move(send)), cfg_(cfg), done_(std::move(done)) {
  if (!send_) throw std::invalid_argument("SdoClient: no send function");
  if (cfg_.channels == 0) throw std::invalid_argument("SdoClient: at least one channel");
  if (cfg_.blksize < 1 || cfg_.blksize > kMaxBlockSize) throw std::invalid_argument("SdoClient: blksize must be 1..127");
  channels_.resize(cfg_.channels);
  // Room for the padding of a block upload's last segment beyond the largest object.
  for (auto& c : channels_) c.buf.assign(cfg_.max_object_bytes + kSegmentData, 0);
}

SdoClient::Channel* SdoClient::channel_for(std::uint8_t node) {
  for (auto& c : channels_)
    if (c.used && c.result.node == node) return &c;
  return nullptr;
}
const SdoClient::Channel* SdoClient::channel_for(std::uint8_t node) const {
  return const_cast<SdoClient*>(this)->channel_for(node);
}

bool SdoClient::busy(std::uint8_t node) const {
  const Channel* c = channel_for(node);
  return c && c->phase != Phase::idle;
}

const SdoResult* SdoClient::result(std::uint8_t node) const {
  const Channel* c = channel_for(node);
  return c ? &c->result : nullptr;
}

SdoClient::Channel* SdoClient::start(std::uint8_t node, std::uint16_t index, std::uint8_t sub, SimTime t,
                                     TransferMode mode, SdoStart& st) {
  if (!omnitwin::canopen::valid_node_id(node)) return st = SdoStart::bad_node, nullptr;
  Channel* c = channel_for(node);
  if (c && c->phase != Phase::idle) return st = SdoStart::busy, nullptr;
  // A node keeps its channel; otherwise the least recently used free one.
  if (!c) {
    for (auto& k : channels_)
      if (k.phase == Phase::idle && (!c || k.used < c->used)) c = &k;
  }
  if (!c) return st = SdoStart::no_channel, nullptr;
  c->result = SdoResult{};
  c->result.status = SdoStatus::busy;
  c->result.mode = mode;
  c->result.node = node;
  c->result.index = index;
  c->result.sub = sub;
  c->used = ++uses_;
  c->last = t;
  c->toggle = c->expedited = c->sized = c->crc = c->last_seen = false;
  c->size = c->pos = 0;
  c->blksize = c->seq = c->sent = 0;
  ++stats_.started;
  st = SdoStart::ok;
  return c;
}

SdoStart SdoClient::upload(std::uint8_t node, std::uint16_t index, std::uint8_t sub, SimTime t, TransferMode mode) {
  SdoStart st{};
  Channel* c = start(node, index, sub, t, mode, st);
  if (!c) return st;
  c->result.upload = true;
  if (mode == TransferMode::block) {
    BlockInitiate m;
    m.index = index;
    m.sub = sub;
    m.crc = cfg_.crc;
    m.blksize = cfg_.blksize;
    m.pst = 0;  // never switch to a normal upload
    c->phase = Phase::blk_up_init;
    send(*c, encode_block_upload_initiate(m), t);
  } else {
    c->phase = Phase::up_initiate;
    send(*c, encode_initiate_upload({index, sub}), t);
  }
  return SdoStart::ok;
}

SdoStart SdoClient::download(std::uint8_t node, std::uint16_t index, std::uint8_t sub,
                             std::span<const std::uint8_t> bytes, SimTime t, TransferMode mode) {
  if (bytes.size() > cfg_.max_object_bytes) return SdoStart::too_long;
  SdoStart st{};
  Channel* c = start(node, index, sub, t, mode, st);
  if (!c) return st;
  std::copy(bytes.begin(), bytes.end(), c->buf.begin());
  c->size = bytes.size();
  if (mode == TransferMode::block) {
    BlockInitiate m;
    m.index = index;
    m.sub = sub;
    m.crc = cfg_.crc;
    m.sized = true;
    m.size = static_cast<std::uint32_t>(bytes.size());
    c->phase = Phase::blk_down_init;
    send(*c, encode_block_download_initiate(m), t);
    return SdoStart::ok;
  }
  // Expedited for 1..4 bytes unless segmented was asked for; size always indicated.
  Initiate m;
  m.index = index;
  m.sub = sub;
  m.sized = true;
  m.size = static_cast<std::uint32_t>(bytes.size());
  m.expedited = c->expedited = mode == TransferMode::automatic && !bytes.empty() && bytes.size() <= 4;
  if (m.expedited) std::copy(bytes.begin(), bytes.end(), m.data.begin());
  c->phase = Phase::down_initiate;
  send(*c, encode_initiate_download(m), t);
  return SdoStart::ok;
}

bool SdoClient::cancel(std::uint8_t node, SimTime t, SdoAbort code) {
  Channel* c = channel_for(node);
  if (!c || c->phase == Phase::idle) return false;
  fail(*c, code, t);
  return true;
}

void SdoClient::on_time(SimTime t) {
  for (auto& c : channels_) {
    if (c.phase == Phase::idle || t - c.last < cfg_.timeout_ns) continue;
    ++stats_.timeouts;
    fail(c, SdoAbort::timeout, t);
  }
}

void SdoClient::on_frame(const can::Frame& f, SimTime t) {
  if (f.extended || f.kind != can::FrameKind::data) return;
  if (f.id <= cob::sdo_tx || f.id >= cob::sdo_tx + 0x80) return;
  Channel* c = channel_for(static_cast<std::uint8_t>(f.id - cob::sdo_tx));
  if (!c || c->phase == Phase::idle) {
    ++stats_.ignored;
    return;
  }
  c->last = t;
  if (f.dlc != 8) return fail(*c, SdoAbort::invalid_command, t);  // as the server does
  response(*c, f.data, t);
}

void SdoClient::send(const Channel& c, const Payload& p, SimTime t) {
  if (!send_(make_frame(cob::sdo_rx + c.result.node, p), t)) ++stats_.send_failures;
}

void SdoClient::finish(Channel& c) {
  c.phase = Phase::idle;
  if (c.result.status == SdoStatus::done) ++stats_.done;
  else ++stats_.aborted;
  if (done_) done_(c.result);
}

void SdoClient::fail(Channel& c, SdoAbort code, SimTime t) {
  ++stats_.aborts_sent;
  send(c, encode_abort({c.result.index, c.result.sub, code}), t);
  c.result.status = SdoStatus::aborted;
  c.result.code = code;
  c.result.server_abort = false;
  finish(c);
}

void SdoClient::response(Channel& c, const Payload& p, SimTime t) {
  const std::uint8_t b0 = p[0], scs = specifier(b0);
  // In a sub-block every frame is a segment, except the server's abort (seqno 0 is never valid).
  if (c.phase == Phase::blk_up_sub && b0 != 0x80) return blk_up_segment(c, p, t);
  if (scs == static_cast<std::uint8_t>(Scs::abort)) {
    Abort a;
    decode_abort(p, a);
    ++stats_.aborts_received;
    c.result.status = SdoStatus::aborted;
    c.result.code = a.code;
    c.result.server_abort = true;
    return finish(c);
  }
  // Initiate responses must name our object.
  const ObjectRef o = object_of(p);
  const bool ours = o.index == c.result.index && o.sub == c.result.sub;
  switch (c.phase) {
    case Phase::up_initiate:
      if (scs == static_cast<std::uint8_t>(Scs::initiate_upload) && ours) return up_initiate(c, p, t);
      break;
    case Phase::up_segment:
      if (scs == static_cast<std::uint8_t>(Scs::upload_segment)) return up_segment(c, p, t);
      break;
    case Phase::down_initiate:
      if (scs != static_cast<std::uint8_t>(Scs::initiate_download) || !ours) break;
      if (!c.expedited) return down_next_segment(c, t);
      c.result.status = SdoStatus::done;
      return finish(c);
    case Phase::down_segment:
      if (scs != static_cast<std::uint8_t>(Scs::download_segment)) break;
      if (toggle_of(b0) != c.toggle) return fail(c, SdoAbort::toggle, t);
      c.toggle = !c.toggle;
      if (!c.last_seen) return down_next_segment(c, t);
      c.result.status = SdoStatus::done;
      return finish(c);
    case Phase::blk_down_init: {
      BlockInitiate m;
      const FrameStatus st = decode_block_download_initiate_response(p, m);
      if (st == FrameStatus::bad_block_size) return fail(c, SdoAbort::invalid_block_size, t);
      if (st != FrameStatus::ok || !ours) break;
      c.blksize = m.blksize;
      c.crc = cfg_.crc && m.crc;
      return blk_down_sub_block(c, t);
    }
    case Phase::blk_down_ack:
      if (scs == static_cast<std::uint8_t>(Scs::block_download) && (b0 & 0x03) == block_cs::ack)
        return blk_down_ack(c, p, t);
      break;
    case Phase::blk_down_end:
      if (!is_block_end_response(p)) break;
      c.result.status = SdoStatus::done;
      return finish(c);
    case Phase::blk_up_init:
      if (scs == static_cast<std::uint8_t>(Scs::block_upload) && (b0 & 0x01) == block_cs::initiate && ours)
        return blk_up_init(c, p, t);
      break;
    case Phase::blk_up_end:
      if (scs == static_cast<std::uint8_t>(Scs::block_upload) && (b0 & 0x01) == block_cs::end) return blk_up_end(c, p, t);
      break;
    case Phase::blk_up_sub:
    case Phase::idle: break;
  }
  fail(c, SdoAbort::invalid_command, t);
}

// ---- expedited / segmented ---------------------------------------------------------------

void SdoClient::up_initiate(Channel& c, const Payload& p, SimTime t) {
  Initiate m;
  decode_initiate(p, m);
  if (m.expedited) {
    std::copy_n(m.data.begin(), m.size, c.buf.begin());
    c.result.data = {c.buf.data(), m.size};
    c.result.status = SdoStatus::done;
    return finish(c);
  }
  if (m.sized && m.size > cfg_.max_object_bytes) return fail(c, SdoAbort::out_of_memory, t);
  c.sized = m.sized;
  c.size = m.size;
  c.phase = Phase::up_segment;
  send(c, encode_upload_segment_request(c.toggle), t);
}

void SdoClient::up_segment(Channel& c, const Payload& p, SimTime t) {
  Segment g;
  decode_segment(p, g);
  if (g.toggle != c.toggle) return fail(c, SdoAbort::toggle, t);
  if (c.sized && c.pos + g.len > c.size) return fail(c, SdoAbort::length_mismatch, t);
  if (c.pos + g.len > cfg_.max_object_bytes) return fail(c, SdoAbort::out_of_memory, t);
  std::copy_n(g.data.begin(), g.len, c.buf.begin() + static_cast<std::ptrdiff_t>(c.pos));
  c.pos += g.len;
  c.toggle = !c.toggle;
  if (!g.last) return send(c, encode_upload_segment_request(c.toggle), t);
  if (c.sized && c.pos != c.size) return fail(c, SdoAbort::length_mismatch, t);
  c.result.data = {c.buf.data(), c.pos};
  c.result.status = SdoStatus::done;
  finish(c);
}

void SdoClient::down_next_segment(Channel& c, SimTime t) {
  Segment g;
  g.toggle = c.toggle;
  g.len = static_cast<std::uint8_t>(std::min(kSegmentData, c.size - c.pos));
  g.last = c.last_seen = c.pos + g.len == c.size;
  std::copy_n(c.buf.begin() + static_cast<std::ptrdiff_t>(c.pos), g.len, g.data.begin());
  c.pos += g.len;
  c.phase = Phase::down_segment;
  send(c, encode_segment(g), t);
}

// ---- block download -----------------------------------------------------------------------

void SdoClient::blk_down_sub_block(Channel& c, SimTime t) {
  // Up to the server's blksize segments from the first byte not yet acknowledged.
  c.sent = 0;
  c.last_seen = false;
  std::size_t at = c.pos;
  while (c.sent < c.blksize && !c.last_seen) {
    const std::size_t n = std::min(kSegmentData, c.size - at);
    BlockSegment g;
    g.seqno = ++c.sent;
    g.last = c.last_seen = at + n >= c.size;
    std::copy_n(c.buf.begin() + static_cast<std::ptrdiff_t>(at), n, g.data.begin());
    at += n;
    send(c, encode_block_segment(g), t);
  }
  c.phase = Phase::blk_down_ack;
}

void SdoClient::blk_down_ack(Channel& c, const Payload& p, SimTime t) {
  BlockAck a;
  if (decode_block_ack(p, a) == FrameStatus::bad_block_size) return fail(c, SdoAbort::invalid_block_size, t);
  if (a.ackseq > c.sent) return fail(c, abort_invalid_seqno, t);
  stats_.retransmitted += c.sent - a.ackseq;
  c.pos = std::min(c.size, c.pos + std::size_t{a.ackseq} * kSegmentData);
  c.blksize = a.blksize;
  if (!c.last_seen || a.ackseq != c.sent) return blk_down_sub_block(c, t);
  // Everything acknowledged: the end request with the CRC of the whole data.
  BlockEnd e;
  e.unused = block_unused(c.size);
  e.crc = c.crc ? crc16({c.buf.data(), c.size}) : 0;
  c.phase = Phase::blk_down_end;
  send(c, encode_block_end(e), t);
}

// ---- block upload -------------------------------------------------------------------------

void SdoClient::blk_up_init(Channel& c, const Payload& p, SimTime t) {
  BlockInitiate m;
  decode_block_upload_initiate_response(p, m);
  if (m.sized && m.size > cfg_.max_object_bytes) return fail(c, SdoAbort::out_of_memory, t);
  c.sized = m.sized;
  c.size = m.size;
  c.crc = cfg_.crc && m.crc;
  c.phase = Phase::blk_up_sub;
  send(c, encode_block_upload_start(), t);
}

void SdoClient::blk_up_segment(Channel& c, const Payload& p, SimTime t) {
  BlockSegment g;
  if (decode_block_segment(p, g) != FrameStatus::ok || g.seqno > cfg_.blksize)
    return fail(c, abort_invalid_seqno, t);
  if (g.seqno == c.seq + 1) {
    // In order: keep all 7 bytes (the end request says how many of the last one count).
    if (c.pos + kSegmentData > c.buf.size()) return fail(c, SdoAbort::out_of_memory, t);
    std::copy_n(g.data.begin(), kSegmentData, c.buf.begin() + static_cast<std::ptrdiff_t>(c.pos));
    c.pos += kSegmentData;
    c.seq = g.seqno;
    c.last_seen = g.last;
  }
  // Out of order: discarded; the ack tells the server where to resume.
  if (g.seqno != cfg_.blksize && !g.last) return;
  BlockAck a;
  a.ackseq = c.seq;
  a.blksize = cfg_.blksize;
  c.seq = 0;
  if (c.last_seen) c.phase = Phase::blk_up_end;
  send(c, encode_block_ack(a), t);
}

void SdoClient::blk_up_end(Channel& c, const Payload& p, SimTime t) {
  BlockEnd e;
  decode_block_end(p, e);
  const std::size_t n = c.pos - std::min<std::size_t>(e.unused, c.pos);
  if (c.sized && n != c.size) return fail(c, SdoAbort::length_mismatch, t);
  if (n > cfg_.max_object_bytes) return fail(c, SdoAbort::out_of_memory, t);
  if (c.crc && crc16({c.buf.data(), n}) != e.crc) return fail(c, abort_crc, t);
  send(c, encode_block_end_response(), t);
  c.result.data = {c.buf.data(), n};
  c.result.status = SdoStatus::done;
  finish(c);
}

}  // namespace omnitwin::controller::canopen
