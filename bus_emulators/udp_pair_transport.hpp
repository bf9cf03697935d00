// bus_emulators — the UDP transport of the frame buses (`udp:HOST[:PORT]`: EtherCAT,
// MECHATROLINK-III): one frame per datagram each way, exactly the frame. One template, so
// both buses share one implementation; each bus gives its traits (as for the in-process
// pair, mem_pair_transport.hpp): its transport interface, Role, TransportError, the smallest
// and largest frame, and the framing check its receivers apply.
//
// slaves: one socket bound to HOST:PORT (HOST may be a wildcard such as 0.0.0.0 or ::; PORT 0
// binds a free port, which local_port() and spec() name); each reply goes to the sender of
// the last frame received. master: one socket bound to an ephemeral port of the same address
// family, sending to HOST:PORT (never port 0); it accepts frames from any sender (nobody else
// knows the ephemeral port). HOST may be numeric (IPv4, IPv6 in brackets) or a name, resolved
// once when opening. Datagrams the bus's check refuses are dropped and counted
// (dropped_foreign, dropped_malformed); bytes after the frame are trimmed.
//
// Real-time: send() and receive() allocate nothing and never throw (receive waits on fd()
// with the caller's timeout, at most 256 datagrams per call); opening throws Error naming the
// spec. Header-only.
#pragma once

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>

#include "bus_emulators/mem_pair_transport.hpp"  // FrameVerdict
#include "bus_emulators/readable_waiter.hpp"
#include "bus_emulators/sender_gate.hpp"
#include "bus_emulators/transport_spec.hpp"

namespace omnitwin::bus_emulators {

template <class Traits>
class UdpPairTransport final : public Traits::Base {
 public:
  using Role = typename Traits::Role;
  using Error = typename Traits::Error;
  using Stats = typename Traits::Base::Stats;

  // Throws Error naming the spec (unknown host, port in use, a master to port 0, …).
  UdpPairTransport(const FrameTransportSpec& spec, Role role) : spec_(spec), role_(role) {
    if (spec_.kind != FrameTransportSpec::Kind::udp) throw Error("UdpTransport: not a udp spec");
    if (role_ == Role::master && spec_.port == 0)
      throw Error(spec_.canonical() + ": a master needs the slaves' port (0 is for the slaves' side)");
    const int family = resolve();
    fd_ = ::socket(family, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (fd_ < 0) throw Error(spec_.canonical() + ": socket: " + std::strerror(errno));
    bind_socket(family);
    ReceiveStamp::enable(fd_);  // best effort: without it last_age_ns() says -1
    sockaddr_storage self{};
    socklen_t len = sizeof self;
    if (::getsockname(fd_, reinterpret_cast<sockaddr*>(&self), &len) != 0) fail("getsockname");
    local_port_ = ntohs(family == AF_INET6 ? reinterpret_cast<sockaddr_in6&>(self).sin6_port
                                           : reinterpret_cast<sockaddr_in&>(self).sin_port);
  }
  ~UdpPairTransport() {
    if (fd_ >= 0) ::close(fd_);
  }

  // master: to HOST:PORT; slaves: to the sender of the last frame (false while there is none).
  bool send(std::span<const std::uint8_t> frame) {
    if (frame.size() < Traits::kMinFrame || frame.size() > Traits::kMaxFrame || !have_peer_) {
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
  // The next frame the bus's check accepts: its size, 0 on timeout, -1 on a system error.
  int receive(std::span<std::uint8_t> buf, std::chrono::nanoseconds timeout) {
    ReadableWaiter waiter(timeout);
    // Bounded, so that a flood of datagrams we drop cannot hold the caller; fd stays readable then.
    for (int budget = 256; budget > 0;) {
      sockaddr_storage from{};
      iovec iov{buf.data(), buf.size()};
      msghdr msg{};
      msg.msg_name = &from;
      msg.msg_namelen = sizeof from;
      msg.msg_iov = &iov;
      msg.msg_iovlen = 1;
      stamp_.attach(msg);
      const long n = waiter.receive(fd_, msg);  // the datagram's real length even when buf is smaller
      if (n == ReadableWaiter::kTimedOut) return 0;
      if (n < 0) {
        // ICMP port unreachable for an earlier send (nobody listening yet): not this receive's
        // failure; the next datagram may be fine.
        if (errno == ECONNREFUSED) continue;
        ++stats_.receive_errors;
        return -1;
      }
      --budget;
      std::size_t size = 0;
      switch (Traits::check(buf.data(), std::min(static_cast<std::size_t>(n), buf.size()), size)) {
        case FrameVerdict::ok: break;
        case FrameVerdict::foreign: ++stats_.dropped_foreign; continue;
        case FrameVerdict::malformed: ++stats_.dropped_malformed; continue;
      }
      if (role_ == Role::slaves) {
        const std::span<const std::uint8_t> sender(reinterpret_cast<const std::uint8_t*>(&from), msg.msg_namelen);
        const std::int64_t now = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                     std::chrono::steady_clock::now().time_since_epoch())
                                     .count();
        if (!gate_.admit(sender, now, stats_.foreign_sender, stats_.refused_sender)) continue;
        stats_.master_changes = gate_.changes();
        remember_sender(from, msg.msg_namelen);
      }
      ++stats_.received;
      last_age_ns_ = ReceiveStamp::age_ns(msg);
      return static_cast<int>(size);
    }
    return 0;
  }
  int fd() const { return fd_; }
  // How long before receive() returned it the last frame had arrived [ns]; -1: unknown.
  std::int64_t last_age_ns() const { return last_age_ns_; }
  // slaves: the bound port (the free one for port 0); master: the slaves' port.
  std::string spec() const {
    FrameTransportSpec real = spec_;
    if (role_ == Role::slaves) real.port = local_port_;
    return real.canonical();
  }
  std::string describe() const {
    return spec() + " (" + Traits::role_name(role_) + ", local port " + std::to_string(local_port_) + ")";
  }
  Stats stats() const { return stats_; }
  std::uint16_t local_port() const { return local_port_; }  // the port this socket is bound to
  // Not marked override, like every member here: each bus's interface declares a different
  // set of them virtual (spec() and last_age_ns() only M-III's), so `override` cannot be
  // written on all, and clang warns when only some carry it.
  void set_refuse_foreign_senders(bool refuse) { gate_.set_refuse(refuse); }
  void set_master_handover(std::int64_t silent_ns) { gate_.set_handover(silent_ns); }

 private:
  // Fills peer_ from spec_; returns the address family.
  int resolve() {
    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_DGRAM;
    hints.ai_flags = AI_NUMERICSERV | (role_ == Role::slaves ? AI_PASSIVE : 0);
    addrinfo* res = nullptr;
    const std::string port = std::to_string(spec_.port);
    if (const int rc = ::getaddrinfo(spec_.name.c_str(), port.c_str(), &hints, &res); rc != 0 || !res)
      throw Error(spec_.canonical() + ": cannot resolve host '" + spec_.name + "': " + ::gai_strerror(rc));
    const int family = res->ai_family;
    std::memcpy(&peer_, res->ai_addr, res->ai_addrlen);
    peer_len_ = res->ai_addrlen;
    ::freeaddrinfo(res);
    return family;
  }
  // slaves: HOST:PORT; master: an ephemeral port.
  void bind_socket(int family) {
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
  void remember_sender(const sockaddr_storage& from, socklen_t len) {
    std::memcpy(&peer_, &from, len);
    peer_len_ = len;
    have_peer_ = true;
  }
  // Closes fd_ and throws naming the spec.
  [[noreturn]] void fail(const std::string& what) {
    const std::string m = spec_.canonical() + ": " + what + ": " + std::strerror(errno);
    ::close(fd_);
    fd_ = -1;
    throw Error(m);
  }

  FrameTransportSpec spec_;
  Role role_;
  int fd_ = -1;
  sockaddr_storage peer_{};  // master: HOST:PORT; slaves: the last sender
  socklen_t peer_len_ = 0;
  bool have_peer_ = false;
  SenderGate gate_;  // slaves: the first sender is the master
  std::uint16_t local_port_ = 0;
  Stats stats_;
  ReceiveStamp stamp_;
  std::int64_t last_age_ns_ = -1;
};

}  // namespace omnitwin::bus_emulators
