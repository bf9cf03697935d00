// bus_emulators/mechatrolink3/transport — M-III on raw Ethernet; see m3_transport_raw.hpp.
#include "bus_emulators/mechatrolink3/transport/m3_transport_raw.hpp"

#include "bus_emulators/raw_ethernet.hpp"

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
  bus_emulators::RawSocket sock = bus_emulators::open_raw_socket<TransportError>(ifname_, spec());
  fd_ = sock.fd, ifindex_ = sock.ifindex, mac_ = sock.mac;
  set_options(options);
  detail::ReceiveStamp::enable(fd_);  // best effort: without it last_age_ns() says -1
  if (options.kernel_filter) attach_filter();
  bus_emulators::bind_raw_socket<TransportError>(sock, options.kernel_filter ? kEtherType : ETH_P_ALL, spec());
}

RawTransport::~RawTransport() {
  if (fd_ >= 0) ::close(fd_);
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

std::string RawTransport::describe() const {
  return fmt::format("{} ({}, {})", spec(), to_string(role_), bus_emulators::mac_text(mac_));
}

bool RawTransport::send(std::span<const std::uint8_t> frame) {
  if (frame.size() < kMinFrame || frame.size() > kMaxFrame) {
    ++stats_.send_errors;
    return false;
  }
  write_eth_header(tx_hdr_.data(), frame[0], frame[1]);
  if (bus_emulators::send_padded(fd_, tx_hdr_.data(), frame)) {
    ++stats_.sent;
    return true;
  }
  ++stats_.send_errors;  // ENETDOWN, ENOBUFS (driver queue full), ENXIO (interface gone), …
  return false;
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
    // Slaves: the first source MAC is the master's; another one is a foreign sender.
    if (role_ == Role::slaves &&
        !gate_.admit(std::span<const std::uint8_t>(rx_hdr_.data() + 6, 6), 0, stats_.foreign_sender, stats_.refused_sender))
      continue;
    ++stats_.received;
    last_age_ns_ = detail::ReceiveStamp::age_ns(msg);
    return static_cast<int>(size);
  }
  return 0;
}

}  // namespace omnitwin::m3
