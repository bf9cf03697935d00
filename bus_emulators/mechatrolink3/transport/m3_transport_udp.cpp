// bus_emulators/mechatrolink3/transport — M-III over UDP; see m3_transport_udp.hpp.
#include "bus_emulators/mechatrolink3/transport/m3_transport_udp.hpp"

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fmt/format.h>

namespace omnitwin::m3 {

UdpTransport::UdpTransport(const TransportSpec& spec, Role role) : spec_(spec), role_(role) {
  if (spec_.kind != TransportSpec::Kind::udp) throw TransportError("UdpTransport: not a udp spec");
  if (role_ == Role::master && spec_.port == 0)
    throw TransportError(fmt::format("{}: a master needs the slaves' port (0 is for the slaves' side)",
                                     spec_.canonical()));
  const int family = resolve();
  fd_ = ::socket(family, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd_ < 0) throw TransportError(fmt::format("{}: socket: {}", spec_.canonical(), std::strerror(errno)));
  bind_socket(family);
  sockaddr_storage self{};
  socklen_t len = sizeof self;
  if (::getsockname(fd_, reinterpret_cast<sockaddr*>(&self), &len) != 0) fail("getsockname");
  local_port_ = ntohs(family == AF_INET6 ? reinterpret_cast<sockaddr_in6&>(self).sin6_port
                                         : reinterpret_cast<sockaddr_in&>(self).sin_port);
}

UdpTransport::~UdpTransport() {
  if (fd_ >= 0) ::close(fd_);
}

int UdpTransport::resolve() {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_DGRAM;
  hints.ai_flags = AI_NUMERICSERV | (role_ == Role::slaves ? AI_PASSIVE : 0);
  addrinfo* res = nullptr;
  const std::string port = std::to_string(spec_.port);
  if (const int rc = ::getaddrinfo(spec_.name.c_str(), port.c_str(), &hints, &res); rc != 0 || !res)
    throw TransportError(
        fmt::format("{}: cannot resolve host '{}': {}", spec_.canonical(), spec_.name, ::gai_strerror(rc)));
  const int family = res->ai_family;
  std::memcpy(&peer_, res->ai_addr, res->ai_addrlen);
  peer_len_ = res->ai_addrlen;
  ::freeaddrinfo(res);
  return family;
}

void UdpTransport::bind_socket(int family) {
  if (role_ == Role::slaves) {
    if (::bind(fd_, reinterpret_cast<const sockaddr*>(&peer_), peer_len_) != 0) fail("bind");
    peer_ = {};
    peer_len_ = 0;
    return;
  }
  sockaddr_storage any{};
  any.ss_family = static_cast<sa_family_t>(family);
  const socklen_t len = family == AF_INET6 ? sizeof(sockaddr_in6) : sizeof(sockaddr_in);
  if (::bind(fd_, reinterpret_cast<const sockaddr*>(&any), len) != 0) fail("bind (ephemeral port)");
  have_peer_ = true;
}

void UdpTransport::fail(const std::string& what) {
  const std::string m = fmt::format("{}: {}: {}", spec_.canonical(), what, std::strerror(errno));
  ::close(fd_);
  fd_ = -1;
  throw TransportError(m);
}

std::string UdpTransport::spec() const {
  TransportSpec real = spec_;
  if (role_ == Role::slaves) real.port = local_port_;  // the free port bound for port 0
  return real.canonical();
}

std::string UdpTransport::describe() const {
  return fmt::format("{} ({}, local port {})", spec(), to_string(role_), local_port_);
}

bool UdpTransport::send(std::span<const std::uint8_t> frame) {
  if (frame.size() < kMinFrame || frame.size() > kMaxFrame || !have_peer_) {
    ++stats_.send_errors;
    return false;
  }
  for (;;) {
    const ssize_t n = ::sendto(fd_, frame.data(), frame.size(), MSG_DONTWAIT | MSG_NOSIGNAL,
                               reinterpret_cast<const sockaddr*>(&peer_), peer_len_);
    if (n == static_cast<ssize_t>(frame.size())) {
      ++stats_.sent;
      return true;
    }
    if (n < 0 && errno == EINTR) continue;
    ++stats_.send_errors;  // EAGAIN (socket buffer full), ECONNREFUSED from an earlier send, …
    return false;
  }
}

int UdpTransport::receive(std::span<std::uint8_t> buf, std::chrono::nanoseconds timeout) {
  detail::ReadableWaiter waiter(timeout);
  // Bounded, so that a flood of datagrams we drop cannot hold the caller; fd stays readable then.
  for (int budget = 256; budget > 0;) {
    sockaddr_storage from{};
    iovec iov{buf.data(), buf.size()};
    msghdr msg{};
    msg.msg_name = &from;
    msg.msg_namelen = sizeof from;
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    const long n = waiter.receive(fd_, msg);  // the datagram's real length even when buf is smaller
    if (n == detail::ReadableWaiter::kTimedOut) return 0;
    if (n < 0) {
      // ICMP port unreachable for an earlier send (nobody listening yet): not this receive's
      // failure; the next datagram may be fine.
      if (errno == ECONNREFUSED) continue;
      ++stats_.receive_errors;
      return -1;
    }
    --budget;
    std::size_t size = 0;
    if (check_frame(buf.data(), std::min(static_cast<std::size_t>(n), buf.size()), size) != FrameCheck::ok) {
      ++stats_.dropped_malformed;
      continue;
    }
    if (role_ == Role::slaves) {
      std::memcpy(&peer_, &from, msg.msg_namelen);
      peer_len_ = msg.msg_namelen;
      have_peer_ = true;
    }
    ++stats_.received;
    return static_cast<int>(size);
  }
  return 0;
}

}  // namespace omnitwin::m3
