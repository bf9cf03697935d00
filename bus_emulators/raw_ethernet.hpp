// bus_emulators — the raw-Ethernet part both Ethernet-framed buses' raw transports share
// (EtherCAT 0x88A4, MECHATROLINK-III 0x88B5): an AF_PACKET socket on one interface (opened,
// its index and MAC read, bound once the bus has set its options and kernel filter), and one
// frame sent as header + payload + zero padding to the 60-byte Ethernet minimum in a single
// sendmsg. Each bus keeps its addressing, filter and receive checks. Error is the bus's
// TransportError; messages name the spec. Header-only; set-up throws, send() never does.
#pragma once

#include <arpa/inet.h>
#include <linux/if_packet.h>
#include <net/if.h>
#include <net/if_arp.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>

#include <fmt/format.h>

namespace omnitwin::bus_emulators {

using EthernetMac = std::array<std::uint8_t, 6>;

inline std::string mac_text(const EthernetMac& m) {
  return fmt::format("{:02x}:{:02x}:{:02x}:{:02x}:{:02x}:{:02x}", m[0], m[1], m[2], m[3], m[4], m[5]);
}

struct RawSocket {
  int fd = -1;
  int ifindex = 0;
  EthernetMac mac{};
};

// Closes s.fd and throws Error "SPEC: WHAT: the system's reason".
template <class Error>
[[noreturn]] void raw_socket_failed(RawSocket& s, const std::string& spec, const std::string& what) {
  const std::string m = fmt::format("{}: {}: {}", spec, what, std::strerror(errno));
  if (s.fd >= 0) ::close(s.fd);
  s.fd = -1;
  throw Error(m);
}

// A non-blocking AF_PACKET socket (protocol 0: it receives nothing until bound) on `ifname`,
// with the interface's index and MAC. Throws Error for a bad name, a missing privilege, a
// missing or non-Ethernet interface.
template <class Error>
RawSocket open_raw_socket(const std::string& ifname, const std::string& spec) {
  if (ifname.empty() || ifname.size() >= IFNAMSIZ) throw Error(spec + ": bad interface name (1 to 15 characters)");
  RawSocket s;
  s.fd = ::socket(AF_PACKET, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (s.fd < 0) {
    if (errno == EPERM || errno == EACCES)
      throw Error(fmt::format("{}: opening a raw AF_PACKET socket needs root or CAP_NET_RAW ({})", spec,
                              std::strerror(errno)));
    throw Error(fmt::format("{}: socket(AF_PACKET, SOCK_RAW): {}", spec, std::strerror(errno)));
  }
  ifreq ifr{};
  std::memcpy(ifr.ifr_name, ifname.c_str(), ifname.size());
  if (::ioctl(s.fd, SIOCGIFINDEX, &ifr) != 0) raw_socket_failed<Error>(s, spec, "no network interface '" + ifname + "'");
  s.ifindex = ifr.ifr_ifindex;
  if (::ioctl(s.fd, SIOCGIFHWADDR, &ifr) != 0) raw_socket_failed<Error>(s, spec, "SIOCGIFHWADDR");
  if (ifr.ifr_hwaddr.sa_family != ARPHRD_ETHER) {
    errno = EINVAL;
    raw_socket_failed<Error>(s, spec, "'" + ifname + "' is not an Ethernet interface (use a veth pair or a NIC)");
  }
  std::memcpy(s.mac.data(), ifr.ifr_hwaddr.sa_data, s.mac.size());
  return s;
}

// Binds the socket to its interface for `protocol` (host order: an EtherType, or ETH_P_ALL).
template <class Error>
void bind_raw_socket(RawSocket& s, std::uint16_t protocol, const std::string& spec) {
  sockaddr_ll sll{};
  sll.sll_family = AF_PACKET;
  sll.sll_protocol = htons(protocol);
  sll.sll_ifindex = s.ifindex;
  if (::bind(s.fd, reinterpret_cast<sockaddr*>(&sll), sizeof sll) != 0) raw_socket_failed<Error>(s, spec, "bind");
}

// One Ethernet frame: the 14-byte header, the payload, zeros up to 60 bytes. True when the
// kernel took all of it; false (errno kept) otherwise: ENETDOWN, ENOBUFS, ENXIO, … Real-time safe.
inline bool send_padded(int fd, const std::uint8_t* header, std::span<const std::uint8_t> payload) noexcept {
  static constexpr std::uint8_t kZeros[60] = {};
  const std::size_t used = 14 + payload.size();
  const std::size_t pad = used < sizeof kZeros ? sizeof kZeros - used : 0;
  iovec iov[3] = {{const_cast<std::uint8_t*>(header), 14},
                  {const_cast<std::uint8_t*>(payload.data()), payload.size()},
                  {const_cast<std::uint8_t*>(kZeros), pad}};
  msghdr msg{};
  msg.msg_iov = iov;
  msg.msg_iovlen = pad > 0 ? 3 : 2;
  for (;;) {
    const ssize_t n = ::sendmsg(fd, &msg, MSG_DONTWAIT | MSG_NOSIGNAL);
    if (n == static_cast<ssize_t>(used + pad)) return true;
    if (n < 0 && errno == EINTR) continue;
    return false;
  }
}

}  // namespace omnitwin::bus_emulators
