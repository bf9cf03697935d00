// bus_emulators/ethercat/transport — EtherCAT on raw Ethernet; see ec_transport_raw.hpp.
#include "bus_emulators/ethercat/transport/ec_transport_raw.hpp"

#include "bus_emulators/raw_ethernet.hpp"

#include <arpa/inet.h>
#include <linux/filter.h>
#include <net/if_arp.h>
#include <linux/if_packet.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fmt/format.h>

namespace omnitwin::ethercat {

namespace {

#ifndef PACKET_QDISC_BYPASS
#define PACKET_QDISC_BYPASS 20  // Linux >= 3.14
#endif
#ifndef PACKET_IGNORE_OUTGOING
#define PACKET_IGNORE_OUTGOING 23  // Linux >= 4.20
#endif

constexpr Mac kBroadcast = {0xff, 0xff, 0xff, 0xff, 0xff, 0xff};

}  // namespace

RawTransport::RawTransport(const std::string& ifname, Role role, RawOptions options) : ifname_(ifname), role_(role) {
  const std::string spec = "raw:" + ifname_;
  bus_emulators::RawSocket sock = bus_emulators::open_raw_socket<TransportError>(ifname_, spec);
  fd_ = sock.fd, ifindex_ = sock.ifindex, mac_ = sock.mac;
  write_eth_header(tx_hdr_.data(), kBroadcast, mac_);

  // Best effort, each: the checks in receive() cover what the kernel does not do.
  const int one = 1;
  ::setsockopt(fd_, SOL_PACKET, PACKET_IGNORE_OUTGOING, &one, sizeof one);
  if (options.qdisc_bypass)
    qdisc_bypass_ = ::setsockopt(fd_, SOL_PACKET, PACKET_QDISC_BYPASS, &one, sizeof one) == 0;
  // Keep: incoming frames (not OUTGOING) with EtherType 0x88A4. The EtherCAT header type is
  // checked in receive(), so frames of another type (network variables, mailbox gateway) are
  // counted in dropped_foreign rather than vanishing in the kernel.
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

  bus_emulators::bind_raw_socket<TransportError>(sock, kEtherType, spec);
}

RawTransport::~RawTransport() {
  if (fd_ >= 0) ::close(fd_);
}

std::string RawTransport::describe() const {
  return fmt::format("raw:{} ({}, {})", ifname_, to_string(role_), bus_emulators::mac_text(mac_));
}

bool RawTransport::send(std::span<const std::uint8_t> pdu) {
  if (pdu.size() > kMaxPdu || (role_ == Role::slaves && !have_peer_)) {
    ++stats_.send_errors;
    return false;
  }
  const std::uint8_t* hdr = role_ == Role::master ? tx_hdr_.data() : reply_hdr_.data();
  if (bus_emulators::send_padded(fd_, hdr, pdu)) {
    ++stats_.sent;
    return true;
  }
  ++stats_.send_errors;  // ENETDOWN, ENOBUFS (driver queue full), ENXIO (interface gone), …
  return false;
}

int RawTransport::receive(std::span<std::uint8_t> buf, std::chrono::nanoseconds timeout) {
  detail::ReadableWaiter waiter(timeout);
  // Bounded, so that a flood of frames we drop cannot hold the caller; fd stays readable then.
  for (int budget = 256; budget > 0;) {
    sockaddr_ll from{};
    iovec iov[2] = {{rx_hdr_.data(), rx_hdr_.size()}, {buf.data(), buf.size()}};
    msghdr msg{};
    msg.msg_name = &from;
    msg.msg_namelen = sizeof from;
    msg.msg_iov = iov;
    msg.msg_iovlen = 2;
    // The frame's real length even when buf is smaller.
    const long n = waiter.receive(fd_, msg);
    if (n == detail::ReadableWaiter::kTimedOut) return 0;
    if (n < 0) {
      ++stats_.receive_errors;
      return -1;
    }
    --budget;
    if (from.sll_pkttype == PACKET_OUTGOING) {
      ++stats_.dropped_own;
      continue;
    }
    if (static_cast<std::size_t>(n) < kEthHeaderSize) {
      ++stats_.dropped_malformed;
      continue;
    }
    if (((rx_hdr_[12] << 8) | rx_hdr_[13]) != kEtherType) {
      ++stats_.dropped_foreign;
      continue;
    }
    const std::size_t got = std::min(static_cast<std::size_t>(n) - kEthHeaderSize, buf.size());
    std::size_t size = 0;
    switch (check_pdu(buf.data(), got, size)) {
      case PduCheck::ok: break;
      case PduCheck::foreign: ++stats_.dropped_foreign; continue;
      case PduCheck::malformed: ++stats_.dropped_malformed; continue;
    }
    if (role_ == Role::slaves) {
      // The first source MAC is the master's; another one is a foreign sender.
      if (!gate_.admit(std::span<const std::uint8_t>(rx_hdr_.data() + 6, 6), 0, stats_.foreign_sender, stats_.refused_sender))
        continue;
      reply_hdr_ = rx_hdr_;
      reply_hdr_[6] |= 0x02;  // bit 1 of the first source-MAC byte: "passed a slave"
      have_peer_ = true;
    }
    last_hdr_ = rx_hdr_;
    ++stats_.received;
    return static_cast<int>(size);
  }
  return 0;
}

}  // namespace omnitwin::ethercat
