// bus_emulators — the spelling every bus's transport spec shares ("socketcan:IFACE",
// "raw:IFACE", "udp:HOST[:PORT]", "udp:[HOST6][:PORT]"): interface names and the host/port
// split with IPv6 in brackets. Each bus checks its own meaning (multicast group or unicast
// host, its default port, its options) and words its own errors around these answers.
// FrameTransportSpec is the whole spec of the frame buses (EtherCAT, MECHATROLINK-III).
// Pure string work, header-only; set-up code.
#pragma once

#include <net/if.h>

#include <charconv>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace omnitwin::bus_emulators {

// Why `name` cannot be a network interface name, or "" when it can.
inline std::string interface_name_problem(std::string_view name) {
  if (name.empty()) return "missing interface name";
  if (name.size() >= IF_NAMESIZE) return "interface name longer than 15 characters";
  if (name.find_first_of(":/ ?&") != std::string_view::npos) return "bad interface name";
  return "";
}

// Splits HOST[:PORT] or [HOST6][:PORT] into host and port (port empty when not given). Returns
// the problem, or "" when the spelling is good. `noun` names the host in messages ("address",
// "group"); `bracketed` is an example of the bracketed form ("udp:[::1]:34980").
inline std::string split_host_port(std::string_view text, std::string_view& host, std::string_view& port,
                                   std::string_view noun, std::string_view bracketed) {
  host = port = {};
  if (!text.empty() && text.front() == '[') {
    const auto close = text.find(']');
    if (close == std::string_view::npos) return "missing ']' after the IPv6 " + std::string(noun);
    host = text.substr(1, close - 1);
    const std::string_view after = text.substr(close + 1);
    if (after.empty()) return "";
    if (after.front() != ':') return "expected ':PORT' after ']'";
    port = after.substr(1);
    return port.empty() ? "empty port" : "";
  }
  const auto colon = text.find(':');
  if (colon != std::string_view::npos && text.find(':', colon + 1) != std::string_view::npos)
    return "an IPv6 " + std::string(noun) + " must be written in brackets, e.g. " + std::string(bracketed);
  host = text.substr(0, colon);
  if (colon == std::string_view::npos) return "";
  port = text.substr(colon + 1);
  return port.empty() ? "empty port" : "";
}

// A port 1..65535 written in decimal, or nothing.
inline std::optional<std::uint16_t> parse_port(std::string_view text) {
  long v = 0;
  const auto [p, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc{} || p != text.data() + text.size() || v < 1 || v > 65535) return std::nullopt;
  return static_cast<std::uint16_t>(v);
}

// The spec of a frame transport, as EtherCAT and MECHATROLINK-III spell it: raw:IFACE (an
// Ethernet interface), udp:HOST[:PORT] or udp:[HOST6][:PORT] (port 0: a free one, chosen by
// the side that binds), mem:NAME (an in-process pair).
struct FrameTransportSpec {
  enum class Kind : std::uint8_t { raw, udp, mem };
  Kind kind = Kind::mem;
  std::string name;         // raw: interface; udp: host (no brackets); mem: pair name
  std::uint16_t port = 0;   // udp only
  // "raw:eth1", "udp:127.0.0.1:34980", "udp:[::1]:34980", "mem:x"
  std::string canonical() const {
    switch (kind) {
      case Kind::raw: return "raw:" + name;
      case Kind::udp:
        return (name.find(':') != std::string::npos ? "udp:[" + name + "]:" : "udp:" + name + ":") + std::to_string(port);
      case Kind::mem: return "mem:" + name;
    }
    return "?";
  }
};

// Parses a frame transport spec into `out` (UDP's port defaulting to `default_port`): "" when
// it is good, else why not; each bus words its own error around the answer.
inline std::string parse_frame_transport_spec(std::string_view spec, std::uint16_t default_port,
                                              FrameTransportSpec& out) {
  const auto colon = spec.find(':');
  if (colon == std::string_view::npos) return "missing ':' after the transport kind";
  const std::string_view kind = spec.substr(0, colon), rest = spec.substr(colon + 1);
  if (kind == "raw") {
    out.kind = FrameTransportSpec::Kind::raw;
    out.name = std::string(rest);
    return interface_name_problem(rest);
  }
  if (kind == "mem") {
    out.kind = FrameTransportSpec::Kind::mem;
    out.name = std::string(rest);
    return rest.empty() ? "missing pair name" : "";
  }
  if (kind != "udp") return "unknown transport '" + std::string(kind) + "'";
  out.kind = FrameTransportSpec::Kind::udp;
  std::string_view host, port;
  const std::string example = "udp:[::1]:" + std::to_string(default_port);
  if (std::string why = split_host_port(rest, host, port, "address", example); !why.empty()) return why;
  if (host.empty()) return "empty host";
  out.name = std::string(host);
  out.port = default_port;
  if (port == "0") out.port = 0;  // the side that binds takes a free port
  else if (!port.empty()) {
    const auto p = parse_port(port);
    if (!p) return "port must be 1..65535, or 0 for a free one (the slaves' side)";
    out.port = *p;
  }
  return "";
}

}  // namespace omnitwin::bus_emulators
