// bus_emulators/ethercat/transport — spec parsing, dispatch and the PDU check; see ec_transport.hpp.
#include "bus_emulators/ethercat/transport/ec_transport.hpp"

#include "bus_emulators/ethercat/ec_frame.hpp"
#include "bus_emulators/transport_spec.hpp"
#include "bus_emulators/ethercat/transport/ec_transport_mem.hpp"
#include "bus_emulators/ethercat/transport/ec_transport_raw.hpp"
#include "bus_emulators/ethercat/transport/ec_transport_udp.hpp"

#include <net/if.h>
#include <poll.h>

#include <cerrno>


namespace omnitwin::ethercat {

namespace {

[[noreturn]] void bad(std::string_view spec, const std::string& why) {
  throw TransportError("bad EtherCAT transport spec '" + std::string(spec) + "': " + why +
                       " (expected raw:IFACE, udp:HOST[:PORT], udp:[HOST6][:PORT] or mem:NAME)");
}

}  // namespace

const char* to_string(Role r) {
  switch (r) {
    case Role::master: return "master";
    case Role::slaves: return "slaves";
  }
  return "?";
}

TransportSpec parse_transport_spec(std::string_view spec) {
  TransportSpec t;
  if (const std::string why = bus_emulators::parse_frame_transport_spec(spec, kUdpPort, t); !why.empty()) bad(spec, why);
  return t;
}

std::unique_ptr<EcTransport> open_transport(std::string_view spec, Role role) {
  const TransportSpec t = parse_transport_spec(spec);
  switch (t.kind) {
    case TransportSpec::Kind::raw: return std::make_unique<RawTransport>(t.name, role);
    case TransportSpec::Kind::udp: return std::make_unique<UdpTransport>(t, role);
    case TransportSpec::Kind::mem: return std::make_unique<MemTransport>(t.name, role);
  }
  throw TransportError("unreachable transport kind");
}

PduCheck check_pdu(const std::uint8_t* data, std::size_t n, std::size_t& size) noexcept {
  // The smallest PDU: the EtherCAT header and one datagram without data.
  constexpr std::size_t kMinPdu = kEcatHeaderSize + kDatagramHeaderSize + kWkcSize;
  if (n < kEcatHeaderSize) return PduCheck::malformed;
  const std::uint16_t header = get_u16(data);
  if ((header >> 12) != kPduTypeSlaves) return PduCheck::foreign;  // type 1: EtherCAT datagrams
  const std::size_t length = header & 0x07FFu;
  if (n < kMinPdu || length + kEcatHeaderSize < kMinPdu || length + kEcatHeaderSize > n) return PduCheck::malformed;
  size = length + kEcatHeaderSize;
  return PduCheck::ok;
}

}  // namespace omnitwin::ethercat
