// bus_emulators/can — CAN over UDP multicast, wire-compatible with python-can's
// `udp_multicast` interface (one msgpack map per datagram; see can_msgpack.hpp).
//
// Like python-can it sends to GROUP:PORT with TTL / hop limit 1 (configurable), multicast
// loopback on, and joins GROUP on the kernel's default interface (or iface=NAME). Unlike
// python-can, which binds ("", PORT) and so hears every group on that port, the receive
// socket is bound to GROUP:PORT and has IP(V6)_MULTICAST_ALL off: it hears only its group.
// Sends go out from a second, unbound socket so that our own datagrams can be told apart
// (source = a local address and that socket's port) and dropped unless own=1.
#pragma once

#include "bus_emulators/can/transport.hpp"

#include <sys/socket.h>

#include <cstdint>
#include <vector>

namespace omnitwin::can {

class UdpTransport final : public Transport {
 public:
  explicit UdpTransport(const TransportSpec& spec);  // throws TransportError
  ~UdpTransport() override;

  bool send(const Frame& f, std::int64_t timestamp_ns = 0) override;
  std::optional<TimedFrame> receive() override;
  int poll_fd() const override { return rx_fd_; }
  TransportStats stats() const override { return stats_; }
  std::string spec() const override;

  // Sends raw bytes to the group (tests use it to inject malformed datagrams).
  bool send_raw(const std::uint8_t* data, std::size_t size);

 private:
  // Back-pressure on send: up to kSendRetries waits of kSendWaitMs for socket-buffer room.
  static constexpr int kSendRetries = 20;
  static constexpr int kSendWaitMs = 5;
  bool is_own(const sockaddr_storage& from) const;

  TransportSpec spec_;
  int rx_fd_ = -1;
  int tx_fd_ = -1;
  sockaddr_storage group_{};
  socklen_t group_len_ = 0;
  std::uint16_t tx_port_ = 0;                    // network order
  std::vector<sockaddr_storage> local_addrs_;    // for own-datagram detection
  TransportStats stats_;
};

}  // namespace omnitwin::can
