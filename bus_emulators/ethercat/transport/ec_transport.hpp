// bus_emulators/ethercat/transport — EtherCAT transports: thin adapters that move PDUs
// (the EtherCAT header and its datagrams) between our master and the emulated slaves.
//
// A transport is opened from a spec string and a role:
//   raw:IFACE            AF_PACKET raw socket on an Ethernet interface (veth, NIC), EtherType
//                        0x88A4: the wire format real masters and slaves use.
//   udp:HOST[:PORT]      EtherCAT over UDP: the PDU is the UDP payload (port 0x88A4 = 34980 by
//   udp:[HOST6][:PORT]   default). Slaves bind HOST:PORT and answer the sender; the master
//                        binds an ephemeral port and sends to HOST:PORT.
//   mem:NAME             in-process pair (one master, one slaves end) for tests.
//
// The roles are the two ends of an EtherCAT segment: the master sends frames out and receives
// them back; the slaves end (the emulated chain) receives each frame and sends it back. A
// transport carries no protocol: it does not parse datagrams, it only rejects what cannot be
// an EtherCAT PDU at all, so that the cores behind it never see it:
//   - not EtherCAT: an EtherCAT header type other than 1 (datagrams), e.g. network variables
//     or mailbox gateway frames → counted in dropped_foreign;
//   - malformed: shorter than an EtherCAT header and one empty datagram (14 bytes), a header
//     length beyond the bytes received, or larger than the caller's buffer → dropped_malformed.
// A PDU handed out by receive() is exactly 2 + the header's length bytes (Ethernet padding and
// any trailing bytes removed), so PduView's length equals receive()'s return value.
//
// Threads: one thread uses a transport at a time; the in-process hub itself is thread-safe.
// Real-time: send() and receive() allocate nothing, never throw and make at most a bounded
// number of system calls (receive() waits on fd() with the caller's timeout); opening and
// describe() allocate and may throw.
#pragma once

#include <sys/socket.h>

#include "bus_emulators/ethercat/ec_frame.hpp"
#include "bus_emulators/readable_waiter.hpp"
#include "bus_emulators/transport_spec.hpp"

#include <array>
#include <chrono>
#include <cstdint>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>

namespace omnitwin::ethercat {

enum class Role : std::uint8_t { master, slaves };
const char* to_string(Role r);

class EcTransport {
 public:
  virtual ~EcTransport() = default;
  EcTransport() = default;
  EcTransport(const EcTransport&) = delete;
  EcTransport& operator=(const EcTransport&) = delete;

  // master: one frame to the segment (raw: Ethernet from our MAC to ff:ff:ff:ff:ff:ff; udp: to
  // the peer). slaves: the reply to the last frame received (raw: the same Ethernet header with
  // bit 1 of the first source-MAC byte set; udp: to the sender; false while nothing was received
  // yet). Padded to 60 bytes on raw. Refuses PDUs over kMaxPdu (1500) bytes. Never blocks, never
  // throws. false (counted in send_errors) on error.
  virtual bool send(std::span<const std::uint8_t> pdu) = 0;
  // One PDU into buf (Ethernet header stripped; own outgoing frames, frames that are not
  // EtherCAT and malformed ones skipped and counted), waiting up to timeout (0 = do not wait).
  // Returns its size, 0 on timeout, -1 on a system error (counted in receive_errors). Never throws.
  virtual int receive(std::span<std::uint8_t> buf, std::chrono::nanoseconds timeout) = 0;
  // The Ethernet header (destination, source, EtherType) of the last PDU receive() returned,
  // as it was on the wire; false for transports without one (udp, mem). For captures.
  virtual bool wire_header(std::array<std::uint8_t, kEthHeaderSize>& /*out*/) const { return false; }
  // slaves: the first sender is the master; frames from any other sender (another MAC on raw,
  // another address on udp) are counted (Stats::foreign_sender) and, when refuse is true,
  // dropped before they are answered or become the reply's address. mem has no senders.
  virtual void set_refuse_foreign_senders(bool /*refuse*/) {}
  // slaves: a sender heard after the master has been silent for silent_ns becomes the master
  // (Stats::master_changes): a master started again on udp sends from a new port. < 0 (the
  // default): never. raw keeps the first MAC (a master started again has the same one); mem
  // has no senders. Set before the first receive.
  virtual void set_master_handover(std::int64_t /*silent_ns*/) {}
  // A descriptor that polls readable (POLLIN) while a PDU may be waiting, for event loops.
  virtual int fd() const = 0;
  // The canonical spec and the role, e.g. "raw:eth1 (master, 00:1b:21:0a:0b:0c)".
  virtual std::string describe() const = 0;

  struct Stats {
    std::uint64_t sent = 0;               // PDUs handed to the OS / the peer
    std::uint64_t received = 0;           // PDUs handed to the caller
    std::uint64_t dropped_foreign = 0;    // not EtherCAT type 1 (seen in user space; raw: most are
                                          // dropped earlier by the kernel filter, uncounted)
    std::uint64_t dropped_malformed = 0;  // too short, header length beyond the data, too large
    std::uint64_t dropped_own = 0;        // our own outgoing frames seen in user space (raw)
    std::uint64_t dropped_overflow = 0;   // mem: the receiving queue was full
    std::uint64_t send_errors = 0;        // refused by the OS, oversized PDU, slaves with no peer yet
    std::uint64_t receive_errors = 0;     // the OS reported a receive error
    std::uint64_t foreign_sender = 0;     // slaves: frames from a sender other than the first (the master)
    std::uint64_t refused_sender = 0;     // … of which refused (set_refuse_foreign_senders)
    std::uint64_t master_changes = 0;     // slaves: senders taken for the master from a silent one
  };
  virtual Stats stats() const = 0;
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
std::unique_ptr<EcTransport> open_transport(std::string_view spec, Role role);

// What a receiving transport does with `n` bytes that claim to be a PDU.
enum class PduCheck : std::uint8_t { ok, foreign, malformed };
// ok: `size` = 2 + the header's length (≤ n). RT-safe.
PduCheck check_pdu(const std::uint8_t* data, std::size_t n, std::size_t& size) noexcept;

namespace detail {
// The waiting part of receive(), shared by every bus's transports (bus_emulators/readable_waiter.hpp).
using ReadableWaiter = bus_emulators::ReadableWaiter;
}  // namespace detail

}  // namespace omnitwin::ethercat
