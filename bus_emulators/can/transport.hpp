// bus_emulators/can — CAN transports: thin adapters that move Frames between processes.
//
// A transport is opened from a spec string:
//   socketcan:IFACE                  SocketCAN raw socket (vcan0, can0, …)
//   udp:GROUP[:PORT][?OPTIONS]       UDP multicast, wire-compatible with python-can's
//   udp:[GROUP6][:PORT][?OPTIONS]      `udp_multicast` interface (msgpack, see can_msgpack.hpp)
//                                    IPv4 group in 224.0.0.0/4, IPv6 group in ff00::/8 (in
//                                    brackets); PORT defaults to 43113 (0: a port of
//                                    its own, chosen at open; spec() names it). OPTIONS, '&'-separated:
//                                    ttl=N (IPv4 TTL / IPv6 hop limit, default 1 as python-can),
//                                    iface=NAME (interface to join and send on; default: the
//                                    kernel's choice, as python-can), own=1 (also receive the
//                                    frames this transport sent; default 0).
//   mem:NAME                         in-process bus shared by every transport opened with NAME
//
// Semantics shared by all transports: send() never throws and does not block, except that UDP
// waits (at most 100 ms) for room when the socket buffer is full — back-pressure from local
// receivers that have not yet been handed earlier datagrams, which must not become loss; receive() is
// non-blocking and returns the next good frame, counting and skipping bad input; poll_fd()
// becomes readable when receive() may have a frame, so a caller's event loop can wait on it
// once receive() has returned nothing (UDP fetches several datagrams per system call and hands
// them out one by one: those already fetched do not make poll_fd() readable).
// A transport does not deliver a frame back to the transport that sent it (as SocketCAN's
// default and a CAN controller's receive path), except UDP with own=1.
// One thread uses a transport at a time; the in-process hub itself is thread-safe.
#pragma once

#include "bus_emulators/can/can_frame.hpp"

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>

namespace omnitwin::can {

// Set-up errors: a bad spec, a missing interface, a socket that cannot be opened.
class TransportError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct TimedFrame {
  Frame frame;
  // Sender's timestamp in nanoseconds where the transport carries one (UDP: the msgpack
  // `timestamp` field, seconds on the wire; mem: as passed to send()); SocketCAN: the
  // kernel's receive time (CLOCK_REALTIME) when available, else 0.
  std::int64_t timestamp_ns = 0;
  // Who sent it, where the transport can tell (nonzero): UDP its source address and port,
  // mem the sending transport. 0 on SocketCAN: a CAN frame names no sender, and the kernel
  // does not say which socket sent it. Receivers count frames from other senders than the
  // one they expect (twin: bus.foreign_frames); set by receive(), ignored by send_many().
  std::uint64_t sender = 0;
};

struct TransportStats {
  std::uint64_t frames_tx = 0;
  std::uint64_t frames_rx = 0;
  std::uint64_t malformed_rx = 0;    // undecodable datagram / short or oversized read / unknown key
  std::uint64_t wrong_dlc_rx = 0;    // dlc > 8 or dlc != payload length
  std::uint64_t bad_id_rx = 0;       // identifier outside its format's range
  std::uint64_t unsupported_rx = 0;  // well-formed but not classic CAN (CAN FD) or bad flag combination
  std::uint64_t invalid_tx = 0;      // frames send() refused (identifier or DLC invalid)
  std::uint64_t send_errors = 0;     // the OS refused a send (network down, buffer full for 100 ms, …)
  std::uint64_t send_waits = 0;      // UDP: sends that waited for socket-buffer room (back-pressure)
  std::uint64_t rx_errors = 0;       // the OS reported a receive error
  std::uint64_t rx_dropped = 0;      // receive queue overflow: in-process (mem) or the kernel's socket buffer (UDP)
};

class Transport {
 public:
  virtual ~Transport() = default;
  Transport() = default;
  Transport(const Transport&) = delete;
  Transport& operator=(const Transport&) = delete;

  // Queues one frame for the bus. Returns false (and counts it) when the frame is invalid or
  // the OS refused it. Never blocks.
  virtual bool send(const Frame& f, std::int64_t timestamp_ns = 0) = 0;
  // Sends frames[0..n) in order, exactly as n calls of send() would (same datagrams, same
  // counters), but may hand several to the OS at once (UDP: one segmented send per run of
  // equal-size datagrams, which costs the kernel one network-device kick instead of one per
  // frame). Returns how many were accepted. Never blocks, except as send() does.
  virtual std::size_t send_many(std::span<const TimedFrame> frames);
  // The next good frame, or nothing when none is waiting. Never blocks.
  virtual std::optional<TimedFrame> receive() = 0;
  // A file descriptor that polls readable (POLLIN) while frames may be waiting.
  virtual int poll_fd() const = 0;
  virtual TransportStats stats() const = 0;
  // The canonical spec this transport was opened with (for logs).
  virtual std::string spec() const = 0;
};

// Opens a transport; throws TransportError with a clear message for a bad spec or when the
// socket / interface cannot be opened.
std::unique_ptr<Transport> open_transport(std::string_view spec);

// Waits until t.poll_fd() is readable or the timeout passes; true when readable.
bool wait_readable(const Transport& t, std::chrono::milliseconds timeout);

// The next frame received within `timeout` (waiting on poll_fd between attempts), or
// nullopt. Blocks: for set-up code, tools and tests, not the cyclic path.
std::optional<TimedFrame> receive_within(Transport& t, std::chrono::milliseconds timeout);

// The host's count of UDP datagrams the kernel dropped because a receive buffer was full
// (RcvbufErrors of Udp in /proc/net/snmp plus Udp6 in /proc/net/snmp6), or -1 when neither
// can be read. Every socket of the host counts: a difference over a wait is an upper bound
// of what one socket lost. Not real-time safe (reads files).
std::int64_t udp_receive_buffer_errors();

// Parsed form of a spec, exposed for tests and for `omnitwin` argument checking.
struct TransportSpec {
  enum class Kind { socketcan, udp, mem };
  Kind kind = Kind::mem;
  std::string name;           // socketcan: interface; udp: group address (no brackets); mem: bus name
  std::uint16_t port = 0;     // udp only
  bool ipv6 = false;          // udp only
  int ttl = 1;                // udp only
  std::string iface;          // udp only; empty: kernel's choice
  bool receive_own = false;   // udp only
};
TransportSpec parse_transport_spec(std::string_view spec);  // throws TransportError

inline constexpr std::uint16_t kPythonCanUdpPort = 43113;
inline constexpr const char* kPythonCanGroupV4 = "239.74.163.2";
inline constexpr const char* kPythonCanGroupV6 = "ff15:7079:7468:6f6e:6465:6d6f:6d63:6173";

}  // namespace omnitwin::can
