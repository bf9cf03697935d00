// bus_emulators/mechatrolink3 — M-III pcap writer (LINKTYPE_ETHERNET); see m3_pcap.hpp.
#include "bus_emulators/mechatrolink3/m3_pcap.hpp"

#include <cstring>

namespace omnitwin::m3 {

namespace {

// The Ethernet header encapsulate() writes, taken from the frame's address bytes whether or
// not the frame is valid (a corrupted frame is recorded as the receiver saw it).
void write_eth_header(std::uint8_t* out, std::uint8_t dst, std::uint8_t src) {
  const Mac d = station_mac(dst), s = station_mac(src);
  std::memcpy(out, d.data(), d.size());
  std::memcpy(out + 6, s.data(), s.size());
  out[12] = static_cast<std::uint8_t>(kEtherType >> 8);
  out[13] = static_cast<std::uint8_t>(kEtherType & 0xFF);
}

}  // namespace

const char* to_string(Direction d) {
  switch (d) {
    case Direction::out: return "out";
    case Direction::back: return "back";
  }
  return "?";
}

bool PcapWriter::write_frame(std::span<const std::uint8_t> m3_frame, SimTime t_ns, Direction dir) {
  if (!writable()) return false;
  if (m3_frame.size() < 2 || m3_frame.size() > kMaxFrame) {
    refuse();
    return false;
  }
  write_eth_header(frame(), m3_frame[0], m3_frame[1]);
  std::memcpy(frame() + kEthHeaderSize, m3_frame.data(), m3_frame.size());
  return record(kEthHeaderSize + m3_frame.size(), t_ns, static_cast<int>(dir));
}

}  // namespace omnitwin::m3
