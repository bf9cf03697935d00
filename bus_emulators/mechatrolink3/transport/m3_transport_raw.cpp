// bus_emulators/mechatrolink3/transport — M-III on raw Ethernet; see m3_transport_raw.hpp.
#include "bus_emulators/mechatrolink3/transport/m3_transport_raw.hpp"

#include <arpa/inet.h>
#include <linux/filter.h>
#include <linux/if_ether.h>
#include <linux/if_packet.h>
#include <net/if.h>
#include <net/if_arp.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fmt/format.h>

namespace omnitwin::m3 {

namespace {

#ifndef PACKET_QDISC_BYPASS
#define PACKET_QDISC_BYPASS 20  // Linux >= 3.14
#endif
#ifndef PACKET_IGNORE_OUTGOING
#define PACKET_IGNORE_OUTGOING 23  // Linux >= 4.20
#endif

constexpr std::uint8_t kZeros[kMinEthFrame] = {};

std::string mac_text(const Mac& m) {
  return fmt::format("{:02x}:{:02x}:{:02x}:{:02x}:{:02x}:{:02x}", m[0], m[1], m[2], m[3], m[4], m[5]);
}

// The Ethernet header m3::encapsulate() writes for a frame starting with these address bytes.
void write_eth_header(std::uint8_t* h, std::uint8_t dst, std::uint8_t src) {
  const Mac d = station_mac(dst), s = station_mac(src);
  std::memcpy(h, d.data(), d.size());
  std::memcpy(h + 6, s.data(), s.size());
  h[12] = static_cast<std::uint8_t>(kEtherType >> 8);
  h[13] = static_cast<std::uint8_t>(kEtherType & 0xFF);
}

}  // namespace

RawTransport::RawTransport(const std::string& ifname, Role role, RawOptions options) : ifname_(ifname), role_(role) {
  if (ifname_.empty() || ifname_.size() >= IFNAMSIZ)
    throw TransportError(spec() + ": bad interface name (1 to 15 characters)");
  open_socket();
  set_options(options);
  detail::ReceiveStamp::enable(fd_);  // best effort: without it last_age_ns() says -1
  if (options.kernel_filter) attach_filter();
  bind_interface(options.kernel_filter ? kEtherType : ETH_P_ALL);
}

RawTransport::~RawTransport() {
  if (fd_ >= 0) ::close(fd_);
}

void RawTransport::fail(const std::string& what) {
  const std::string m = fmt::format("{}: {}: {}", spec(), what, std::strerror(errno));
  ::close(fd_);
  fd_ = -1;
  throw TransportError(m);
}

void RawTransport::open_socket() {
  // Protocol 0 until bind(): the socket receives nothing before it is bound to the interface.
  fd_ = ::socket(AF_PACKET, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd_ < 0) {
    if (errno == EPERM || errno == EACCES)
      throw TransportError(fmt::format("{}: opening a raw AF_PACKET socket needs root or CAP_NET_RAW ({})", spec(),
                                       std::strerror(errno)));
    throw TransportError(fmt::format("{}: socket(AF_PACKET, SOCK_RAW): {}", spec(), std::strerror(errno)));
  }
  ifreq ifr{};
  std::memcpy(ifr.ifr_name, ifname_.c_str(), ifname_.size());
  if (::ioctl(fd_, SIOCGIFINDEX, &ifr) != 0) fail("no network interface '" + ifname_ + "'");
  ifindex_ = ifr.ifr_ifindex;
  if (::ioctl(fd_, SIOCGIFHWADDR, &ifr) != 0) fail("SIOCGIFHWADDR");
  if (ifr.ifr_hwaddr.sa_family != ARPHRD_ETHER) {
    errno = EINVAL;
    fail("'" + ifname_ + "' is not an Ethernet interface (use a veth pair or a NIC)");
  }
  std::memcpy(mac_.data(), ifr.ifr_hwaddr.sa_data, mac_.size());
}

void RawTransport::set_options(const RawOptions& options) {
  // Best effort, each: the checks in receive() cover what the kernel does not do.
  const int one = 1;
  ::setsockopt(fd_, SOL_PACKET, PACKET_IGNORE_OUTGOING, &one, sizeof one);
  if (options.qdisc_bypass)
    qdisc_bypass_ = ::setsockopt(fd_, SOL_PACKET, PACKET_QDISC_BYPASS, &one, sizeof one) == 0;
  // Frames to station MACs pass a NIC's address filter only in promiscuous mode; the kernel
  // undoes it when the socket closes.
  packet_mreq mr{};
  mr.mr_ifindex = ifindex_;
  mr.mr_type = PACKET_MR_PROMISC;
  promiscuous_ = ::setsockopt(fd_, SOL_PACKET, PACKET_ADD_MEMBERSHIP, &mr, sizeof mr) == 0;
}

void RawTransport::attach_filter() {
  // Keep: incoming frames (not OUTGOING) with EtherType 0x88B5. Whether the bytes after the
  // header can be a frame is checked in receive() (and counted).
  sock_filter prog[] = {
      BPF_STMT(BPF_LD | BPF_W | BPF_ABS, static_cast<std::uint32_t>(SKF_AD_OFF + SKF_AD_PKTTYPE)),  // 0
      BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, PACKET_OUTGOING, 3, 0),                                    // 1 → 5
      BPF_STMT(BPF_LD | BPF_H | BPF_ABS, 12),                                                        // 2
      BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, kEtherType, 0, 1),                                         // 3 → 5
      BPF_STMT(BPF_RET | BPF_K, 0xFFFFFFFFu),                                                        // 4 keep
      BPF_STMT(BPF_RET | BPF_K, 0),                                                                  // 5 drop
  };
  sock_fprog fp{static_cast<unsigned short>(sizeof prog / sizeof prog[0]), prog};
  kernel_filter_ = ::setsockopt(fd_, SOL_SOCKET, SO_ATTACH_FILTER, &fp, sizeof fp) == 0;
}

void RawTransport::bind_interface(std::uint16_t protocol) {
  sockaddr_ll sll{};
  sll.sll_family = AF_PACKET;
  sll.sll_protocol = htons(protocol);
  sll.sll_ifindex = ifindex_;
  if (::bind(fd_, reinterpret_cast<sockaddr*>(&sll), sizeof sll) != 0) fail("bind");
}

std::string RawTransport::describe() const {
  return fmt::format("{} ({}, {})", spec(), to_string(role_), mac_text(mac_));
}

bool RawTransport::send(std::span<const std::uint8_t> frame) {
  if (frame.size() < kMinFrame || frame.size() > kMaxFrame) {
    ++stats_.send_errors;
    return false;
  }
  write_eth_header(tx_hdr_.data(), frame[0], frame[1]);
  const std::size_t used = kEthHeaderSize + frame.size();
  const std::size_t pad = used < kMinEthFrame ? kMinEthFrame - used : 0;
  iovec iov[3] = {{tx_hdr_.data(), kEthHeaderSize},
                  {const_cast<std::uint8_t*>(frame.data()), frame.size()},
                  {const_cast<std::uint8_t*>(kZeros), pad}};
  msghdr msg{};
  msg.msg_iov = iov;
  msg.msg_iovlen = pad > 0 ? 3 : 2;
  for (;;) {
    const ssize_t n = ::sendmsg(fd_, &msg, MSG_DONTWAIT | MSG_NOSIGNAL);
    if (n == static_cast<ssize_t>(used + pad)) {
      ++stats_.sent;
      return true;
    }
    if (n < 0 && errno == EINTR) continue;
    ++stats_.send_errors;  // ENETDOWN, ENOBUFS (driver queue full), ENXIO (interface gone), …
    return false;
  }
}

std::uint64_t* RawTransport::drop_reason(unsigned pkttype, std::size_t n, std::span<const std::uint8_t> buf,
                                         std::size_t& size) {
  if (pkttype == PACKET_OUTGOING) return &stats_.dropped_own;
  if (n < kEthHeaderSize) return &stats_.dropped_malformed;
  if (((rx_hdr_[12] << 8) | rx_hdr_[13]) != kEtherType) return &stats_.dropped_foreign;
  const std::size_t payload = n - kEthHeaderSize;
  if (check_frame(buf.data(), std::min(payload, buf.size()), size) != FrameCheck::ok) return &stats_.dropped_malformed;
  // After the frame only the padding to the Ethernet minimum (and an Ethernet FCS) may follow,
  // as m3::decapsulate() has it.
  if (payload > size && n > kMinEthFrame + 4) return &stats_.dropped_malformed;
  return nullptr;
}

int RawTransport::receive(std::span<std::uint8_t> buf, std::chrono::nanoseconds timeout) {
  detail::ReadableWaiter waiter(timeout);
  // Bounded, so that a flood of frames we drop cannot hold the caller; fd stays readable then.
  for (int budget = 256; budget > 0; --budget) {
    sockaddr_ll from{};
    iovec iov[2] = {{rx_hdr_.data(), rx_hdr_.size()}, {buf.data(), buf.size()}};
    msghdr msg{};
    msg.msg_name = &from;
    msg.msg_namelen = sizeof from;
    msg.msg_iov = iov;
    msg.msg_iovlen = 2;
    stamp_.attach(msg);
    const long n = waiter.receive(fd_, msg);  // the frame's real length even when buf is smaller
    if (n == detail::ReadableWaiter::kTimedOut) return 0;
    if (n < 0) {
      ++stats_.receive_errors;
      return -1;
    }
    std::size_t size = 0;
    if (std::uint64_t* counter = drop_reason(from.sll_pkttype, static_cast<std::size_t>(n), buf, size)) {
      ++*counter;
      continue;
    }
    ++stats_.received;
    last_age_ns_ = detail::ReceiveStamp::age_ns(msg);
    return static_cast<int>(size);
  }
  return 0;
}

}  // namespace omnitwin::m3
