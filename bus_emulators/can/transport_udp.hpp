// bus_emulators/can — CAN over UDP multicast, wire-compatible with python-can's
// `udp_multicast` interface (one msgpack map per datagram; see can_msgpack.hpp).
//
// Like python-can it sends to GROUP:PORT with TTL / hop limit 1 (configurable), multicast
// loopback on, and joins GROUP on the kernel's default interface (or iface=NAME). Unlike
// python-can, which binds ("", PORT) and so hears every group on that port, the receive
// socket is bound to GROUP:PORT and has IP(V6)_MULTICAST_ALL off: it hears only its group.
// Sends go out from a second, unbound socket so that our own datagrams can be told apart
// (source = a local address and that socket's port) and dropped unless own=1: in the kernel
// already, by a socket filter on the receive socket (so they cost no wake-up, no queueing and
// no receive call), and again here (should the filter be refused).
//
// receive() fetches up to kRxBatch datagrams per system call (recvmmsg) and hands them out
// one by one: poll_fd() does not see datagrams already fetched, so a caller must call
// receive() until it returns nothing before it waits on poll_fd() (as every caller does).
//
// send_many() encodes the frames exactly as send() does and hands each run of equal-size
// datagrams (optionally ended by one shorter one) to the kernel in one UDP_SEGMENT (GSO)
// send: the kernel cuts it into the very same datagrams (local receivers and the network see
// no difference; python-can included), but the network device is kicked once per run instead
// of once per datagram, which is most of a datagram's cost on a virtual NIC. Where the kernel
// or the device refuses segmentation, it falls back to one send per datagram for good.
//
// The receive socket asks for a receive buffer of kRxBufferBytes (SO_RCVBUFFORCE where the
// process may, else SO_RCVBUF, which the kernel caps at net.core.rmem_max): the default
// (212992 bytes, about 275 datagrams) overflowed under a lockstep tick's burst. What the
// kernel still drops because the buffer was full shows in the host's UDP RcvbufErrors
// (udp_receive_buffer_errors(); the socket's own drop count also counts the own-datagram filter).
#pragma once

#include "bus_emulators/can/can_msgpack.hpp"
#include "bus_emulators/can/transport.hpp"

#include <sys/socket.h>

#include <array>
#include <cstdint>
#include <span>
#include <vector>

namespace omnitwin::can {

class UdpTransport final : public Transport {
 public:
  explicit UdpTransport(const TransportSpec& spec);  // throws TransportError
  ~UdpTransport() override;

  bool send(const Frame& f, std::int64_t timestamp_ns = 0) override;
  std::size_t send_many(std::span<const TimedFrame> frames) override;
  std::optional<TimedFrame> receive() override;
  int poll_fd() const override { return rx_fd_; }
  TransportStats stats() const override { return stats_; }
  std::string spec() const override;

  // Sends raw bytes to the group (tests use it to inject malformed datagrams).
  bool send_raw(const std::uint8_t* data, std::size_t size);

  // True when the kernel drops our own datagrams before they reach the receive socket
  // (never with own=1); false when it refused the filter (they are then dropped here).
  bool kernel_drops_own() const { return kernel_filter_; }
  // True while send_many() still uses segmented sends (false after the kernel refused one).
  bool segmented_sends() const { return gso_ok_; }

 private:
  // Back-pressure on send: up to kSendRetries waits of kSendWaitMs for socket-buffer room.
  static constexpr int kSendRetries = 20;
  static constexpr int kSendWaitMs = 5;
  // Most datagrams one segmented send carries (the kernel's UDP_MAX_SEGMENTS is 64 or more).
  static constexpr std::size_t kMaxSegments = 64;
  // The receive buffer asked for [bytes] (best effort; the kernel doubles what it grants).
  static constexpr int kRxBufferBytes = 4 << 20;
  // Datagrams one receive call (recvmmsg) fetches; receive() hands them out one by one.
  static constexpr std::size_t kRxBatch = 16;
  static constexpr std::size_t kRxSlot = msgpack_wire::kMaxDatagramSize + 1;  // one byte more than
                                        // python-can reads, so an oversized datagram shows as truncated
  bool refill();  // one recvmmsg into the batch; false when nothing came (or an error)
  bool is_own(const sockaddr_storage& from) const;
  void take_bound_port();
  void attach_own_filter();
  // Waits (bounded) for send-buffer room after EAGAIN/ENOBUFS; false when the waits are spent.
  bool wait_for_room(int& waits);
  // One run of `count` datagrams of `seg` bytes (the last may be shorter), `size` bytes in all.
  std::size_t send_run(const std::uint8_t* data, std::size_t size, std::size_t seg, std::size_t count);

  TransportSpec spec_;
  int rx_fd_ = -1;
  int tx_fd_ = -1;
  sockaddr_storage group_{};
  socklen_t group_len_ = 0;
  std::uint16_t tx_port_ = 0;                    // network order
  std::vector<sockaddr_storage> local_addrs_;    // for own-datagram detection
  bool kernel_filter_ = false;
  bool gso_ok_ = true;
  std::vector<std::uint8_t> tx_buf_;             // send_many(): one run, encoded
  std::vector<std::uint8_t> rx_buf_;             // kRxBatch slots of kRxSlot bytes
  std::array<mmsghdr, kRxBatch> rx_msgs_{};
  std::array<iovec, kRxBatch> rx_iov_{};
  std::array<sockaddr_storage, kRxBatch> rx_from_{};
  std::size_t rx_next_ = 0;   // next datagram of the batch to hand out
  std::size_t rx_count_ = 0;  // datagrams in the batch
  TransportStats stats_;
};

}  // namespace omnitwin::can
