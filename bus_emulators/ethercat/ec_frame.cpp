// bus_emulators/ethercat — EtherCAT frame codec (see ec_frame.hpp).
#include "bus_emulators/ethercat/ec_frame.hpp"

#include <algorithm>
#include <cstring>

namespace omnitwin::ethercat {

const char* to_string(Cmd c) {
  switch (c) {
    case Cmd::nop: return "NOP";
    case Cmd::aprd: return "APRD";
    case Cmd::apwr: return "APWR";
    case Cmd::aprw: return "APRW";
    case Cmd::fprd: return "FPRD";
    case Cmd::fpwr: return "FPWR";
    case Cmd::fprw: return "FPRW";
    case Cmd::brd: return "BRD";
    case Cmd::bwr: return "BWR";
    case Cmd::brw: return "BRW";
    case Cmd::lrd: return "LRD";
    case Cmd::lwr: return "LWR";
    case Cmd::lrw: return "LRW";
    case Cmd::armw: return "ARMW";
    case Cmd::frmw: return "FRMW";
  }
  return "?";
}

CmdAddressing addressing(Cmd c) noexcept {
  switch (c) {
    case Cmd::aprd: case Cmd::apwr: case Cmd::aprw: case Cmd::armw: return CmdAddressing::position;
    case Cmd::fprd: case Cmd::fpwr: case Cmd::fprw: case Cmd::frmw: return CmdAddressing::node;
    case Cmd::brd: case Cmd::bwr: case Cmd::brw: return CmdAddressing::broadcast;
    case Cmd::lrd: case Cmd::lwr: case Cmd::lrw: return CmdAddressing::logical;
    case Cmd::nop: break;
  }
  return CmdAddressing::none;
}

bool cmd_reads(Cmd c) noexcept {
  switch (c) {
    case Cmd::aprd: case Cmd::aprw: case Cmd::fprd: case Cmd::fprw: case Cmd::brd: case Cmd::brw:
    case Cmd::lrd: case Cmd::lrw: case Cmd::armw: case Cmd::frmw: return true;
    default: return false;
  }
}

bool cmd_writes(Cmd c) noexcept {
  switch (c) {
    case Cmd::apwr: case Cmd::aprw: case Cmd::fpwr: case Cmd::fprw: case Cmd::bwr: case Cmd::brw:
    case Cmd::lwr: case Cmd::lrw: return true;
    default: return false;  // ARMW/FRMW: the addressed slave only reads
  }
}

const char* to_string(PduError e) {
  switch (e) {
    case PduError::ok: return "ok";
    case PduError::too_short: return "too short";
    case PduError::wrong_type: return "wrong type";
    case PduError::length_mismatch: return "length mismatch";
    case PduError::truncated_datagram: return "truncated datagram";
    case PduError::too_many_datagrams: return "too many datagrams";
  }
  return "?";
}

PduError parse_pdu(std::span<std::uint8_t> pdu, PduView& out) noexcept {
  out.count = 0;
  out.length = 0;
  if (pdu.size() < kEcatHeaderSize) return PduError::too_short;
  const std::uint16_t h = get_u16(pdu.data());
  if ((h >> 12) != kPduTypeSlaves) return PduError::wrong_type;
  const std::size_t len = h & 0x07FF;
  if (len > kMaxPdu - kEcatHeaderSize) return PduError::length_mismatch;
  if (pdu.size() < kEcatHeaderSize + len) return PduError::too_short;
  const std::size_t end = kEcatHeaderSize + len;
  std::size_t pos = kEcatHeaderSize;
  std::size_t n = 0;
  for (;;) {
    if (pos + kDatagramHeaderSize + kWkcSize > end) {
      out.count = 0;
      return PduError::truncated_datagram;
    }
    if (n == kMaxDatagrams) {
      out.count = 0;
      return PduError::too_many_datagrams;
    }
    Datagram d(pdu.data() + pos);
    if (pos + d.size() > end) {
      out.count = 0;
      return PduError::truncated_datagram;
    }
    out.datagrams[n++] = d;
    pos += d.size();
    if (!d.more()) break;
  }
  if (pos != end) {
    out.count = 0;
    return PduError::length_mismatch;
  }
  out.count = n;
  out.length = end;
  return PduError::ok;
}

PduBuilder::PduBuilder(std::span<std::uint8_t> buf)
    : buf_(buf), cap_(std::min(buf.size(), kMaxPdu)) {}

void PduBuilder::reset() {
  pos_ = kEcatHeaderSize;
  count_ = 0;
  last_ = 0;
}

std::size_t PduBuilder::room() const {
  if (count_ >= kMaxDatagrams) return 0;
  const std::size_t overhead = kDatagramHeaderSize + kWkcSize;
  if (pos_ + overhead > cap_) return 0;
  return std::min<std::size_t>(cap_ - pos_ - overhead, kMaxDatagramData);
}

int PduBuilder::add(Cmd cmd, std::uint8_t index, std::uint16_t adp, std::uint16_t ado,
                    std::uint16_t length, const void* data) {
  if (cap_ < kEcatHeaderSize || length > room() || count_ >= kMaxDatagrams) return -1;
  if (pos_ + kDatagramHeaderSize + length + kWkcSize > cap_) return -1;
  if (count_ > 0) {  // chain: the previous datagram now has a successor
    std::uint8_t* prev = buf_.data() + last_;
    put_u16(prev + 6, static_cast<std::uint16_t>(get_u16(prev + 6) | 0x8000));
  }
  std::uint8_t* h = buf_.data() + pos_;
  h[0] = static_cast<std::uint8_t>(cmd);
  h[1] = index;
  put_u16(h + 2, adp);
  put_u16(h + 4, ado);
  put_u16(h + 6, length);
  put_u16(h + 8, 0);
  if (data != nullptr) {
    std::memcpy(h + kDatagramHeaderSize, data, length);
  } else {
    std::memset(h + kDatagramHeaderSize, 0, length);
  }
  put_u16(h + kDatagramHeaderSize + length, 0);
  last_ = pos_;
  pos_ += kDatagramHeaderSize + length + kWkcSize;
  ++count_;
  return static_cast<int>(last_ + kDatagramHeaderSize);
}

int PduBuilder::add_logical(Cmd cmd, std::uint8_t index, std::uint32_t address, std::uint16_t length,
                            const void* data) {
  return add(cmd, index, static_cast<std::uint16_t>(address & 0xFFFF),
             static_cast<std::uint16_t>(address >> 16), length, data);
}

void PduBuilder::rewind(const Mark& m) {
  if (m.count > count_) return;  // not a mark of this builder's past
  pos_ = m.pos;
  count_ = m.count;
  last_ = m.last;
  if (count_ > 0) {  // the last datagram kept has no successor any more
    std::uint8_t* h = buf_.data() + last_;
    put_u16(h + 6, static_cast<std::uint16_t>(get_u16(h + 6) & ~0x8000));
  }
}

std::size_t PduBuilder::finish() {
  if (cap_ < kEcatHeaderSize) return 0;
  const std::size_t len = pos_ - kEcatHeaderSize;
  put_u16(buf_.data(), static_cast<std::uint16_t>((len & 0x07FF) | (kPduTypeSlaves << 12)));
  return pos_;
}

std::size_t write_eth_header(std::uint8_t* out, const Mac& dst, const Mac& src) noexcept {
  std::memcpy(out, dst.data(), 6);
  std::memcpy(out + 6, src.data(), 6);
  out[12] = static_cast<std::uint8_t>(kEtherType >> 8);
  out[13] = static_cast<std::uint8_t>(kEtherType & 0xFF);
  return kEthHeaderSize;
}

}  // namespace omnitwin::ethercat
