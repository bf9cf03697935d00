// bus_emulators/mechatrolink3/transport — MECHATROLINK-III transports: thin adapters that move
// M-III frames (header, information field, FCS; see m3_frame.hpp) between our C1 master and
// the emulated slaves. Shaped like the EtherCAT transports (ethercat/transport/ec_transport.hpp):
// same roles, spec spelling, counters and real-time rules, so the twin drives both alike.
//
// A transport is opened from a spec string and a role:
//   raw:IFACE            AF_PACKET raw socket on an Ethernet interface (veth, NIC): the Ethernet
//                        encapsulation of docs/protocols/mechatrolink3.md (station MACs,
//                        EtherType 0x88B5, zero padding to 60 bytes).
//   udp:HOST[:PORT]      one frame per datagram, no padding (port 0x88B5 = 34997 by default;
//   udp:[HOST6][:PORT]   0 on the slaves' side: a free port chosen at open, which spec() names).
//                        Slaves bind HOST:PORT and answer the sender of the last frame; the
//                        master binds an ephemeral port and sends to HOST:PORT.
//   mem:NAME             in-process pair (one master, one slaves end) for tests.
//
// The roles are the two ends of the line: the master sends commands and receives responses;
// the slaves end (every emulated station) receives the master's frames and sends responses. A
// transport carries no protocol. It does not check the FCS, the addresses, the frame type or
// whether the data length suits the type: the receiving station does (as the ASIC would), so
// a frame corrupted on the way reaches it and is counted there. A transport rejects only what
// cannot be a frame at all, so that the stations behind it never see it:
//   - not M-III: raw Ethernet frames of another EtherType → dropped_foreign (raw only: a UDP
//     datagram or an in-process message has no other kind);
//   - malformed: fewer bytes than a header and FCS (9), a data length over 64 or beyond the
//     bytes received, more bytes than the caller's buffer, or (raw) bytes after the frame
//     beyond the 64-byte Ethernet minimum and FCS → dropped_malformed.
// A frame handed out by receive() is exactly header + data length + FCS (Ethernet padding and
// any trailing bytes removed), so m3::decode() of receive()'s bytes sees the frame itself.
//
// Threads: one thread uses a transport at a time; the in-process hub itself is thread-safe.
// Real-time: send() and receive() allocate nothing, never throw and make at most a bounded
// number of system calls (receive() waits on fd() with the caller's timeout); opening,
// spec() and describe() allocate and may throw.
#pragma once

#include "bus_emulators/mechatrolink3/m3_frame.hpp"

#include <sys/socket.h>

#include "bus_emulators/readable_waiter.hpp"
#include "bus_emulators/transport_spec.hpp"

#include <chrono>
#include <cstdint>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>

namespace omnitwin::m3 {

enum class Role : std::uint8_t { master, slaves };
const char* to_string(Role r);

// The fewest bytes a frame has: header and FCS (no information field).
inline constexpr std::size_t kMinFrame = kHeaderSize + kFcsSize;

class M3Transport {
 public:
  virtual ~M3Transport() = default;
  M3Transport() = default;
  M3Transport(const M3Transport&) = delete;
  M3Transport& operator=(const M3Transport&) = delete;

  // One frame to the other end, as given (a bad FCS included). raw: the Ethernet frame with
  // the station MACs of the frame's destination and source bytes, padded to 60; udp: master to
  // HOST:PORT, slaves to the sender of the last frame received (false while nothing was
  // received yet). Refuses fewer than kMinFrame or more than kMaxFrame (73) bytes. Never
  // blocks, never throws. false (counted in send_errors) on error.
  virtual bool send(std::span<const std::uint8_t> frame) = 0;
  // One frame into buf (Ethernet header and padding stripped; own outgoing frames, frames
  // that are not M-III and malformed ones skipped and counted), waiting up to timeout (0 = do
  // not wait). Returns its size, 0 on timeout, -1 on a system error (counted in
  // receive_errors). Never throws.
  virtual int receive(std::span<std::uint8_t> buf, std::chrono::nanoseconds timeout) = 0;
  // How long before receive() returned it the last frame had arrived [ns], from the kernel's
  // receive time stamp (raw, udp); -1 where unknown (mem: handed over directly). Real-time safe.
  virtual std::int64_t last_age_ns() const { return -1; }
  // A descriptor that polls readable (POLLIN) while a frame may be waiting, for event loops.
  virtual int fd() const = 0;
  // The canonical spec as opened, with the real port where one was chosen at open
  // ("udp:127.0.0.1:40123" for "udp:127.0.0.1:0"): what the other end is given.
  virtual std::string spec() const = 0;
  // spec() and the role, e.g. "raw:eth1 (master, 00:1b:21:0a:0b:0c)".
  virtual std::string describe() const = 0;

  struct Stats {
    std::uint64_t sent = 0;               // frames handed to the OS / the peer
    std::uint64_t received = 0;           // frames handed to the caller
    std::uint64_t dropped_foreign = 0;    // raw: another EtherType seen in user space (most are
                                          // dropped earlier by the kernel filter, uncounted)
    std::uint64_t dropped_malformed = 0;  // cannot be a frame (see above)
    std::uint64_t dropped_own = 0;        // our own outgoing frames seen in user space (raw)
    std::uint64_t dropped_overflow = 0;   // mem: the receiving queue was full
    std::uint64_t send_errors = 0;        // refused by the OS, bad size, slaves with no peer yet
    std::uint64_t receive_errors = 0;     // the OS reported a receive error
    std::uint64_t foreign_sender = 0;     // slaves: frames from a sender other than the first (the master)
    std::uint64_t refused_sender = 0;     // … of which refused (set_refuse_foreign_senders)
    std::uint64_t master_changes = 0;     // slaves: senders taken for the master from a silent one
  };
  virtual Stats stats() const = 0;
  // slaves: see EcTransport::set_refuse_foreign_senders.
  virtual void set_refuse_foreign_senders(bool /*refuse*/) {}
  // slaves: see EcTransport::set_master_handover.
  virtual void set_master_handover(std::int64_t /*silent_ns*/) {}
};

// Set-up errors: a bad spec, a missing interface or privilege, a port in use. The message names
// the spec.
class TransportError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Parsed form of a spec, exposed for tests and argument checking (shared by the frame buses).
using TransportSpec = bus_emulators::FrameTransportSpec;
TransportSpec parse_transport_spec(std::string_view spec);  // throws TransportError

// "raw:IFACE", "udp:HOST[:PORT]", "mem:NAME"; throws TransportError naming the spec.
std::unique_ptr<M3Transport> open_transport(std::string_view spec, Role role);

// What a receiving transport does with `n` bytes that claim to be a frame.
enum class FrameCheck : std::uint8_t { ok, malformed };
// The framing of m3::decode_prefix() without its FCS and field checks (those are the
// receiving station's): ok when n holds a header, a data length ≤ 64 and that many bytes and
// the FCS; then `size` = header + data length + FCS (≤ n). RT-safe.
FrameCheck check_frame(const std::uint8_t* data, std::size_t n, std::size_t& size) noexcept;

namespace detail {
// The waiting part of receive(), shared by every bus's transports (bus_emulators/readable_waiter.hpp).
using ReadableWaiter = bus_emulators::ReadableWaiter;
using ReceiveStamp = bus_emulators::ReceiveStamp;
}  // namespace detail

}  // namespace omnitwin::m3
