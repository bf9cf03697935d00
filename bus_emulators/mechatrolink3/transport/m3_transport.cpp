// bus_emulators/mechatrolink3/transport — spec parsing, dispatch and the framing check; see
// m3_transport.hpp.
#include "bus_emulators/mechatrolink3/transport/m3_transport.hpp"

#include "bus_emulators/mechatrolink3/transport/m3_transport_mem.hpp"
#include "bus_emulators/mechatrolink3/transport/m3_transport_raw.hpp"
#include "bus_emulators/mechatrolink3/transport/m3_transport_udp.hpp"
#include "bus_emulators/transport_spec.hpp"

#include <poll.h>

#include <cerrno>

namespace omnitwin::m3 {

namespace {

[[noreturn]] void bad(std::string_view spec, const std::string& why) {
  throw TransportError("bad MECHATROLINK-III transport spec '" + std::string(spec) + "': " + why +
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

std::unique_ptr<M3Transport> open_transport(std::string_view spec, Role role) {
  const TransportSpec t = parse_transport_spec(spec);
  switch (t.kind) {
    case TransportSpec::Kind::raw: return std::make_unique<RawTransport>(t.name, role);
    case TransportSpec::Kind::udp: return std::make_unique<UdpTransport>(t, role);
    case TransportSpec::Kind::mem: return std::make_unique<MemTransport>(t.name, role);
  }
  throw TransportError("unreachable transport kind");
}

FrameCheck check_frame(const std::uint8_t* data, std::size_t n, std::size_t& size) noexcept {
  if (n < kMinFrame) return FrameCheck::malformed;
  const std::size_t length = data[4];  // the data length field
  if (length > kMaxData || kMinFrame + length > n) return FrameCheck::malformed;
  size = kMinFrame + length;
  return FrameCheck::ok;
}

}  // namespace omnitwin::m3
