// bus_emulators/can — transport spec parsing and dispatch; see transport.hpp.
#include "bus_emulators/can/transport.hpp"

#include "bus_emulators/can/transport_mem.hpp"
#include "bus_emulators/can/transport_socketcan.hpp"
#include "bus_emulators/can/transport_udp.hpp"
#include "bus_emulators/transport_spec.hpp"

#include <arpa/inet.h>
#include <net/if.h>
#include <poll.h>

#include <cerrno>
#include <charconv>

namespace omnitwin::can {

namespace {

[[noreturn]] void bad(std::string_view spec, const std::string& why) {
  throw TransportError("bad CAN transport spec '" + std::string(spec) + "': " + why +
                       " (expected socketcan:IFACE, udp:GROUP[:PORT][?ttl=N&iface=NAME&own=1],"
                       " udp:[GROUP6][:PORT], or mem:NAME)");
}

bool parse_int(std::string_view s, long min, long max, long& out) {
  if (s.empty()) return false;
  long v = 0;
  const auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc{} || p != s.data() + s.size() || v < min || v > max) return false;
  out = v;
  return true;
}

void parse_udp(std::string_view spec, std::string_view rest, TransportSpec& t) {
  std::string_view opts;
  if (const auto q = rest.find('?'); q != std::string_view::npos) {
    opts = rest.substr(q + 1);
    rest = rest.substr(0, q);
  }
  std::string_view host;
  std::string_view port;
  if (rest.empty()) {
    host = kPythonCanGroupV6;  // python-can's default channel
  } else if (const std::string why = bus_emulators::split_host_port(rest, host, port, "group", "udp:[ff15::1]:43113");
             !why.empty()) {
    bad(spec, why);
  }
  t.name = std::string(host);
  if (t.name.empty()) bad(spec, "empty multicast group");
  in_addr a4{};
  in6_addr a6{};
  if (inet_pton(AF_INET, t.name.c_str(), &a4) == 1) {
    t.ipv6 = false;
    if (!IN_MULTICAST(ntohl(a4.s_addr))) bad(spec, t.name + " is not an IPv4 multicast address (224.0.0.0/4)");
  } else if (inet_pton(AF_INET6, t.name.c_str(), &a6) == 1) {
    t.ipv6 = true;
    if (!IN6_IS_ADDR_MULTICAST(&a6)) bad(spec, t.name + " is not an IPv6 multicast address (ff00::/8)");
  } else {
    bad(spec, "'" + t.name + "' is not a numeric IPv4 or IPv6 multicast address");
  }
  t.port = kPythonCanUdpPort;
  if (port == "0") {
    t.port = 0;  // a port of its own, chosen when the transport opens (spec() names it)
  } else if (!port.empty()) {
    const auto p = bus_emulators::parse_port(port);
    if (!p) bad(spec, "port must be 1..65535, or 0 for a free one");
    t.port = *p;
  }

  while (!opts.empty()) {
    const auto amp = opts.find('&');
    std::string_view kv = opts.substr(0, amp);
    opts = amp == std::string_view::npos ? std::string_view{} : opts.substr(amp + 1);
    const auto eq = kv.find('=');
    if (eq == std::string_view::npos) bad(spec, "option '" + std::string(kv) + "' needs a value");
    const std::string_view k = kv.substr(0, eq);
    const std::string_view val = kv.substr(eq + 1);
    long n = 0;
    if (k == "ttl") {
      if (!parse_int(val, 0, 255, n)) bad(spec, "ttl must be 0..255");
      t.ttl = static_cast<int>(n);
    } else if (k == "iface") {
      if (val.empty() || val.size() >= IF_NAMESIZE) bad(spec, "bad interface name");
      t.iface = std::string(val);
    } else if (k == "own") {
      if (!parse_int(val, 0, 1, n)) bad(spec, "own must be 0 or 1");
      t.receive_own = n == 1;
    } else {
      bad(spec, "unknown option '" + std::string(k) + "'");
    }
  }
}

}  // namespace

TransportSpec parse_transport_spec(std::string_view spec) {
  const auto colon = spec.find(':');
  const std::string_view kind = spec.substr(0, colon);
  const std::string_view rest = colon == std::string_view::npos ? std::string_view{} : spec.substr(colon + 1);
  TransportSpec t;
  if (kind == "socketcan") {
    t.kind = TransportSpec::Kind::socketcan;
    if (const std::string why = bus_emulators::interface_name_problem(rest); !why.empty()) bad(spec, why);
    t.name = std::string(rest);
  } else if (kind == "udp") {
    t.kind = TransportSpec::Kind::udp;
    parse_udp(spec, rest, t);
  } else if (kind == "mem") {
    t.kind = TransportSpec::Kind::mem;
    if (rest.empty()) bad(spec, "missing bus name");
    t.name = std::string(rest);
  } else {
    bad(spec, "unknown transport '" + std::string(kind) + "'");
  }
  return t;
}

std::unique_ptr<Transport> open_transport(std::string_view spec) {
  const TransportSpec t = parse_transport_spec(spec);
  switch (t.kind) {
    case TransportSpec::Kind::socketcan: return std::make_unique<SocketCanTransport>(t.name);
    case TransportSpec::Kind::udp: return std::make_unique<UdpTransport>(t);
    case TransportSpec::Kind::mem: return std::make_unique<MemTransport>(t.name);
  }
  throw TransportError("unreachable transport kind");
}

std::size_t Transport::send_many(std::span<const TimedFrame> frames) {
  std::size_t sent = 0;
  for (const TimedFrame& f : frames) sent += send(f.frame, f.timestamp_ns) ? 1 : 0;
  return sent;
}

bool wait_readable(const Transport& t, std::chrono::milliseconds timeout) {
  pollfd p{t.poll_fd(), POLLIN, 0};
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    const int r = ::poll(&p, 1, static_cast<int>(std::max<long long>(0, left.count())));
    if (r > 0) return true;
    if (r == 0) return false;
    if (errno != EINTR) return false;
  }
}

std::optional<TimedFrame> receive_within(Transport& t, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    if (auto f = t.receive()) return f;
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left <= std::chrono::milliseconds(0)) return std::nullopt;
    wait_readable(t, left);
  }
}

}  // namespace omnitwin::can
