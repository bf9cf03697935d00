// bus_emulators/ethercat/transport — EtherCAT pcap writer (LINKTYPE_ETHERNET); see ec_pcap.hpp.
#include "bus_emulators/ethercat/transport/ec_pcap.hpp"

#include <cstring>

namespace omnitwin::ethercat {

namespace {
constexpr Mac kBroadcast = {0xff, 0xff, 0xff, 0xff, 0xff, 0xff};
}  // namespace

const char* to_string(Direction d) {
  switch (d) {
    case Direction::out: return "out";
    case Direction::back: return "back";
  }
  return "?";
}

bool PcapWriter::write(std::span<const std::uint8_t> pdu, SimTime t, Direction dir) {
  return write(pdu, t, dir, kBroadcast, master_mac_);
}

bool PcapWriter::write(std::span<const std::uint8_t> pdu, SimTime t, Direction dir, const Mac& dst, const Mac& src) {
  if (!writable()) return false;
  if (pdu.size() > kMaxPdu) {
    refuse();
    return false;
  }
  Mac from = src;
  if (dir == Direction::back) from[0] |= 0x02;
  write_eth_header(frame(), dst, from);
  if (!pdu.empty()) std::memcpy(frame() + kEthHeaderSize, pdu.data(), pdu.size());
  return record(kEthHeaderSize + pdu.size(), t, static_cast<int>(dir));
}

}  // namespace omnitwin::ethercat
