// bus_emulators/can — CAN over UDP multicast (python-can `udp_multicast`); see transport_udp.hpp.
#include "bus_emulators/can/transport_udp.hpp"

#include "bus_emulators/can/can_msgpack.hpp"

#include <arpa/inet.h>
#include <ifaddrs.h>
#include <linux/filter.h>
#include <net/if.h>
#include <netinet/in.h>
#include <netinet/udp.h>
#include <poll.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <fmt/format.h>

namespace omnitwin::can {

namespace {

#ifndef IPV6_MULTICAST_ALL
#define IPV6_MULTICAST_ALL 29  // Linux >= 4.20
#endif
#ifndef UDP_SEGMENT
#define UDP_SEGMENT 103  // Linux >= 4.18
#endif

[[noreturn]] void fail(const TransportSpec& s, const std::string& what) {
  throw TransportError(fmt::format("udp CAN transport {}:{}: {}: {}", s.name, s.port, what, std::strerror(errno)));
}

void set_opt(int fd, int level, int name, int value, const TransportSpec& s, const char* what) {
  if (::setsockopt(fd, level, name, &value, sizeof value) != 0) fail(s, what);
}

// A larger receive buffer: forced past net.core.rmem_max where permitted (CAP_NET_ADMIN),
// else as large as that limit allows. Best effort: the default still works for small bursts.
void raise_receive_buffer(int fd, int bytes) {
  if (::setsockopt(fd, SOL_SOCKET, SO_RCVBUFFORCE, &bytes, sizeof bytes) == 0) return;
  ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &bytes, sizeof bytes);
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
  raise_receive_buffer(rx_fd_, kRxBufferBytes);
  tx_fd_ = ::socket(family, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (tx_fd_ < 0) {
    ::close(rx_fd_);
    fail(spec_, "socket");
  }
  try {
    // Share the port (python-can does too). Port 0 asks for a port nobody holds: the bind
    // then happens without SO_REUSEADDR, so the kernel's choice cannot be a port another
    // socket shares, and the option is set afterwards so the peer can join it.
    const bool own_port = spec_.port == 0;
    if (!own_port) set_opt(rx_fd_, SOL_SOCKET, SO_REUSEADDR, 1, spec_, "SO_REUSEADDR");
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
      if (own_port) take_bound_port();
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
      if (own_port) take_bound_port();
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
    if (!spec_.receive_own) attach_own_filter();
    tx_buf_.resize(kMaxSegments * msgpack_wire::kMaxEncodedSize);
    rx_buf_.resize(kRxBatch * kRxSlot);
    for (std::size_t i = 0; i < kRxBatch; ++i) {
      rx_iov_[i] = iovec{rx_buf_.data() + i * kRxSlot, kRxSlot};
      rx_msgs_[i].msg_hdr.msg_iov = &rx_iov_[i];
      rx_msgs_[i].msg_hdr.msg_iovlen = 1;
      rx_msgs_[i].msg_hdr.msg_name = &rx_from_[i];
    }
  } catch (...) {
    ::close(rx_fd_);
    ::close(tx_fd_);
    throw;
  }
}

// A classic BPF program on the receive socket that drops datagrams from our own send socket
// (UDP source port = its port and IP source = one of this host's addresses, as is_own()), so
// the kernel neither queues them nor wakes us for them. A UDP socket's filter sees the packet
// from the UDP header on (offset 0 = source port); SKF_NET_OFF reaches the IP header. Best
// effort: without it (too many addresses for 8-bit jumps, or refused) is_own() still drops them.
// After a bind to port 0: the port the kernel chose becomes the group's port (the one sent
// to and named by spec()), and the receive socket is opened for sharing from now on.
void UdpTransport::take_bound_port() {
  sockaddr_storage bound{};
  socklen_t len = sizeof bound;
  if (::getsockname(rx_fd_, reinterpret_cast<sockaddr*>(&bound), &len) != 0) fail(spec_, "getsockname");
  const std::uint16_t port = spec_.ipv6 ? reinterpret_cast<sockaddr_in6&>(bound).sin6_port
                                        : reinterpret_cast<sockaddr_in&>(bound).sin_port;
  spec_.port = ntohs(port);
  if (spec_.ipv6)
    reinterpret_cast<sockaddr_in6&>(group_).sin6_port = port;
  else
    reinterpret_cast<sockaddr_in&>(group_).sin_port = port;
  set_opt(rx_fd_, SOL_SOCKET, SO_REUSEADDR, 1, spec_, "SO_REUSEADDR");
}

void UdpTransport::attach_own_filter() {
  std::vector<sock_filter> prog;
  const auto stmt = [&](std::uint16_t code, std::uint32_t k) { prog.push_back(BPF_STMT(code, k)); };
  const auto jump = [&](std::uint16_t code, std::uint32_t k, std::uint8_t jt, std::uint8_t jf) {
    prog.push_back(BPF_JUMP(code, k, jt, jf));
  };
  const bool v6 = spec_.ipv6;
  const std::size_t words = v6 ? 4 : 1;           // address words
  const std::size_t per_addr = 2 * words;          // load + compare per word
  const std::size_t n = local_addrs_.size();
  const std::size_t body = n * per_addr;           // instructions after the port check
  if (n == 0 || body + 2 > 250) return;            // jumps are 8 bits wide
  stmt(BPF_LD | BPF_H | BPF_ABS, 0);               // A = UDP source port
  jump(BPF_JMP | BPF_JEQ | BPF_K, ntohs(tx_port_), 0, static_cast<std::uint8_t>(body));  // other port: accept
  for (std::size_t a = 0; a < n; ++a) {
    std::uint32_t w[4] = {};
    if (v6) {
      std::memcpy(w, &reinterpret_cast<const sockaddr_in6&>(local_addrs_[a]).sin6_addr, sizeof w);
    } else {
      w[0] = reinterpret_cast<const sockaddr_in&>(local_addrs_[a]).sin_addr.s_addr;
    }
    const std::uint32_t src_off = v6 ? 8 : 12;     // IP source address in the IPv6 / IPv4 header
    for (std::size_t i = 0; i < words; ++i) {
      // Instructions after this compare up to the accept (the last of the body): a mismatch
      // skips the rest of this address; a full match jumps past accept, to drop.
      const std::size_t after = body - (a * per_addr + 2 * i + 2);
      const std::size_t next_addr = (words - 1 - i) * 2;
      stmt(BPF_LD | BPF_W | BPF_ABS, static_cast<std::uint32_t>(SKF_NET_OFF) + src_off + 4 * static_cast<std::uint32_t>(i));
      const bool last_word = i + 1 == words;
      jump(BPF_JMP | BPF_JEQ | BPF_K, ntohl(w[i]), last_word ? static_cast<std::uint8_t>(after + 1) : 0,
           static_cast<std::uint8_t>(next_addr));
    }
  }
  stmt(BPF_RET | BPF_K, 0xFFFFFFFFu);  // accept (whole datagram)
  stmt(BPF_RET | BPF_K, 0);            // drop
  sock_fprog fp{static_cast<unsigned short>(prog.size()), prog.data()};
  kernel_filter_ = ::setsockopt(rx_fd_, SOL_SOCKET, SO_ATTACH_FILTER, &fp, sizeof fp) == 0;
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

bool UdpTransport::wait_for_room(int& waits) {
  // A full socket buffer (EAGAIN/ENOBUFS: the kernel has not yet handed earlier datagrams to
  // the local receivers) is back-pressure, not loss: wait for room, a bounded time.
  if (!(errno == EAGAIN || errno == EWOULDBLOCK || errno == ENOBUFS) || waits >= kSendRetries) return false;
  ++waits;
  ++stats_.send_waits;
  pollfd p{tx_fd_, POLLOUT, 0};
  ::poll(&p, 1, kSendWaitMs);
  return true;
}

bool UdpTransport::send_raw(const std::uint8_t* data, std::size_t size) {
  int waits = 0;
  for (;;) {
    const ssize_t n = ::sendto(tx_fd_, data, size, MSG_DONTWAIT | MSG_NOSIGNAL,
                               reinterpret_cast<const sockaddr*>(&group_), group_len_);
    if (n == static_cast<ssize_t>(size)) return true;
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && wait_for_room(waits)) continue;
    ++stats_.send_errors;
    return false;
  }
}

std::size_t UdpTransport::send_run(const std::uint8_t* data, std::size_t size, std::size_t seg, std::size_t count) {
  if (count > 1 && gso_ok_) {
    // One send; the kernel cuts it every `seg` bytes into `count` datagrams.
    alignas(cmsghdr) char ctrl[CMSG_SPACE(sizeof(std::uint16_t))] = {};
    iovec iov{const_cast<std::uint8_t*>(data), size};
    msghdr msg{};
    msg.msg_name = &group_;
    msg.msg_namelen = group_len_;
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    msg.msg_control = ctrl;
    msg.msg_controllen = sizeof ctrl;
    cmsghdr* c = CMSG_FIRSTHDR(&msg);
    c->cmsg_level = SOL_UDP;
    c->cmsg_type = UDP_SEGMENT;
    c->cmsg_len = CMSG_LEN(sizeof(std::uint16_t));
    const auto seg16 = static_cast<std::uint16_t>(seg);
    std::memcpy(CMSG_DATA(c), &seg16, sizeof seg16);
    int waits = 0;
    for (;;) {
      const ssize_t n = ::sendmsg(tx_fd_, &msg, MSG_DONTWAIT | MSG_NOSIGNAL);
      if (n == static_cast<ssize_t>(size)) {
        stats_.frames_tx += count;
        return count;
      }
      if (n < 0 && errno == EINTR) continue;
      if (n < 0 && wait_for_room(waits)) continue;
      // Segmentation refused (old kernel, no checksum offload on the device, …): never again.
      // Any other error: this run one datagram at a time, so each failure counts as send()'s.
      if (n < 0 && (errno == EIO || errno == EINVAL || errno == ENOPROTOOPT || errno == EOPNOTSUPP ||
                    errno == EMSGSIZE))
        gso_ok_ = false;
      break;
    }
  }
  std::size_t sent = 0;
  for (std::size_t i = 0; i < count; ++i) {
    const std::size_t len = i + 1 < count ? seg : size - seg * (count - 1);
    if (send_raw(data + i * seg, len)) {
      ++stats_.frames_tx;
      ++sent;
    }
  }
  return sent;
}

std::size_t UdpTransport::send_many(std::span<const TimedFrame> frames) {
  // Runs of equal-size datagrams, each optionally closed by one shorter datagram (the kernel
  // allows the last segment to be short), in the frames' order.
  std::size_t sent = 0;
  std::size_t i = 0;
  while (i < frames.size()) {
    std::size_t used = 0, count = 0, seg = 0;
    while (i < frames.size() && count < kMaxSegments) {
      const TimedFrame& tf = frames[i];
      const std::size_t n = msgpack_wire::encode(tf.frame, static_cast<double>(tf.timestamp_ns) * 1e-9,
                                                 {tx_buf_.data() + used, msgpack_wire::kMaxEncodedSize});
      if (n == 0) {  // refused as send() refuses it
        ++stats_.invalid_tx;
        ++i;
        continue;
      }
      if (count > 0 && n > seg) break;  // starts the next run (encoded again there)
      if (count == 0) seg = n;
      used += n;
      ++count;
      ++i;
      if (n < seg) break;  // a shorter datagram closes the run
    }
    if (count > 0) sent += send_run(tx_buf_.data(), used, seg, count);
  }
  return sent;
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

namespace {
// A nonzero key for a datagram's source address and port: IPv4 exactly (address, port and
// bit 48), IPv6 as a 64-bit FNV-1a hash of address and port with bit 63 set.
std::uint64_t sender_key(const sockaddr_storage& from) {
  if (from.ss_family == AF_INET) {
    const auto& a = reinterpret_cast<const sockaddr_in&>(from);
    return (std::uint64_t{1} << 48) | (std::uint64_t{ntohl(a.sin_addr.s_addr)} << 16) | ntohs(a.sin_port);
  }
  const auto& a = reinterpret_cast<const sockaddr_in6&>(from);
  std::uint64_t h = 1469598103934665603ull;
  const auto mix = [&h](std::uint8_t b) { h = (h ^ b) * 1099511628211ull; };
  for (std::uint8_t b : a.sin6_addr.s6_addr) mix(b);
  mix(static_cast<std::uint8_t>(a.sin6_port & 0xff));
  mix(static_cast<std::uint8_t>(a.sin6_port >> 8));
  return h | (std::uint64_t{1} << 63);
}
}  // namespace

bool UdpTransport::is_own(const sockaddr_storage& from) const {
  const std::uint16_t port = from.ss_family == AF_INET6 ? reinterpret_cast<const sockaddr_in6&>(from).sin6_port
                                                        : reinterpret_cast<const sockaddr_in&>(from).sin_port;
  if (port != tx_port_) return false;
  for (const auto& a : local_addrs_)
    if (same_addr(a, from)) return true;
  return false;
}

bool UdpTransport::refill() {
  for (;;) {
    for (auto& m : rx_msgs_) {
      m.msg_hdr.msg_namelen = sizeof(sockaddr_storage);
      m.msg_hdr.msg_flags = 0;
      m.msg_len = 0;
    }
    const int n = ::recvmmsg(rx_fd_, rx_msgs_.data(), static_cast<unsigned>(kRxBatch), MSG_DONTWAIT, nullptr);
    if (n > 0) {
      rx_next_ = 0;
      rx_count_ = static_cast<std::size_t>(n);
      return true;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK) ++stats_.rx_errors;
    return false;
  }
}

std::optional<TimedFrame> UdpTransport::receive() {
  // Bounded, so that a flood of bad datagrams cannot hold the caller's loop; the descriptor
  // stays readable for the rest.
  for (int budget = 256; budget > 0; --budget) {
    if (rx_next_ == rx_count_ && !refill()) return std::nullopt;
    const std::size_t k = rx_next_++;
    const msghdr& msg = rx_msgs_[k].msg_hdr;
    const std::size_t n = rx_msgs_[k].msg_len;
    if (!spec_.receive_own && is_own(rx_from_[k])) continue;
    if ((msg.msg_flags & MSG_TRUNC) || n > msgpack_wire::kMaxDatagramSize) {
      ++stats_.malformed_rx;
      continue;
    }
    msgpack_wire::Decoded d;
    switch (msgpack_wire::decode({rx_buf_.data() + k * kRxSlot, n}, d)) {
      case msgpack_wire::DecodeStatus::ok: {
        ++stats_.frames_rx;
        const double ns = d.timestamp * 1e9;
        const std::int64_t ts = std::isfinite(ns) && std::fabs(ns) < 9.2e18 ? std::llround(ns) : 0;
        return TimedFrame{d.frame, ts, sender_key(rx_from_[k])};
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

namespace {
// RcvbufErrors from /proc/net/snmp's "Udp:" header/value line pair; -1 when absent.
std::int64_t snmp_udp_rcvbuf_errors() {
  std::ifstream f("/proc/net/snmp");
  std::string names, values;
  while (std::getline(f, names) && std::getline(f, values)) {
    if (!names.starts_with("Udp: ")) continue;
    std::istringstream n(names), v(values);
    for (std::string name, value; n >> name && v >> value;)
      if (name == "RcvbufErrors") return std::stoll(value);
  }
  return -1;
}
// Udp6RcvbufErrors from /proc/net/snmp6 ("NAME VALUE" lines); -1 when absent.
std::int64_t snmp6_udp_rcvbuf_errors() {
  std::ifstream f("/proc/net/snmp6");
  std::string name;
  std::int64_t value = 0;
  while (f >> name >> value)
    if (name == "Udp6RcvbufErrors") return value;
  return -1;
}
}  // namespace

std::int64_t udp_receive_buffer_errors() {
  const std::int64_t v4 = snmp_udp_rcvbuf_errors(), v6 = snmp6_udp_rcvbuf_errors();
  if (v4 < 0 && v6 < 0) return -1;
  return std::max<std::int64_t>(v4, 0) + std::max<std::int64_t>(v6, 0);
}

}  // namespace omnitwin::can
