// bus_emulators/ethercat/device — CoE SDO server (see ec_coe.hpp).
#include "bus_emulators/ethercat/device/ec_coe.hpp"

#include <algorithm>
#include <cstring>

#include "bus_emulators/ethercat/ec_frame.hpp"

namespace omnitwin::ethercat {

namespace {
constexpr std::size_t kCoeHeader = 2;
constexpr std::size_t kSdoHeader = 8;  // command, index, subindex, 4 data bytes
constexpr std::size_t kMinMailbox = 16;
}  // namespace

CoeServer::CoeServer(ObjectDictionary& od, const CoeServerConfig& config) : od_(od), cfg_(config) {
  cfg_.mailbox_size = std::max(cfg_.mailbox_size, kMinMailbox);
  cfg_.queue = std::max<std::size_t>(cfg_.queue, 2);
  mbx_size_ = cfg_.mailbox_size;
  queue_.resize(cfg_.queue);
  last_.resize(cfg_.queue);
  for (auto& r : queue_) r.bytes.assign(cfg_.mailbox_size, 0);
  for (auto& r : last_) r.bytes.assign(cfg_.mailbox_size, 0);
  t_buf_.assign(cfg_.max_transfer, 0);
  scratch_.assign(std::max<std::size_t>(cfg_.max_transfer, 2 * 65536 + 2), 0);
}

void CoeServer::set_mailbox_size(std::size_t bytes) noexcept {
  mbx_size_ = std::clamp(bytes, kMinMailbox, cfg_.mailbox_size);
}

void CoeServer::reset() noexcept {
  head_ = count_ = 0;
  last_n_ = 0;
  last_counter_ = 0;
  transfer_ = Transfer::idle;
}

std::span<const std::uint8_t> CoeServer::front() const noexcept {
  if (!count_) return {};
  const auto& r = queue_[head_];
  return {r.bytes.data(), r.size};
}

void CoeServer::pop() noexcept {
  if (!count_) return;
  head_ = (head_ + 1) % queue_.size();
  --count_;
}

std::uint8_t* CoeServer::begin_reply(std::size_t data_len, MailboxType type) {
  if (count_ == queue_.size() || kMailboxHeaderSize + data_len > mbx_size_) {
    ++stats_.dropped_replies;
    return nullptr;
  }
  auto& r = queue_[(head_ + count_) % queue_.size()];
  ++count_;
  r.size = kMailboxHeaderSize + data_len;
  std::fill(r.bytes.begin(), r.bytes.begin() + static_cast<std::ptrdiff_t>(r.size), 0);
  reply_counter_ = next_mailbox_counter(reply_counter_);
  MailboxHeader h;
  h.length = static_cast<std::uint16_t>(data_len);
  h.type = static_cast<std::uint8_t>(type);
  h.counter = reply_counter_;
  encode_mailbox_header(h, r.bytes.data());
  return r.bytes.data() + kMailboxHeaderSize;
}

bool CoeServer::post_emergency(std::uint16_t code, std::uint8_t error_register, const std::uint8_t (&data)[5]) noexcept {
  std::uint8_t* p = begin_reply(10, MailboxType::coe);
  if (!p) return false;
  put_u16(p, static_cast<std::uint16_t>(coe::svc_emergency << 12));  // CoE header: number 0, service
  put_u16(p + 2, code);
  p[4] = error_register;
  std::copy(std::begin(data), std::end(data), p + 5);
  ++stats_.emergencies;
  return true;
}

void CoeServer::mailbox_error(MailboxError e) {
  ++stats_.mailbox_errors;
  std::uint8_t* p = begin_reply(4, MailboxType::error);
  if (!p) return;
  put_u16(p, 0x0001);
  put_u16(p + 2, static_cast<std::uint16_t>(e));
}

void CoeServer::abort(std::uint16_t index, std::uint8_t sub, SdoAbort code) {
  ++stats_.aborts;
  transfer_ = Transfer::idle;
  std::uint8_t* p = begin_reply(kCoeHeader + kSdoHeader, MailboxType::coe);
  if (!p) return;
  put_u16(p, static_cast<std::uint16_t>(coe::svc_sdo_request << 12));
  p[2] = 0x80;
  put_u16(p + 3, index);
  p[5] = sub;
  put_u32(p + 6, static_cast<std::uint32_t>(code));
}

void CoeServer::on_mailbox(std::span<const std::uint8_t> m, OdState state, bool reply_unread) noexcept {
  ++stats_.requests;
  const auto h = decode_mailbox_header(m);
  if (!h) return;  // nothing a reply could refer to
  if (h->counter != 0 && h->counter == last_counter_) {
    ++stats_.repeats;
    if (reply_unread || count_ > 0) return;  // the answer is still on its way
    for (std::size_t i = 0; i < last_n_; ++i) {
      if (count_ == queue_.size()) {
        ++stats_.dropped_replies;
        break;
      }
      auto& r = queue_[(head_ + count_) % queue_.size()];
      r.size = last_[i].size;
      std::copy_n(last_[i].bytes.begin(), r.size, r.bytes.begin());
      ++count_;
    }
    return;
  }
  last_counter_ = h->counter;
  const std::size_t before = count_;
  if (h->length + kMailboxHeaderSize > m.size()) {
    mailbox_error(MailboxError::invalid_size);
  } else if (h->type != static_cast<std::uint8_t>(MailboxType::coe)) {
    mailbox_error(MailboxError::unsupported_protocol);
  } else if (h->length < kCoeHeader) {
    mailbox_error(MailboxError::size_too_short);
  } else {
    const auto p = m.subspan(kMailboxHeaderSize, h->length);
    const std::uint16_t service = get_u16(p.data()) >> 12;
    if (service == coe::svc_sdo_request) {
      if (p.size() < kCoeHeader + kSdoHeader) mailbox_error(MailboxError::size_too_short);
      else sdo(p, state);
    } else if (service == coe::svc_sdo_info && cfg_.sdo_info) {
      if (p.size() < kCoeHeader + 4) mailbox_error(MailboxError::size_too_short);
      else sdo_info(p);
    } else {
      mailbox_error(MailboxError::service_not_supported);
    }
  }
  // Remember this request's replies for a repeat.
  last_n_ = std::min(count_ - before, last_.size());
  for (std::size_t i = 0; i < last_n_; ++i) {
    const auto& r = queue_[(head_ + before + i) % queue_.size()];
    last_[i].size = r.size;
    std::copy_n(r.bytes.begin(), r.size, last_[i].bytes.begin());
  }
}

void CoeServer::sdo(std::span<const std::uint8_t> p, OdState s) {
  const std::uint8_t cmd = p[2];
  const std::uint16_t index = get_u16(p.data() + 3);
  const std::uint8_t sub = p[5];
  const std::uint8_t ccs = cmd >> 5;
  // A running transfer continues only with its own segment requests.
  if (transfer_ == Transfer::downloading && ccs != 0) transfer_ = Transfer::idle;
  if (transfer_ == Transfer::uploading && ccs != 3) transfer_ = Transfer::idle;
  switch (ccs) {
    case 0:
      if (transfer_ != Transfer::downloading) return abort(index, sub, SdoAbort::invalid_command);
      return download_segment(p, cmd, s);
    case 1: return download_initiate(p, s);
    case 2: return upload_initiate(index, sub, (cmd & 0x10) != 0, s);
    case 3:
      if (transfer_ != Transfer::uploading) return abort(index, sub, SdoAbort::invalid_command);
      return upload_segment(cmd);
    case 4: transfer_ = Transfer::idle; return;  // abort from the master: no answer
    default: return abort(index, sub, SdoAbort::invalid_command);
  }
}

void CoeServer::upload_initiate(std::uint16_t index, std::uint8_t sub, bool ca, OdState s) {
  if (ca && !cfg_.complete_access) return abort(index, sub, SdoAbort::unsupported_access);
  std::size_t len = 0;
  SdoAbort a = ca ? od_.read_complete(index, sub, s, scratch_, len) : od_.read(index, sub, s, scratch_, len);
  if (a != SdoAbort::none) return abort(index, sub, a);
  // Expedited carries 1-4 bytes; an empty value goes the normal way with size 0 (0x43 with
  // 4 - 0 in the size bits made 0x53: the complete-access bit; found by a protocol review).
  if (len >= 1 && len <= 4 && !ca) {
    std::uint8_t* p = begin_reply(kCoeHeader + kSdoHeader, MailboxType::coe);
    if (!p) return;
    put_u16(p, static_cast<std::uint16_t>(coe::svc_sdo_response << 12));
    p[2] = static_cast<std::uint8_t>(0x43 | ((4 - len) << 2));
    put_u16(p + 3, index);
    p[5] = sub;
    std::copy_n(scratch_.begin(), len, p + 6);
    return;
  }
  const std::size_t room = mbx_size_ - kMailboxHeaderSize - kCoeHeader - kSdoHeader;
  const std::size_t first = std::min(len, room);
  if (first < len && len > t_buf_.size()) return abort(index, sub, SdoAbort::out_of_memory);
  std::uint8_t* p = begin_reply(kCoeHeader + kSdoHeader + first, MailboxType::coe);
  if (!p) return;
  put_u16(p, static_cast<std::uint16_t>(coe::svc_sdo_response << 12));
  p[2] = static_cast<std::uint8_t>(0x41 | (ca ? 0x10 : 0));
  put_u16(p + 3, index);
  p[5] = sub;
  put_u32(p + 6, static_cast<std::uint32_t>(len));
  std::copy_n(scratch_.begin(), first, p + 10);
  if (first < len) {
    std::copy_n(scratch_.begin(), len, t_buf_.begin());
    transfer_ = Transfer::uploading;
    t_index_ = index;
    t_sub_ = sub;
    t_size_ = len;
    t_done_ = first;
    t_toggle_ = 0;
  }
}

void CoeServer::upload_segment(std::uint8_t cmd) {
  const std::uint8_t toggle = (cmd >> 4) & 1;
  if (toggle != t_toggle_) return abort(t_index_, t_sub_, SdoAbort::toggle);
  const std::size_t room = mbx_size_ - kMailboxHeaderSize - kCoeHeader - 1;
  const std::size_t n = std::min(room, t_size_ - t_done_);
  const bool last = t_done_ + n == t_size_;
  const std::size_t data_len = std::max<std::size_t>(n, 7);
  std::uint8_t* p = begin_reply(kCoeHeader + 1 + data_len, MailboxType::coe);
  if (!p) return;
  put_u16(p, static_cast<std::uint16_t>(coe::svc_sdo_response << 12));
  p[2] = static_cast<std::uint8_t>((toggle << 4) | (n < 7 ? (7 - n) << 1 : 0) | (last ? 1 : 0));
  std::copy_n(t_buf_.begin() + static_cast<std::ptrdiff_t>(t_done_), n, p + 3);
  t_done_ += n;
  t_toggle_ ^= 1;
  if (last) transfer_ = Transfer::idle;
}

void CoeServer::download_initiate(std::span<const std::uint8_t> p, OdState s) {
  const std::uint8_t cmd = p[2];
  const std::uint16_t index = get_u16(p.data() + 3);
  const std::uint8_t sub = p[5];
  const bool ca = (cmd & 0x10) != 0;
  const bool expedited = (cmd & 0x02) != 0, sized = (cmd & 0x01) != 0;
  if (ca && !cfg_.complete_access) return abort(index, sub, SdoAbort::unsupported_access);
  auto respond = [&]() {
    std::uint8_t* r = begin_reply(kCoeHeader + kSdoHeader, MailboxType::coe);
    if (!r) return;
    put_u16(r, static_cast<std::uint16_t>(coe::svc_sdo_response << 12));
    r[2] = 0x60;
    put_u16(r + 3, index);
    r[5] = sub;
  };
  if (expedited) {
    std::size_t n = sized ? 4u - ((cmd >> 2) & 3u) : 4u;
    if (!sized && !ca) {
      // Size not indicated: as many bytes as the entry holds (at most 4).
      if (const OdEntry* e = od_.entry(index, sub)) n = std::min<std::size_t>(e->bytes(), 4);
    }
    const auto data = p.subspan(6, n);
    const SdoAbort a = ca ? od_.write_complete(index, sub, s, data) : od_.write(index, sub, s, data);
    if (a != SdoAbort::none) return abort(index, sub, a);
    return respond();
  }
  if (!sized) return abort(index, sub, SdoAbort::invalid_command);
  const std::size_t size = get_u32(p.data() + 6);
  const std::size_t here = p.size() - kCoeHeader - kSdoHeader;
  if (size <= here) {
    const auto data = p.subspan(kCoeHeader + kSdoHeader, size);
    const SdoAbort a = ca ? od_.write_complete(index, sub, s, data) : od_.write(index, sub, s, data);
    if (a != SdoAbort::none) return abort(index, sub, a);
    return respond();
  }
  // Segmented: check what can be checked now, then collect the segments.
  if (!ca) {
    const OdObject* o = od_.find(index);
    if (!o) return abort(index, sub, SdoAbort::no_object);
    const OdEntry* e = o->entry(sub);
    if (!e) return abort(index, sub, SdoAbort::no_subindex);
    if (size > e->bytes()) return abort(index, sub, SdoAbort::too_long);
  } else if (const SdoAbort a = od_.complete_access_check(index, sub); a != SdoAbort::none) {
    return abort(index, sub, a);
  }
  if (size > t_buf_.size()) return abort(index, sub, SdoAbort::out_of_memory);
  std::copy_n(p.begin() + kCoeHeader + kSdoHeader, here, t_buf_.begin());
  transfer_ = Transfer::downloading;
  t_index_ = index;
  t_sub_ = sub;
  t_ca_ = ca;
  t_size_ = size;
  t_done_ = here;
  t_toggle_ = 0;
  respond();
}

SdoAbort CoeServer::commit_download(OdState s) {
  const auto data = std::span<const std::uint8_t>(t_buf_.data(), t_size_);
  return t_ca_ ? od_.write_complete(t_index_, t_sub_, s, data) : od_.write(t_index_, t_sub_, s, data);
}

void CoeServer::download_segment(std::span<const std::uint8_t> p, std::uint8_t cmd, OdState s) {
  const std::uint8_t toggle = (cmd >> 4) & 1;
  if (toggle != t_toggle_) return abort(t_index_, t_sub_, SdoAbort::toggle);
  const bool last = (cmd & 1) != 0;
  std::size_t n = p.size() - kCoeHeader - 1;
  if (p.size() == kCoeHeader + kSdoHeader) n = 7u - ((cmd >> 1) & 7u);
  if (t_done_ + n > t_size_) return abort(t_index_, t_sub_, SdoAbort::too_long);
  std::copy_n(p.begin() + kCoeHeader + 1, n, t_buf_.begin() + static_cast<std::ptrdiff_t>(t_done_));
  t_done_ += n;
  t_toggle_ ^= 1;
  if (last) {
    transfer_ = Transfer::idle;
    if (t_done_ != t_size_) return abort(t_index_, t_sub_, SdoAbort::length_mismatch);
    if (const SdoAbort a = commit_download(s); a != SdoAbort::none) return abort(t_index_, t_sub_, a);
  }
  std::uint8_t* r = begin_reply(kCoeHeader + kSdoHeader, MailboxType::coe);
  if (!r) return;
  put_u16(r, static_cast<std::uint16_t>(coe::svc_sdo_response << 12));
  r[2] = static_cast<std::uint8_t>(0x20 | (toggle << 4));
}

void CoeServer::info_error(SdoAbort code) {
  std::uint8_t* p = begin_reply(kCoeHeader + 4 + 4, MailboxType::coe);
  if (!p) return;
  put_u16(p, static_cast<std::uint16_t>(coe::svc_sdo_info << 12));
  p[2] = coe::info_error;
  put_u32(p + 6, static_cast<std::uint32_t>(code));
}

void CoeServer::info_fragments(std::uint8_t opcode, std::span<const std::uint8_t> data) {
  const std::size_t room = (mbx_size_ - kMailboxHeaderSize - kCoeHeader - 4) & ~std::size_t{1};
  const std::size_t frags = data.empty() ? 1 : (data.size() + room - 1) / room;
  for (std::size_t i = 0; i < frags; ++i) {
    const std::size_t at = i * room, n = std::min(room, data.size() - at);
    std::uint8_t* p = begin_reply(kCoeHeader + 4 + n, MailboxType::coe);
    if (!p) return;
    put_u16(p, static_cast<std::uint16_t>(coe::svc_sdo_info << 12));
    p[2] = static_cast<std::uint8_t>(opcode | (i + 1 < frags ? 0x80 : 0));
    put_u16(p + 4, static_cast<std::uint16_t>(frags - 1 - i));
    std::copy_n(data.begin() + static_cast<std::ptrdiff_t>(at), n, p + 6);
  }
}

void CoeServer::sdo_info(std::span<const std::uint8_t> p) {
  const std::uint8_t opcode = p[2] & 0x7F;
  const auto body = p.subspan(kCoeHeader + 4);
  auto name_of = [](const std::string& s, std::uint8_t* out, std::size_t room) {
    const std::size_t n = std::min(s.size(), room);
    std::copy_n(s.begin(), n, out);
    return n;
  };
  switch (opcode) {
    case coe::info_list_req: {
      if (body.size() < 2) return info_error(SdoAbort::length_mismatch);
      const std::uint16_t type = get_u16(body.data());
      if (type > 5) return info_error(SdoAbort::value_range);
      auto in_list = [](const OdObject& o, std::uint16_t t) {
        std::uint16_t acc = 0;
        for (const auto& e : o.entries) acc |= e.access;
        switch (t) {
          case 1: return true;
          case 2: return (acc & od_access::rxpdo) != 0;
          case 3: return (acc & od_access::txpdo) != 0;
          case 4: return (acc & od_access::backup) != 0;
          case 5: return (acc & od_access::setting) != 0;
        }
        return false;
      };
      std::size_t n = 0;
      put_u16(scratch_.data(), type);
      n = 2;
      if (type == 0) {
        for (std::uint16_t t = 1; t <= 5; ++t) {
          std::uint16_t c = 0;
          for (const auto& o : od_.objects()) c = static_cast<std::uint16_t>(c + (in_list(o, t) ? 1 : 0));
          put_u16(scratch_.data() + n, c);
          n += 2;
        }
      } else {
        for (const auto& o : od_.objects()) {
          if (!in_list(o, type)) continue;
          put_u16(scratch_.data() + n, o.index);
          n += 2;
        }
      }
      return info_fragments(coe::info_list_rsp, {scratch_.data(), n});
    }
    case coe::info_obj_req: {
      if (body.size() < 2) return info_error(SdoAbort::length_mismatch);
      const OdObject* o = od_.find(get_u16(body.data()));
      if (!o) return info_error(SdoAbort::no_object);
      put_u16(scratch_.data(), o->index);
      put_u16(scratch_.data() + 2, o->data_type);
      scratch_[4] = o->max_subindex();
      scratch_[5] = o->object_code;
      const std::size_t n = 6 + name_of(o->name, scratch_.data() + 6, 255);
      return info_fragments(coe::info_obj_rsp, {scratch_.data(), n});
    }
    case coe::info_entry_req: {
      if (body.size() < 4) return info_error(SdoAbort::length_mismatch);
      const std::uint16_t index = get_u16(body.data());
      const std::uint8_t sub = body[2];
      const OdObject* o = od_.find(index);
      if (!o) return info_error(SdoAbort::no_object);
      const OdEntry* e = o->entry(sub);
      if (!e) return info_error(SdoAbort::no_subindex);
      put_u16(scratch_.data(), index);
      scratch_[2] = sub;
      scratch_[3] = 0;  // value info: no unit/default/min/max appended
      put_u16(scratch_.data() + 4, e->data_type);
      put_u16(scratch_.data() + 6, e->bits);
      put_u16(scratch_.data() + 8, e->access);
      const std::size_t n = 10 + name_of(e->name, scratch_.data() + 10, 255);
      return info_fragments(coe::info_entry_rsp, {scratch_.data(), n});
    }
    default:
      return info_error(SdoAbort::invalid_command);
  }
}

}  // namespace omnitwin::ethercat
