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

void parse_udp(std::string_view spec, std::string_view rest, TransportSpec& t) {
  std::string_view host, port;
  if (const std::string why = bus_emulators::split_host_port(rest, host, port, "address", "udp:[::1]:34997");
      !why.empty())
    bad(spec, why);
  if (host.empty()) bad(spec, "empty host");
  t.name = std::string(host);
  t.port = kUdpPort;
  if (port == "0") {
    t.port = 0;  // the slaves' side binds a free port (spec() and local_port() name it)
  } else if (!port.empty()) {
    const auto p = bus_emulators::parse_port(port);
    if (!p) bad(spec, "port must be 1..65535, or 0 for a free one (the slaves' side)");
    t.port = *p;
  }
}

}  // namespace

const char* to_string(Role r) {
  switch (r) {
    case Role::master: return "master";
    case Role::slaves: return "slaves";
  }
  return "?";
}

std::string TransportSpec::canonical() const {
  switch (kind) {
    case Kind::raw: return "raw:" + name;
    case Kind::udp:
      return (name.find(':') != std::string::npos ? "udp:[" + name + "]:" : "udp:" + name + ":") + std::to_string(port);
    case Kind::mem: return "mem:" + name;
  }
  return "?";
}

TransportSpec parse_transport_spec(std::string_view spec) {
  const auto colon = spec.find(':');
  if (colon == std::string_view::npos) bad(spec, "missing ':' after the transport kind");
  const std::string_view kind = spec.substr(0, colon);
  const std::string_view rest = spec.substr(colon + 1);
  TransportSpec t;
  if (kind == "raw") {
    t.kind = TransportSpec::Kind::raw;
    if (const std::string why = bus_emulators::interface_name_problem(rest); !why.empty()) bad(spec, why);
    t.name = std::string(rest);
  } else if (kind == "udp") {
    t.kind = TransportSpec::Kind::udp;
    parse_udp(spec, rest, t);
  } else if (kind == "mem") {
    t.kind = TransportSpec::Kind::mem;
    if (rest.empty()) bad(spec, "missing pair name");
    t.name = std::string(rest);
  } else {
    bad(spec, "unknown transport '" + std::string(kind) + "'");
  }
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
