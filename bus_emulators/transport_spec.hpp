// bus_emulators — the spelling every bus's transport spec shares ("socketcan:IFACE",
// "raw:IFACE", "udp:HOST[:PORT]", "udp:[HOST6][:PORT]"): interface names and the host/port
// split with IPv6 in brackets. Each bus checks its own meaning (multicast group or unicast
// host, its default port, its options) and words its own errors around these answers.
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

}  // namespace omnitwin::bus_emulators
