// bus_emulators/mechatrolink3 — M-III frame codec; see m3_frame.hpp for the layout.
#include "bus_emulators/mechatrolink3/m3_frame.hpp"

#include <zlib.h>

#include <algorithm>
#include <cstring>

namespace omnitwin::m3 {

namespace {

std::uint32_t get_u32le(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}

void put_u32le(std::uint8_t* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

// The checks on the five header bytes that need no data.
FrameStatus check_header(const std::uint8_t* h) {
  const auto type = static_cast<FrameType>(h[3]);
  if (!is_known(type)) return FrameStatus::unknown_type;
  if (!data_length_allowed(type, h[4])) return FrameStatus::bad_data_length;
  if ((h[2] & kReservedControl) != 0) return FrameStatus::bad_control;
  if (!is_station_address(h[1])) return FrameStatus::bad_address;
  if (!is_station_address(h[0]) && h[0] != kBroadcast) return FrameStatus::bad_address;
  return FrameStatus::ok;
}

}  // namespace

bool is_slave_address(std::uint8_t a) noexcept { return a >= kFirstSlave && a <= kLastSlave; }
bool is_station_address(std::uint8_t a) noexcept {
  return a == kC1Master || a == kC2Master || is_slave_address(a);
}

const char* to_string(FrameType t) {
  switch (t) {
    case FrameType::sync: return "SYNC";
    case FrameType::cyclic_command: return "CMD";
    case FrameType::cyclic_response: return "RSP";
    case FrameType::event_command: return "EVT_CMD";
    case FrameType::event_response: return "EVT_RSP";
    case FrameType::detect: return "DETECT";
    case FrameType::detect_reply: return "DETECT_RPL";
    case FrameType::delay_request: return "DLY_REQ";
    case FrameType::delay_reply: return "DLY_RPL";
    case FrameType::cycle_notify: return "CYC_NOTIFY";
    case FrameType::comm_start: return "COMM_START";
  }
  return "?";
}

bool is_known(FrameType t) noexcept { return std::strcmp(to_string(t), "?") != 0; }

const char* to_string(FrameStatus s) {
  switch (s) {
    case FrameStatus::ok: return "ok";
    case FrameStatus::truncated: return "truncated";
    case FrameStatus::oversized: return "oversized";
    case FrameStatus::bad_fcs: return "bad FCS";
    case FrameStatus::bad_address: return "bad address";
    case FrameStatus::unknown_type: return "unknown frame type";
    case FrameStatus::bad_data_length: return "bad data length";
    case FrameStatus::bad_control: return "reserved message-control bits set";
    case FrameStatus::not_m3: return "not an M-III frame";
  }
  return "?";
}

bool is_cyclic_length(std::size_t n) noexcept { return n == 8 || n == 16 || n == 32 || n == 48 || n == 64; }

bool data_length_allowed(FrameType type, std::size_t n) noexcept {
  switch (type) {
    case FrameType::cyclic_command:
    case FrameType::cyclic_response: return is_cyclic_length(n);
    case FrameType::event_command:
    case FrameType::event_response: return n == kMaxData;  // seed 000: fixed at 64 bytes
    case FrameType::sync:
    case FrameType::detect_reply:
    case FrameType::comm_start: return n == 8;
    case FrameType::cycle_notify: return n == 16;
    case FrameType::detect:
    case FrameType::delay_request:
    case FrameType::delay_reply: return n == 0;
  }
  return false;
}

std::uint32_t fcs(std::span<const std::uint8_t> bytes) noexcept {
  return static_cast<std::uint32_t>(
      crc32(crc32(0L, Z_NULL, 0), bytes.data(), static_cast<uInt>(bytes.size())));
}

FrameStatus decode_prefix(std::span<const std::uint8_t> bytes, FrameView& out, std::size_t* used) {
  if (bytes.size() < kHeaderSize + kFcsSize) return FrameStatus::truncated;
  const std::uint8_t* h = bytes.data();
  const std::size_t n = h[4];
  if (n > kMaxData) return FrameStatus::bad_data_length;
  const std::size_t size = kHeaderSize + n + kFcsSize;
  if (bytes.size() < size) return FrameStatus::truncated;
  // The FCS first, as the ASIC does: a corrupted header must not be interpreted.
  if (fcs(bytes.first(size - kFcsSize)) != get_u32le(h + size - kFcsSize)) return FrameStatus::bad_fcs;
  if (const FrameStatus s = check_header(h); s != FrameStatus::ok) return s;
  out = FrameView{h[0], h[1], h[2], static_cast<FrameType>(h[3]), bytes.subspan(kHeaderSize, n)};
  if (used != nullptr) *used = size;
  return FrameStatus::ok;
}

FrameStatus decode(std::span<const std::uint8_t> bytes, FrameView& out) {
  if (bytes.size() > kMaxFrame) return FrameStatus::oversized;
  std::size_t used = 0;
  const FrameStatus s = decode_prefix(bytes, out, &used);
  if (s == FrameStatus::ok && used != bytes.size()) return FrameStatus::oversized;  // bytes after the FCS
  return s;
}

std::size_t encode(const FrameSpec& f, std::span<std::uint8_t> out) {
  const std::size_t size = kHeaderSize + f.data.size() + kFcsSize;
  if (!data_length_allowed(f.type, f.data.size()) || out.size() < size) return 0;
  if (!is_station_address(f.src) || (!is_station_address(f.dst) && f.dst != kBroadcast)) return 0;
  std::uint8_t* p = out.data();
  p[0] = f.dst;
  p[1] = f.src;
  p[2] = static_cast<std::uint8_t>((f.sequence & kSequenceMask) | (f.retry ? kRetryBit : 0));
  p[3] = static_cast<std::uint8_t>(f.type);
  p[4] = static_cast<std::uint8_t>(f.data.size());
  if (!f.data.empty()) std::memcpy(p + kHeaderSize, f.data.data(), f.data.size());
  put_u32le(p + size - kFcsSize, fcs(out.first(size - kFcsSize)));
  return size;
}

Mac station_mac(std::uint8_t address) noexcept {
  if (address == kBroadcast) return {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF};
  return {0x02, 0x4D, 0x33, 0x00, 0x00, address};
}

std::size_t encapsulate(std::span<const std::uint8_t> m3, std::span<std::uint8_t> out) {
  FrameView v;
  if (decode(m3, v) != FrameStatus::ok) return 0;
  const std::size_t size = std::max(kEthHeaderSize + m3.size(), kMinEthFrame);
  if (out.size() < size) return 0;
  const Mac dst = station_mac(v.dst), src = station_mac(v.src);
  std::memcpy(out.data(), dst.data(), 6);
  std::memcpy(out.data() + 6, src.data(), 6);
  out[12] = static_cast<std::uint8_t>(kEtherType >> 8);
  out[13] = static_cast<std::uint8_t>(kEtherType & 0xFF);
  std::memcpy(out.data() + kEthHeaderSize, m3.data(), m3.size());
  std::fill(out.begin() + static_cast<std::ptrdiff_t>(kEthHeaderSize + m3.size()),
            out.begin() + static_cast<std::ptrdiff_t>(size), std::uint8_t{0});
  return size;
}

FrameStatus decapsulate(std::span<const std::uint8_t> eth, FrameView& out) {
  if (eth.size() < kEthHeaderSize) return FrameStatus::truncated;
  if (((eth[12] << 8) | eth[13]) != kEtherType) return FrameStatus::not_m3;
  const auto payload = eth.subspan(kEthHeaderSize);
  std::size_t used = 0;
  const FrameStatus s = decode_prefix(payload, out, &used);
  if (s != FrameStatus::ok) return s;
  // After the frame only the padding to the Ethernet minimum (and the Ethernet FCS, where a
  // capture kept it) may follow: 64 bytes in all.
  if (used != payload.size() && eth.size() > kMinEthFrame + 4) return FrameStatus::oversized;
  return FrameStatus::ok;
}

}  // namespace omnitwin::m3
