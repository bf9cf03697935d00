// controller/ethercat — CoE SDO client transfers (see ec_sdo.hpp).
#include "controller/ethercat/ec_sdo.hpp"

#include <algorithm>
#include <cstring>

#include "bus_emulators/ethercat/ec_frame.hpp"

namespace omnitwin::controller::ethercat {

using omnitwin::ethercat::get_u16;
using omnitwin::ethercat::get_u32;
using omnitwin::ethercat::put_u16;
using omnitwin::ethercat::put_u32;

std::optional<CoeEmergency> parse_emergency(std::span<const std::uint8_t> m) noexcept {
  if (m.size() < 16 || (m[5] & 0x0F) != static_cast<std::uint8_t>(MbxType::coe) || get_u16(m.data()) < 10) return std::nullopt;
  if ((get_u16(m.data() + 6) >> 12) != static_cast<std::uint16_t>(CoeService::emergency)) return std::nullopt;
  CoeEmergency e;
  e.code = get_u16(m.data() + 8);
  e.error_register = m[10];
  for (std::size_t i = 0; i < e.data.size(); ++i) e.data[i] = m[11 + i];
  return e;
}

const char* emergency_text(std::uint16_t code) {
  if (code == 0x0000) return "error reset or no error";
  if (code == 0x8611) return "following error";
  if (code == 0x8612) return "reference limit";
  if ((code & 0xFF00) == 0xFF00) return "device specific";
  switch (code >> 12) {
    case 0x1: return "generic error";
    case 0x2: return "current";
    case 0x3: return "voltage";
    case 0x4: return "temperature";
    case 0x5: return "device hardware";
    case 0x6: return (code & 0xFF00) == 0x6300 ? "data set / parameter" : "device software";
    case 0x7: return "additional modules";
    case 0x8: return (code & 0xFF00) == 0x8400 ? "velocity controller"
                     : (code & 0xFF00) == 0x8500 ? "position controller"
                     : (code & 0xFF00) == 0x8600 ? "positioning controller"
                                                 : "monitoring / communication";
    case 0x9: return "external error";
    case 0xF: return "additional functions";
    default: return "unknown error code";
  }
}

const char* sdo_abort_text(std::uint32_t code) {
  switch (static_cast<SdoAbort>(code)) {
    case SdoAbort::toggle: return "toggle bit not alternated";
    case SdoAbort::timeout: return "SDO protocol timed out";
    case SdoAbort::command_unknown: return "command specifier not valid or unknown";
    case SdoAbort::unsupported_access: return "unsupported access to an object";
    case SdoAbort::write_only: return "attempt to read a write-only object";
    case SdoAbort::read_only: return "attempt to write a read-only object";
    case SdoAbort::no_object: return "object does not exist in the object dictionary";
    case SdoAbort::not_mappable: return "object cannot be mapped to the PDO";
    case SdoAbort::pdo_length: return "mapped objects exceed the PDO length";
    case SdoAbort::type_mismatch: return "data type does not match, length does not match";
    case SdoAbort::too_long: return "data type does not match, length too high";
    case SdoAbort::too_short: return "data type does not match, length too low";
    case SdoAbort::no_subindex: return "subindex does not exist";
    case SdoAbort::value_range: return "value range of parameter exceeded";
    case SdoAbort::general: return "general error";
    case SdoAbort::cannot_store: return "data cannot be transferred or stored";
    case SdoAbort::device_state: return "data cannot be transferred because of the device state";
  }
  return "unknown abort code";
}

const char* to_string(SdoStatus s) {
  switch (s) {
    case SdoStatus::pending: return "pending";
    case SdoStatus::done: return "done";
    case SdoStatus::aborted: return "aborted";
    case SdoStatus::timeout: return "timeout";
    case SdoStatus::mailbox_error: return "mailbox_error";
    case SdoStatus::failed: return "failed";
  }
  return "?";
}

void put_mbx_header(std::uint8_t* out, std::uint16_t length, MbxType type, std::uint8_t counter) {
  put_u16(out, length);
  put_u16(out + 2, 0);  // address: master
  out[4] = 0;           // channel 0, priority 0
  out[5] = static_cast<std::uint8_t>((static_cast<std::uint8_t>(type) & 0x0F) | ((counter & 0x07) << 4));
}

std::vector<std::uint8_t> value_bytes(std::int64_t value, unsigned bytes) {
  std::vector<std::uint8_t> out(bytes);
  for (unsigned i = 0; i < bytes; ++i) out[i] = static_cast<std::uint8_t>(static_cast<std::uint64_t>(value) >> (8 * i));
  return out;
}

std::int64_t bytes_value(std::span<const std::uint8_t> bytes, bool is_signed) {
  std::uint64_t v = 0;
  const std::size_t n = std::min<std::size_t>(bytes.size(), 8);
  for (std::size_t i = 0; i < n; ++i) v |= static_cast<std::uint64_t>(bytes[i]) << (8 * i);
  if (is_signed && n > 0 && n < 8 && (bytes[n - 1] & 0x80)) v |= ~0ULL << (8 * n);
  return static_cast<std::int64_t>(v);
}

void SdoTransfer::begin(SdoRequest req, std::size_t mbx_out_size) {
  req_ = std::move(req);
  mbx_size_ = mbx_out_size;
  phase_ = Phase::initiate;
  step_ = Step::send;
  status_ = SdoStatus::pending;
  abort_code_ = 0;
  toggle_ = false;
  sent_ = 0;
  total_ = 0;
  data_.clear();
  if (mbx_size_ < kMbxHeaderSize + kCoeSdoSize) fail(SdoStatus::failed);
}

void SdoTransfer::fail(SdoStatus status) {
  status_ = status;
  step_ = Step::done;
}

SdoTransfer::ReplyOutcome SdoTransfer::finish() {
  status_ = SdoStatus::done;
  step_ = Step::done;
  return ReplyOutcome::finished;
}

SdoTransfer::ReplyOutcome SdoTransfer::begin_segments() {
  phase_ = Phase::segment;
  toggle_ = false;
  step_ = Step::send;
  return ReplyOutcome::progress;
}

void SdoTransfer::abort_local(std::uint32_t code) {
  abort_code_ = code;
  status_ = SdoStatus::aborted;
  step_ = Step::done;
}

std::size_t SdoTransfer::next_request(std::span<std::uint8_t> out, std::uint8_t counter) {
  if (step_ != Step::send || out.size() < kMbxHeaderSize + kCoeSdoSize) return 0;
  std::fill(out.begin(), out.end(), std::uint8_t{0});
  std::uint8_t* coe = out.data() + kMbxHeaderSize;
  put_u16(coe, static_cast<std::uint16_t>(static_cast<unsigned>(CoeService::sdo_request) << 12));
  std::uint8_t* sdo = coe + 2;
  std::uint16_t length = kCoeSdoSize;
  const std::size_t room = out.size() - kMbxHeaderSize;  // CoE bytes that fit
  if (req_.upload) {
    if (phase_ == Phase::initiate) {
      sdo[0] = 0x40;  // initiate upload request
      put_u16(sdo + 1, req_.index);
      sdo[3] = req_.sub;
    } else {
      sdo[0] = static_cast<std::uint8_t>(0x60 | (toggle_ ? 0x10 : 0));  // upload segment request
    }
  } else if (phase_ == Phase::initiate) {
    put_u16(sdo + 1, req_.index);
    sdo[3] = req_.sub;
    const std::size_t n = req_.data.size();
    if (n >= 1 && n <= 4) {  // expedited, size indicated
      sdo[0] = static_cast<std::uint8_t>(0x23 | ((4 - n) << 2));
      std::memcpy(sdo + 4, req_.data.data(), n);
      sent_ = n;
    } else {  // normal: complete size, then as much data as fits (segments follow)
      sdo[0] = 0x21;
      put_u32(sdo + 4, static_cast<std::uint32_t>(n));
      const std::size_t chunk = std::min(n, room - kCoeSdoSize);
      std::memcpy(sdo + 8, req_.data.data(), chunk);
      sent_ = chunk;
      length = static_cast<std::uint16_t>(kCoeSdoSize + chunk);
    }
  } else {  // download segment: cmd, then up to room − 3 bytes (at least 7 bytes of room)
    const std::size_t left = req_.data.size() - sent_;
    const std::size_t chunk = std::min(left, room - 3);
    const bool last = chunk == left;
    std::uint8_t cmd = static_cast<std::uint8_t>((toggle_ ? 0x10 : 0) | (last ? 0x01 : 0));
    if (chunk < 7) cmd = static_cast<std::uint8_t>(cmd | ((7 - chunk) << 1));
    sdo[0] = cmd;
    std::memcpy(sdo + 1, req_.data.data() + sent_, chunk);
    sent_ += chunk;
    length = static_cast<std::uint16_t>(std::max<std::size_t>(kCoeSdoSize, 3 + chunk));
  }
  put_mbx_header(out.data(), length, MbxType::coe, counter);
  return kMbxHeaderSize + length;
}

SdoTransfer::ReplyOutcome SdoTransfer::on_reply(std::span<const std::uint8_t> mbx) {
  if (step_ == Step::done || mbx.size() < kMbxHeaderSize) return ReplyOutcome::ignored;
  const std::uint16_t len = get_u16(mbx.data());
  const auto type = static_cast<MbxType>(mbx[5] & 0x0F);
  if (len + kMbxHeaderSize > mbx.size()) return ReplyOutcome::ignored;
  const std::uint8_t* p = mbx.data() + kMbxHeaderSize;
  if (type == MbxType::error) {
    abort_code_ = len >= 4 ? get_u16(p + 2) : 0;
    status_ = SdoStatus::mailbox_error;
    step_ = Step::done;
    return ReplyOutcome::finished;
  }
  if (type != MbxType::coe || len < 3) return ReplyOutcome::ignored;
  const auto service = static_cast<CoeService>(get_u16(p) >> 12);
  const std::uint8_t* sdo = p + 2;
  const std::uint8_t cmd = sdo[0];
  if ((service == CoeService::sdo_request || service == CoeService::sdo_response) && cmd == 0x80 && len >= kCoeSdoSize) {
    if (get_u16(sdo + 1) != req_.index || sdo[3] != req_.sub) {
      if (phase_ == Phase::initiate) return ReplyOutcome::ignored;
    }
    abort_code_ = get_u32(sdo + 4);
    status_ = SdoStatus::aborted;
    step_ = Step::done;
    return ReplyOutcome::finished;
  }
  if (service != CoeService::sdo_response) return ReplyOutcome::ignored;
  const std::uint8_t scs = cmd >> 5;
  if (phase_ == Phase::initiate) {
    if (len < kCoeSdoSize || get_u16(sdo + 1) != req_.index || sdo[3] != req_.sub) return ReplyOutcome::ignored;
    if (req_.upload) {
      if (scs != 2) { abort_local(static_cast<std::uint32_t>(SdoAbort::command_unknown)); return ReplyOutcome::finished; }
      if (cmd & 0x02) {  // expedited
        const std::size_t n = (cmd & 0x01) ? 4 - ((cmd >> 2) & 0x03) : 4;
        data_.assign(sdo + 4, sdo + 4 + n);
        return finish();
      }
      total_ = get_u32(sdo + 4);
      const std::size_t here = std::min<std::size_t>(len - kCoeSdoSize, total_);
      data_.assign(sdo + 8, sdo + 8 + here);
      if (data_.size() >= total_) {
        return finish();
      }
      return begin_segments();
    }
    if (scs != 3) { abort_local(static_cast<std::uint32_t>(SdoAbort::command_unknown)); return ReplyOutcome::finished; }
    if (sent_ >= req_.data.size()) {
      return finish();
    }
    return begin_segments();
  }
  // segment phase
  const bool toggle = (cmd & 0x10) != 0;
  if (req_.upload) {
    if (scs != 0) return ReplyOutcome::ignored;
    if (toggle != toggle_) { abort_local(static_cast<std::uint32_t>(SdoAbort::toggle)); return ReplyOutcome::finished; }
    // A segment is at least the CoE header and 8 SDO bytes; the 7 data bytes of a short one
    // are inside them (a shorter reply would hand out bytes from past the mailbox's length).
    if (len < kCoeSdoSize) { abort_local(static_cast<std::uint32_t>(SdoAbort::type_mismatch)); return ReplyOutcome::finished; }
    std::size_t n = len - 3;
    if (n <= 7) n = 7 - ((cmd >> 1) & 0x07);
    n = std::min<std::size_t>(n, total_ - data_.size());
    data_.insert(data_.end(), sdo + 1, sdo + 1 + n);
    toggle_ = !toggle_;
    if ((cmd & 0x01) || data_.size() >= total_) {
      return finish();
    }
    step_ = Step::send;
    return ReplyOutcome::progress;
  }
  if (scs != 1) return ReplyOutcome::ignored;
  if (toggle != toggle_) { abort_local(static_cast<std::uint32_t>(SdoAbort::toggle)); return ReplyOutcome::finished; }
  toggle_ = !toggle_;
  if (sent_ >= req_.data.size()) {
    return finish();
  }
  step_ = Step::send;
  return ReplyOutcome::progress;
}

}  // namespace omnitwin::controller::ethercat
