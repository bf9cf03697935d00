// bus_emulators/canopen — the SDO server of a node (see co_sdo_server.hpp).
#include "bus_emulators/canopen/co_sdo_server.hpp"

#include <algorithm>
#include <stdexcept>

namespace omnitwin::canopen {

using namespace sdo;

std::uint64_t SdoServerStats::aborts_with(SdoAbort code) const {
  for (std::size_t i = 0; i < kCodes; ++i)
    if (abort_count[i] && abort_code[i] == static_cast<std::uint32_t>(code)) return abort_count[i];
  return 0;
}

SdoServer::SdoServer(ObjectDictionary& od, std::uint8_t node_id, SendFn send, SdoServerConfig cfg)
    : od_(od), node_(node_id), send_(std::move(send)), cfg_(cfg) {
  if (!valid_node_id(node_id)) throw std::invalid_argument("SdoServer: node ID must be 1..127");
  if (cfg_.blksize < 1 || cfg_.blksize > kMaxBlockSize) throw std::invalid_argument("SdoServer: blksize must be 1..127");
  if (!send_) throw std::invalid_argument("SdoServer: no send function");
  // Room for the padding of a block download's last segment beyond the largest object.
  buf_.assign(cfg_.max_object_bytes + kSegmentData, 0);
}

void SdoServer::reset() { state_ = State::idle; }

void SdoServer::on_time(SimTime t) {
  if (state_ == State::idle || t - last_ < cfg_.timeout_ns) return;
  ++stats_.timeouts;
  now_ = t;
  abort_transfer(SdoAbort::timeout);
}

void SdoServer::on_frame(const can::Frame& f, SimTime t, OdState state) {
  if (f.extended || f.kind != can::FrameKind::data || f.id != rx_cob()) return;
  ++stats_.requests;
  now_ = t;
  if (f.dlc != 8) {
    // Not an SDO request: abort (naming the running transfer's object, else the frame's).
    if (state_ != State::idle) return abort_transfer(SdoAbort::invalid_command);
    const bool has_object = f.dlc >= 4;
    return abort(has_object ? get_u16(f.data.data() + 1) : 0, has_object ? f.data[3] : 0, SdoAbort::invalid_command);
  }
  request(f.data, state);
}

void SdoServer::send(const Payload& p) {
  if (!send_(make_frame(tx_cob(), p), now_)) ++stats_.send_failures;
}

void SdoServer::count_abort(SdoAbort code) {
  ++stats_.aborts_sent;
  for (std::size_t i = 0; i < SdoServerStats::kCodes; ++i) {
    // A free slot has count 0; the first slot with this code or free takes it.
    if (stats_.abort_count[i] == 0 || stats_.abort_code[i] == static_cast<std::uint32_t>(code)) {
      stats_.abort_code[i] = static_cast<std::uint32_t>(code);
      ++stats_.abort_count[i];
      return;
    }
  }
}

void SdoServer::abort(std::uint16_t index, std::uint8_t sub, SdoAbort code) {
  state_ = State::idle;
  count_abort(code);
  send(encode_abort({index, sub, code}));
}

void SdoServer::begin(State st, std::uint16_t index, std::uint8_t sub) {
  state_ = st;
  index_ = index;
  sub_ = sub;
  last_ = now_;
  toggle_ = false;
  sized_ = crc_ = last_seen_ = false;
  size_ = pos_ = 0;
  seq_ = sent_ = 0;
}

void SdoServer::request(const Payload& p, OdState s) {
  const std::uint8_t b0 = p[0];
  // In a sub-block every frame is a segment, except the client's abort (seqno 0 is never valid).
  if (state_ == State::block_down_sub && b0 != 0x80) return block_download_segment(p);
  const auto ccs = static_cast<Ccs>(specifier(b0));
  const std::uint8_t cs2 = b0 & 0x03;  // block upload request sub-command
  if (ccs == Ccs::abort) {
    ++stats_.aborts_received;
    state_ = State::idle;
    return;
  }
  switch (state_) {
    case State::idle:
      switch (ccs) {
        case Ccs::initiate_download: return initiate_download(p, s);
        case Ccs::initiate_upload: return initiate_upload(p, s);
        case Ccs::block_upload:
          if (cs2 == block_cs::initiate) return block_upload_initiate(p, s);
          break;
        case Ccs::block_download:
          if ((b0 & 0x01) == block_cs::initiate) return block_download_initiate(p, s);
          break;
        default: break;
      }
      return abort(get_u16(p.data() + 1), p[3], SdoAbort::invalid_command);
    case State::download_segments:
      if (ccs == Ccs::download_segment) return download_segment(p, s);
      break;
    case State::upload_segments:
      if (ccs == Ccs::upload_segment) return upload_segment(p);
      break;
    case State::block_down_sub: break;  // only the client's abort reaches here
    case State::block_down_end:
      if (ccs == Ccs::block_download && (b0 & 0x01) == block_cs::end) return block_download_end(p, s);
      break;
    case State::block_up_start:
      if (ccs == Ccs::block_upload && cs2 == block_cs::start) {
        last_ = now_;
        return send_sub_block();
      }
      break;
    case State::block_up_ack:
      if (ccs == Ccs::block_upload && cs2 == block_cs::ack) return block_upload_ack(p);
      break;
    case State::block_up_end:
      if (ccs == Ccs::block_upload && cs2 == block_cs::end) {
        state_ = State::idle;
        ++stats_.uploads;
        return;
      }
      break;
  }
  abort_transfer(SdoAbort::invalid_command);
}

// ---- expedited and segmented download ------------------------------------------------------

SdoAbort SdoServer::check_download(std::uint16_t index, std::uint8_t sub, OdState s, bool sized,
                                   std::size_t size) const {
  // The checks ObjectDictionary::write will make, done before any segment is accepted.
  const OdObject* o = od_.find(index);
  if (!o) return SdoAbort::no_object;
  const OdEntry* e = o->entry(sub);
  if (!e) return SdoAbort::no_subindex;
  const auto write_bit = static_cast<std::uint16_t>(od_access::write_preop << static_cast<int>(s));
  if (!(e->access & write_bit)) return (e->access & od_access::write_all) ? SdoAbort::state : SdoAbort::read_only;
  if (sized && size > e->bytes()) return SdoAbort::too_long;
  if (sized && size < e->bytes() && !e->is_string()) return SdoAbort::too_short;
  return SdoAbort::none;
}

SdoAbort SdoServer::commit(OdState s) { return od_.write(index_, sub_, s, {buf_.data(), pos_}); }

void SdoServer::initiate_download(const Payload& p, OdState s) {
  Initiate m;
  decode_initiate(p, m);
  if (m.expedited) {
    std::size_t n = m.size;
    // Size not indicated: as many bytes as the entry holds (at most 4).
    if (!m.sized) {
      const OdEntry* e = od_.entry(m.index, m.sub);
      n = e ? std::min<std::size_t>(e->bytes(), 4) : 4;
    }
    if (const SdoAbort a = od_.write(m.index, m.sub, s, {m.data.data(), n}); a != SdoAbort::none)
      return abort(m.index, m.sub, a);
    ++stats_.downloads;
    return send(encode_initiate_download_response({m.index, m.sub}));
  }
  if (const SdoAbort a = check_download(m.index, m.sub, s, m.sized, m.size); a != SdoAbort::none)
    return abort(m.index, m.sub, a);
  if (m.sized && m.size > cfg_.max_object_bytes) return abort(m.index, m.sub, SdoAbort::out_of_memory);
  begin(State::download_segments, m.index, m.sub);
  sized_ = m.sized;
  size_ = m.size;
  send(encode_initiate_download_response({m.index, m.sub}));
}

void SdoServer::download_segment(const Payload& p, OdState s) {
  Segment g;
  decode_segment(p, g);
  if (g.toggle != toggle_) return abort_transfer(SdoAbort::toggle);
  if (sized_ && pos_ + g.len > size_) return abort_transfer(SdoAbort::length_mismatch);
  if (pos_ + g.len > cfg_.max_object_bytes) return abort_transfer(SdoAbort::out_of_memory);
  // Collect the data; the OD is written once, after the last segment.
  std::copy_n(g.data.begin(), g.len, buf_.begin() + static_cast<std::ptrdiff_t>(pos_));
  pos_ += g.len;
  toggle_ = !toggle_;
  last_ = now_;
  ++stats_.segments;
  if (g.last) {
    if (sized_ && pos_ != size_) return abort_transfer(SdoAbort::length_mismatch);
    if (const SdoAbort a = commit(s); a != SdoAbort::none) return abort_transfer(a);
    state_ = State::idle;
    ++stats_.downloads;
  }
  send(encode_download_segment_response(g.toggle));
}

// ---- expedited and segmented upload --------------------------------------------------------

void SdoServer::initiate_upload(const Payload& p, OdState s) {
  const ObjectRef o = object_of(p);
  std::size_t len = 0;
  if (const SdoAbort a = od_.read_size(o.index, o.sub, s, len); a != SdoAbort::none) return abort(o.index, o.sub, a);
  if (len > cfg_.max_object_bytes) return abort(o.index, o.sub, SdoAbort::out_of_memory);
  // Snapshot the whole entry now: the segments then carry one consistent value.
  if (const SdoAbort a = od_.read(o.index, o.sub, s, buf_, len); a != SdoAbort::none) return abort(o.index, o.sub, a);
  Initiate m;
  m.index = o.index;
  m.sub = o.sub;
  m.sized = true;
  m.size = static_cast<std::uint32_t>(len);
  if (len >= 1 && len <= 4) {
    m.expedited = true;
    std::copy_n(buf_.begin(), len, m.data.begin());
    ++stats_.uploads;
    return send(encode_initiate_upload_response(m));
  }
  begin(State::upload_segments, o.index, o.sub);
  size_ = len;
  send(encode_initiate_upload_response(m));
}

void SdoServer::upload_segment(const Payload& p) {
  if (toggle_of(p[0]) != toggle_) return abort_transfer(SdoAbort::toggle);
  Segment g;
  g.toggle = toggle_;
  g.len = static_cast<std::uint8_t>(std::min(kSegmentData, size_ - pos_));
  g.last = pos_ + g.len == size_;
  std::copy_n(buf_.begin() + static_cast<std::ptrdiff_t>(pos_), g.len, g.data.begin());
  pos_ += g.len;
  toggle_ = !toggle_;
  last_ = now_;
  ++stats_.segments;
  if (g.last) {
    state_ = State::idle;
    ++stats_.uploads;
  }
  send(encode_segment(g));
}

// ---- block download ---------------------------------------------------------------------------

void SdoServer::block_download_initiate(const Payload& p, OdState s) {
  BlockInitiate m;
  decode_block_download_initiate(p, m);
  if (const SdoAbort a = check_download(m.index, m.sub, s, m.sized, m.size); a != SdoAbort::none)
    return abort(m.index, m.sub, a);
  if (m.sized && m.size > cfg_.max_object_bytes) return abort(m.index, m.sub, SdoAbort::out_of_memory);
  begin(State::block_down_sub, m.index, m.sub);
  sized_ = m.sized;
  size_ = m.size;
  crc_ = m.crc && cfg_.crc;
  BlockInitiate r;
  r.index = m.index;
  r.sub = m.sub;
  r.crc = cfg_.crc;
  r.blksize = cfg_.blksize;
  send(encode_block_download_initiate_response(r));
}

void SdoServer::block_download_segment(const Payload& p) {
  BlockSegment g;
  if (decode_block_segment(p, g) != FrameStatus::ok || g.seqno > cfg_.blksize)
    return abort_transfer(abort_invalid_seqno);
  last_ = now_;
  ++stats_.block_segments;
  if (g.seqno == seq_ + 1) {
    // In order: keep all 7 bytes (the end request says how many of the last one count).
    if (sized_ && pos_ >= std::max<std::size_t>(size_, 1)) return abort_transfer(SdoAbort::length_mismatch);
    if (pos_ + kSegmentData > buf_.size()) return abort_transfer(SdoAbort::out_of_memory);
    std::copy_n(g.data.begin(), kSegmentData, buf_.begin() + static_cast<std::ptrdiff_t>(pos_));
    pos_ += kSegmentData;
    seq_ = g.seqno;
    last_seen_ = g.last;
  }
  // Out of order: discarded; the ack at the sub-block's end tells the client where to resume.
  if (g.seqno != cfg_.blksize && !g.last) return;
  BlockAck a;
  a.ackseq = seq_;
  a.blksize = cfg_.blksize;
  seq_ = 0;
  ++stats_.blocks;
  if (last_seen_) state_ = State::block_down_end;
  send(encode_block_ack(a));
}

void SdoServer::block_download_end(const Payload& p, OdState s) {
  BlockEnd e;
  decode_block_end(p, e);
  const std::size_t n = pos_ - std::min<std::size_t>(e.unused, pos_);
  if (sized_ && n != size_) return abort_transfer(SdoAbort::length_mismatch);
  if (n > cfg_.max_object_bytes) return abort_transfer(SdoAbort::out_of_memory);
  if (crc_ && crc16({buf_.data(), n}) != e.crc) return abort_transfer(abort_crc);
  pos_ = n;
  if (const SdoAbort a = commit(s); a != SdoAbort::none) return abort_transfer(a);
  state_ = State::idle;
  ++stats_.downloads;
  send(encode_block_end_response());
}

// ---- block upload -----------------------------------------------------------------------------

void SdoServer::block_upload_initiate(const Payload& p, OdState s) {
  BlockInitiate m;
  if (decode_block_upload_initiate(p, m) == FrameStatus::bad_block_size)
    return abort(m.index, m.sub, SdoAbort::invalid_block_size);
  std::size_t len = 0;
  if (const SdoAbort a = od_.read_size(m.index, m.sub, s, len); a != SdoAbort::none) return abort(m.index, m.sub, a);
  if (len > cfg_.max_object_bytes) return abort(m.index, m.sub, SdoAbort::out_of_memory);
  if (const SdoAbort a = od_.read(m.index, m.sub, s, buf_, len); a != SdoAbort::none) return abort(m.index, m.sub, a);
  // m.pst (protocol switch threshold) is ignored: always a block upload.
  begin(State::block_up_start, m.index, m.sub);
  size_ = len;
  blksize_ = m.blksize;
  crc_ = m.crc && cfg_.crc;
  BlockInitiate r;
  r.index = m.index;
  r.sub = m.sub;
  r.crc = cfg_.crc;
  r.sized = true;
  r.size = static_cast<std::uint32_t>(len);
  send(encode_block_upload_initiate_response(r));
}

void SdoServer::send_sub_block() {
  // Up to blksize_ segments from pos_ (the first byte not yet acknowledged); the one holding
  // the object's last byte (or the only one, for an empty object) has c = 1.
  sent_ = 0;
  last_seen_ = false;
  std::size_t at = pos_;
  while (sent_ < blksize_ && !last_seen_) {
    const std::size_t n = std::min(kSegmentData, size_ - at);
    BlockSegment g;
    g.seqno = ++sent_;
    g.last = last_seen_ = at + n >= size_;
    std::copy_n(buf_.begin() + static_cast<std::ptrdiff_t>(at), n, g.data.begin());
    at += n;
    ++stats_.block_segments;
    send(encode_block_segment(g));
  }
  state_ = State::block_up_ack;
}

void SdoServer::block_upload_ack(const Payload& p) {
  BlockAck a;
  if (decode_block_ack(p, a) == FrameStatus::bad_block_size) return abort_transfer(SdoAbort::invalid_block_size);
  if (a.ackseq > sent_) return abort_transfer(abort_invalid_seqno);
  last_ = now_;
  ++stats_.blocks;
  pos_ = std::min(size_, pos_ + std::size_t{a.ackseq} * kSegmentData);
  blksize_ = a.blksize;
  // Not all acknowledged: the next sub-block starts at the first byte the client lacks.
  if (!last_seen_ || a.ackseq != sent_) return send_sub_block();
  BlockEnd e;
  e.unused = block_unused(size_);
  e.crc = crc_ ? crc16({buf_.data(), size_}) : 0;
  state_ = State::block_up_end;
  send(encode_block_end(e));
}

}  // namespace omnitwin::canopen
