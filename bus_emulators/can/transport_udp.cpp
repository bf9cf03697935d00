// bus_emulators/can — CAN over UDP multicast (python-can `udp_multicast`); see transport_udp.hpp.
#include "bus_emulators/can/transport_udp.hpp"

#include "bus_emulators/can/can_msgpack.hpp"

#include <arpa/inet.h>
#include <ifaddrs.h>
#include <net/if.h>
#include <netinet/in.h>
#include <poll.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fmt/format.h>

namespace omnitwin::can {

namespace {

#ifndef IPV6_MULTICAST_ALL
#define IPV6_MULTICAST_ALL 29  // Linux >= 4.20
#endif

[[noreturn]] void fail(const TransportSpec& s, const std::string& what) {
  throw TransportError(fmt::format("udp CAN transport {}:{}: {}: {}", s.name, s.port, what, std::strerror(errno)));
}

void set_opt(int fd, int level, int name, int value, const TransportSpec& s, const char* what) {
  if (::setsockopt(fd, level, name, &value, sizeof value) != 0) fail(s, what);
}

bool same_addr(const sockaddr_storage& a, const sockaddr_storage& b) {
  if (a.ss_family != b.ss_family) return false;
  if (a.ss_family == AF_INET)
    return reinterpret_cast<const sockaddr_in&>(a).sin_addr.s_addr ==
           reinterpret_cast<const sockaddr_in&>(b).sin_addr.s_addr;
  if (a.ss_family == AF_INET6)
    return std::memcmp(&reinterpret_cast<const sockaddr_in6&>(a).sin6_addr,
                       &reinterpret_cast<const sockaddr_in6&>(b).sin6_addr, sizeof(in6_addr)) == 0;
  return false;
}

}  // namespace

UdpTransport::UdpTransport(const TransportSpec& spec) : spec_(spec) {
  if (spec_.kind != TransportSpec::Kind::udp) throw TransportError("UdpTransport: not a udp spec");
  const int family = spec_.ipv6 ? AF_INET6 : AF_INET;
  unsigned ifindex = 0;
  if (!spec_.iface.empty()) {
    ifindex = ::if_nametoindex(spec_.iface.c_str());
    if (ifindex == 0) fail(spec_, "no interface '" + spec_.iface + "'");
  }

  rx_fd_ = ::socket(family, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (rx_fd_ < 0) fail(spec_, "socket");
  tx_fd_ = ::socket(family, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (tx_fd_ < 0) {
    ::close(rx_fd_);
    fail(spec_, "socket");
  }
  try {
    set_opt(rx_fd_, SOL_SOCKET, SO_REUSEADDR, 1, spec_, "SO_REUSEADDR");  // share the port (python-can does too)
    if (spec_.ipv6) {
      auto& g = reinterpret_cast<sockaddr_in6&>(group_);
      g.sin6_family = AF_INET6;
      g.sin6_port = htons(spec_.port);
      ::inet_pton(AF_INET6, spec_.name.c_str(), &g.sin6_addr);
      g.sin6_scope_id = ifindex;
      group_len_ = sizeof(sockaddr_in6);
      set_opt(rx_fd_, IPPROTO_IPV6, IPV6_V6ONLY, 1, spec_, "IPV6_V6ONLY");
      const int off = 0;  // best effort: older kernels lack IPV6_MULTICAST_ALL
      ::setsockopt(rx_fd_, IPPROTO_IPV6, IPV6_MULTICAST_ALL, &off, sizeof off);
      if (::bind(rx_fd_, reinterpret_cast<sockaddr*>(&group_), group_len_) != 0) fail(spec_, "bind");
      ipv6_mreq mreq{};
      mreq.ipv6mr_multiaddr = g.sin6_addr;
      mreq.ipv6mr_interface = ifindex;
      if (::setsockopt(rx_fd_, IPPROTO_IPV6, IPV6_JOIN_GROUP, &mreq, sizeof mreq) != 0) fail(spec_, "IPV6_JOIN_GROUP");
      set_opt(tx_fd_, IPPROTO_IPV6, IPV6_V6ONLY, 1, spec_, "IPV6_V6ONLY");
      set_opt(tx_fd_, IPPROTO_IPV6, IPV6_MULTICAST_HOPS, spec_.ttl, spec_, "IPV6_MULTICAST_HOPS");
      set_opt(tx_fd_, IPPROTO_IPV6, IPV6_MULTICAST_LOOP, 1, spec_, "IPV6_MULTICAST_LOOP");
      if (ifindex != 0) set_opt(tx_fd_, IPPROTO_IPV6, IPV6_MULTICAST_IF, static_cast<int>(ifindex), spec_, "IPV6_MULTICAST_IF");
      sockaddr_in6 any{};
      any.sin6_family = AF_INET6;
      if (::bind(tx_fd_, reinterpret_cast<sockaddr*>(&any), sizeof any) != 0) fail(spec_, "bind (send socket)");
    } else {
      auto& g = reinterpret_cast<sockaddr_in&>(group_);
      g.sin_family = AF_INET;
      g.sin_port = htons(spec_.port);
      ::inet_pton(AF_INET, spec_.name.c_str(), &g.sin_addr);
      group_len_ = sizeof(sockaddr_in);
      set_opt(rx_fd_, IPPROTO_IP, IP_MULTICAST_ALL, 0, spec_, "IP_MULTICAST_ALL");
      if (::bind(rx_fd_, reinterpret_cast<sockaddr*>(&group_), group_len_) != 0) fail(spec_, "bind");
      ip_mreqn mreq{};
      mreq.imr_multiaddr = g.sin_addr;
      mreq.imr_ifindex = static_cast<int>(ifindex);
      if (::setsockopt(rx_fd_, IPPROTO_IP, IP_ADD_MEMBERSHIP, &mreq, sizeof mreq) != 0) fail(spec_, "IP_ADD_MEMBERSHIP");
      set_opt(tx_fd_, IPPROTO_IP, IP_MULTICAST_TTL, spec_.ttl, spec_, "IP_MULTICAST_TTL");
      set_opt(tx_fd_, IPPROTO_IP, IP_MULTICAST_LOOP, 1, spec_, "IP_MULTICAST_LOOP");
      if (ifindex != 0) {
        ip_mreqn ifreq{};
        ifreq.imr_ifindex = static_cast<int>(ifindex);
        if (::setsockopt(tx_fd_, IPPROTO_IP, IP_MULTICAST_IF, &ifreq, sizeof ifreq) != 0) fail(spec_, "IP_MULTICAST_IF");
      }
      sockaddr_in any{};
      any.sin_family = AF_INET;
      if (::bind(tx_fd_, reinterpret_cast<sockaddr*>(&any), sizeof any) != 0) fail(spec_, "bind (send socket)");
    }
    sockaddr_storage self{};
    socklen_t len = sizeof self;
    if (::getsockname(tx_fd_, reinterpret_cast<sockaddr*>(&self), &len) != 0) fail(spec_, "getsockname");
    tx_port_ = spec_.ipv6 ? reinterpret_cast<sockaddr_in6&>(self).sin6_port : reinterpret_cast<sockaddr_in&>(self).sin_port;

    ifaddrs* ifs = nullptr;
    if (::getifaddrs(&ifs) == 0) {
      for (ifaddrs* i = ifs; i; i = i->ifa_next) {
        if (!i->ifa_addr || i->ifa_addr->sa_family != family) continue;
        sockaddr_storage a{};
        std::memcpy(&a, i->ifa_addr, family == AF_INET6 ? sizeof(sockaddr_in6) : sizeof(sockaddr_in));
        local_addrs_.push_back(a);
      }
      ::freeifaddrs(ifs);
    }
  } catch (...) {
    ::close(rx_fd_);
    ::close(tx_fd_);
    throw;
  }
}

UdpTransport::~UdpTransport() {
  if (rx_fd_ >= 0) ::close(rx_fd_);
  if (tx_fd_ >= 0) ::close(tx_fd_);
}

std::string UdpTransport::spec() const {
  std::string s = spec_.ipv6 ? fmt::format("udp:[{}]:{}", spec_.name, spec_.port)
                             : fmt::format("udp:{}:{}", spec_.name, spec_.port);
  std::string opts;
  if (spec_.ttl != 1) opts += fmt::format("&ttl={}", spec_.ttl);
  if (!spec_.iface.empty()) opts += "&iface=" + spec_.iface;
  if (spec_.receive_own) opts += "&own=1";
  if (!opts.empty()) s += "?" + opts.substr(1);
  return s;
}

bool UdpTransport::send_raw(const std::uint8_t* data, std::size_t size) {
  // A full socket buffer (EAGAIN/ENOBUFS: the kernel has not yet handed earlier datagrams to
  // the local receivers) is back-pressure, not loss: wait for room, a bounded time.
  int waits = 0;
  for (;;) {
    const ssize_t n = ::sendto(tx_fd_, data, size, MSG_DONTWAIT | MSG_NOSIGNAL,
                               reinterpret_cast<const sockaddr*>(&group_), group_len_);
    if (n == static_cast<ssize_t>(size)) return true;
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == ENOBUFS) && waits < kSendRetries) {
      ++waits;
      ++stats_.send_waits;
      pollfd p{tx_fd_, POLLOUT, 0};
      ::poll(&p, 1, kSendWaitMs);
      continue;
    }
    ++stats_.send_errors;
    return false;
  }
}

bool UdpTransport::send(const Frame& f, std::int64_t timestamp_ns) {
  std::array<std::uint8_t, msgpack_wire::kMaxEncodedSize> buf{};
  const std::size_t n = msgpack_wire::encode(f, static_cast<double>(timestamp_ns) * 1e-9, buf);
  if (n == 0) {
    ++stats_.invalid_tx;
    return false;
  }
  if (!send_raw(buf.data(), n)) return false;
  ++stats_.frames_tx;
  return true;
}

bool UdpTransport::is_own(const sockaddr_storage& from) const {
  const std::uint16_t port = from.ss_family == AF_INET6 ? reinterpret_cast<const sockaddr_in6&>(from).sin6_port
                                                        : reinterpret_cast<const sockaddr_in&>(from).sin_port;
  if (port != tx_port_) return false;
  for (const auto& a : local_addrs_)
    if (same_addr(a, from)) return true;
  return false;
}

std::optional<TimedFrame> UdpTransport::receive() {
  // One byte more than python-can reads, so that an oversized datagram shows as truncated.
  std::array<std::uint8_t, msgpack_wire::kMaxDatagramSize + 1> buf;
  // Bounded, so that a flood of bad datagrams cannot hold the caller's loop; the descriptor
  // stays readable for the rest.
  for (int budget = 256; budget > 0; --budget) {
    sockaddr_storage from{};
    iovec iov{buf.data(), buf.size()};
    msghdr msg{};
    msg.msg_name = &from;
    msg.msg_namelen = sizeof from;
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    const ssize_t n = ::recvmsg(rx_fd_, &msg, MSG_DONTWAIT);
    if (n < 0) {
      if (errno == EINTR) continue;  // (uses one unit of budget)
      if (errno != EAGAIN && errno != EWOULDBLOCK) ++stats_.rx_errors;
      return std::nullopt;
    }
    if (!spec_.receive_own && is_own(from)) continue;
    if ((msg.msg_flags & MSG_TRUNC) || static_cast<std::size_t>(n) > msgpack_wire::kMaxDatagramSize) {
      ++stats_.malformed_rx;
      continue;
    }
    msgpack_wire::Decoded d;
    switch (msgpack_wire::decode({buf.data(), static_cast<std::size_t>(n)}, d)) {
      case msgpack_wire::DecodeStatus::ok: {
        ++stats_.frames_rx;
        const double ns = d.timestamp * 1e9;
        const std::int64_t ts = std::isfinite(ns) && std::fabs(ns) < 9.2e18 ? std::llround(ns) : 0;
        return TimedFrame{d.frame, ts};
      }
      case msgpack_wire::DecodeStatus::wrong_dlc: ++stats_.wrong_dlc_rx; break;
      case msgpack_wire::DecodeStatus::bad_id: ++stats_.bad_id_rx; break;
      case msgpack_wire::DecodeStatus::fd_unsupported:
      case msgpack_wire::DecodeStatus::invalid_flags: ++stats_.unsupported_rx; break;
      case msgpack_wire::DecodeStatus::malformed:
      case msgpack_wire::DecodeStatus::unknown_key:
      case msgpack_wire::DecodeStatus::bad_type: ++stats_.malformed_rx; break;
    }
  }
  return std::nullopt;
}

}  // namespace omnitwin::can
