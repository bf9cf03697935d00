// bus_emulators/tml — TML over RS-232 / RS-485 (seed 003 chapter 3; facts/tml.md): the packet
// codec and the link layer as protocol cores.
//
// Packet: length byte (ID code + opcode + data bytes), ID code, opcode, data words — all big-
// endian — and a checksum (sum of the previous bytes mod 256). The link layer is three cores
// with no sockets and no clock: bytes and time (integer ns) go in, bytes (each with the time
// its stop bits end on the line) and decoded events come out through callbacks.
//   - SerialReceiver: bytes → packets, 'O' acknowledgements, SYNC bytes; bad checksums are
//     counted and reported, never acknowledged.
//   - SerialDriveLink: a drive's port: acknowledges what it accepts with 'O' (not group or
//     axis-0 messages on RS-485), echoes SYNC bytes between packets on RS-232, sends answers.
//   - SerialHostLink: the host's sender: one command at a time, waits ~2 ms for 'O', recovers
//     with SYNC bytes (RS-232: one at a time until echoed, 15 at most, then "link broken";
//     RS-485: 15 at once, wait, resend once), then waits for the answer of a type B request.
// Byte timing: 8N2 framing, 11 bit times per byte (start, 8 data, 2 stop).
// Our choices (docs/protocols/tml.md): RS-485 drives do not echo SYNC bytes (the seed's RS-485
// recovery never waits for an echo, and 32 drives echoing would collide); an RS-232 command is
// resent at most 3 times; a type B answer is awaited 100 ms (configurable; not in the seed).
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <span>

#include "bus_emulators/tml/tml_message.hpp"

namespace omnitwin::tml {

enum class Link : std::uint8_t { rs232, rs485 };
const char* to_string(Link l);

inline constexpr std::uint8_t kAckByte = 0x4F;   // 'O'
inline constexpr std::uint8_t kSyncByte = 0x0D;
inline constexpr std::size_t kMaxPacketBytes = 1 + 2 + 2 + 2 * kMaxDataWords + 1;  // 14
inline constexpr std::uint8_t kMinLengthByte = 4, kMaxLengthByte = 12;

// ---- Packet codec ------------------------------------------------------------------------------
struct Packet {
  std::array<std::uint8_t, kMaxPacketBytes> bytes{};
  std::uint8_t size = 0;
  std::span<const std::uint8_t> view() const { return {bytes.data(), size}; }
};

// Sum of the bytes mod 256. RT-safe.
std::uint8_t checksum(std::span<const std::uint8_t> bytes);
// The packet of a message (count clamped to 4). RT-safe.
Packet encode_packet(const Message& m);

enum class PacketStatus : std::uint8_t { ok, too_short, bad_length, size_mismatch, bad_checksum };
const char* to_string(PacketStatus s);
// One whole packet (length byte .. checksum). RT-safe.
PacketStatus decode_packet(std::span<const std::uint8_t> bytes, Message& out);

// ---- Addressing on a serial link ---------------------------------------------------------------
// The host's own ID code as a sender: RS-232 shares the relay's axis with HOST set; RS-485 has
// its own axis and HOST = 0. RT-safe.
std::uint16_t host_sender_code(Link link, std::uint8_t host_axis);
// Whether the drive answers this message with 'O': types A and B, except group and axis-0
// messages on RS-485 (every drive takes them: the 'O's would collide). RT-safe.
bool acknowledged(Link link, const Message& m);

enum class LinkCheck : std::uint8_t {
  ok, invalid, give_me_data_to_group, request_to_group_on_rs485, request_to_axis_0_on_rs485, type_c_on_rs485,
  host_bit_on_rs485
};
const char* to_string(LinkCheck c);
// What the host may send on this link (seed ch. 3 and 6). RT-safe.
LinkCheck check_host_message(Link link, const Message& m);

// ---- Byte timing (8N2) -------------------------------------------------------------------------
class ByteTiming {
 public:
  static constexpr int kBitsPerByte = 11;
  explicit ByteTiming(std::uint32_t baud);  // throws std::invalid_argument on 0 (set-up)
  std::uint32_t baud() const { return baud_; }
  // Duration of n back-to-back bytes [ns], rounded to the nearest ns (no drift over a burst).
  std::int64_t duration_ns(std::size_t n) const;
  std::int64_t byte_ns() const { return duration_ns(1); }
  // End of byte k (0-based) of a burst whose first start bit begins at start_ns. RT-safe.
  std::int64_t end_of(std::int64_t start_ns, std::size_t k) const { return start_ns + duration_ns(k + 1); }

 private:
  std::uint32_t baud_;
};
// The baud rates the seed lists (56600 as printed; the usual rate is 57600).
inline constexpr std::array<std::uint32_t, 5> kSeedBaudRates{9600, 19200, 38400, 56600, 115200};

// Sends bytes back to back on one direction of a line: each byte starts when the previous one
// ended (or now, if the line is idle). RT-safe.
class LineTx {
 public:
  using Sink = std::function<void(std::uint8_t byte, std::int64_t end_ns)>;
  LineTx(std::uint32_t baud, Sink sink) : timing_(baud), sink_(std::move(sink)) {}
  // Queues bytes at now_ns; returns the end time of the last one.
  std::int64_t send(std::span<const std::uint8_t> bytes, std::int64_t now_ns);
  std::int64_t send(std::uint8_t byte, std::int64_t now_ns) { return send(std::span(&byte, 1), now_ns); }
  const ByteTiming& timing() const { return timing_; }
  std::int64_t free_at() const { return free_ns_; }

 private:
  ByteTiming timing_;
  Sink sink_;
  std::int64_t free_ns_ = INT64_MIN;
};

// ---- Receiver ----------------------------------------------------------------------------------
enum class Role : std::uint8_t { drive, host };
enum class RxEventKind : std::uint8_t { message, ack, sync, bad_checksum, bad_length, junk };
const char* to_string(RxEventKind k);

struct RxEvent {
  RxEventKind kind = RxEventKind::junk;
  std::int64_t t_ns = 0;  // when the byte that completed it was received
  Message message{};      // kind == message
  std::uint8_t byte = 0;  // the byte (ack, sync, bad_length, junk)
};

struct RxStats {
  std::uint64_t messages = 0, acks = 0, syncs = 0, bad_checksums = 0, bad_lengths = 0, junk = 0;
};

// Turns received bytes into events.
// States:
//   idle   — between packets. A length byte (4–12, even) opens a packet. Drive role: any other
//            byte >= 0x0D is a SYNC byte ("larger values are accepted too"). Host role: 'O' is
//            an acknowledgement and 0x0D a SYNC echo. Other values: bad_length (< 0x0D) or junk.
//   packet — collecting the rest of the packet (length + 1 bytes); on the checksum byte:
//            message or bad_checksum, back to idle.
class SerialReceiver {
 public:
  using Sink = std::function<void(const RxEvent&)>;
  SerialReceiver(Role role, Sink sink) : role_(role), sink_(std::move(sink)) {}
  // One received byte; t_ns: the end of its stop bits. RT-safe.
  void on_byte(std::uint8_t b, std::int64_t t_ns);
  void reset() { state_ = State::idle, fill_ = 0; }
  bool in_packet() const { return state_ == State::packet; }
  const RxStats& stats() const { return stats_; }

 private:
  enum class State : std::uint8_t { idle, packet };
  void idle_byte(std::uint8_t b, std::int64_t t_ns);
  void emit(RxEventKind kind, std::int64_t t_ns, std::uint8_t b);
  Role role_;
  Sink sink_;
  State state_ = State::idle;
  std::array<std::uint8_t, kMaxPacketBytes> buf_{};
  std::size_t fill_ = 0, need_ = 0;
  RxStats stats_;
};

// ---- Drive side --------------------------------------------------------------------------------
struct DriveLinkConfig {
  Link link = Link::rs232;
  std::uint8_t axis = 255;        // this drive's axis ID
  std::uint8_t groups = 1;        // its group ID (mask) when set_groups() gives none; default group 1
  std::uint32_t baud = 9600;
};

struct DriveLinkStats {
  std::uint64_t acks_sent = 0, syncs_echoed = 0, not_for_us = 0, delivered = 0;
  std::uint64_t invalid_id_codes = 0;  // ID code bits 15–13 or 3–1 set: dropped, no 'O'
};

// A drive's serial port. Every packet with a good checksum and a well-formed ID code (bits 15–13
// and 3–1 zero; others are counted and dropped, no 'O') that is for this drive (RS-232: every
// packet — the relay forwards the others; RS-485: its axis, axis 0, or one of its groups, as the
// drive's current group mask says when set_groups() gives it) goes to the message sink; it is
// acknowledged with 'O' unless it is a group or axis-0 message on RS-485 or an answer/type C
// message. Bad checksums: counted, no acknowledgement. SYNC bytes between packets are echoed
// with 0x0D on RS-232. send() puts answers and type C messages on the line.
class SerialDriveLink {
 public:
  using MessageSink = std::function<void(const Message&, std::int64_t t_ns)>;
  SerialDriveLink(const DriveLinkConfig& cfg, LineTx::Sink tx, MessageSink on_message);
  SerialDriveLink(const SerialDriveLink&) = delete;
  SerialDriveLink& operator=(const SerialDriveLink&) = delete;
  // Set-up: where the group mask comes from (the drive's, which GROUPID/ADDGRID/REMGRID change);
  // empty: cfg.groups.
  void set_groups(std::function<std::uint8_t()> groups) { groups_ = std::move(groups); }
  // One byte received from the host; t_ns: the end of its stop bits. RT-safe.
  void on_byte(std::uint8_t b, std::int64_t t_ns) { rx_.on_byte(b, t_ns); }
  // Sends a message (answer or type C) after whatever is already on the line. RT-safe.
  void send(const Message& m, std::int64_t now_ns) { tx_.send(encode_packet(m).view(), now_ns); }
  // Whether this drive takes a message with this destination ID code (RS-485 rules; groups: the
  // current mask). RT-safe.
  bool for_us(std::uint16_t id_code) const;
  const RxStats& rx_stats() const { return rx_.stats(); }
  const DriveLinkStats& stats() const { return stats_; }

 private:
  void on_event(const RxEvent& e);
  DriveLinkConfig cfg_;
  LineTx tx_;
  MessageSink on_message_;
  std::function<std::uint8_t()> groups_;
  SerialReceiver rx_;
  DriveLinkStats stats_;
};

// ---- Host side ---------------------------------------------------------------------------------
struct HostLinkConfig {
  Link link = Link::rs232;
  std::uint32_t baud = 9600;
  std::int64_t ack_timeout_ns = 2'000'000;     // after the checksum byte (seed: at least 2 ms)
  std::int64_t sync_timeout_ns = 2'000'000;    // after a SYNC byte (seed: typically 2 ms)
  int max_sync = 15;                           // seed: 15 SYNC bytes
  int max_resends = 3;                         // OUR CHOICE (RS-232): resends per command
  std::int64_t answer_timeout_ns = 100'000'000;  // OUR CHOICE: type B answer wait
};

enum class HostEventKind : std::uint8_t {
  acked,                // 'O' for a type A command
  sent_unacknowledged,  // an RS-485 group or axis-0 message left the line (no 'O' expected)
  answer,               // the TakeData / TakeData2 of a type B request ('O' came first): same kind, width, address
  answer_timeout,       // 'O' came, the answer did not
  resent,               // the command was sent again after SYNC recovery
  link_broken,          // recovery failed
  unsolicited,          // a message that is not the awaited answer (type C, or another request's answer)
};
const char* to_string(HostEventKind k);

struct HostEvent {
  HostEventKind kind = HostEventKind::acked;
  std::int64_t t_ns = 0;
  Message message{};  // the answer/unsolicited message, or the command for the others
};

enum class SendStatus : std::uint8_t { ok, busy, link_broken, not_allowed };
const char* to_string(SendStatus s);

// The host's sender.
// States:
//   idle        — send() accepted; received messages are `unsolicited`.
//   wait_ack    — the command is on the line; 'O' → acked (type A, idle) or wait_answer (type
//                 B); no 'O' by ack_timeout after the checksum byte → RS-232: one SYNC,
//                 wait_echo; RS-485: 15 SYNC bytes, wait_resync (after a resend: link_broken).
//   wait_echo   — RS-232: 0x0D echoed → resend, wait_ack (more than max_resends: link_broken);
//                 no echo by sync_timeout → another SYNC (max_sync in all: link_broken).
//   wait_resync — RS-485: sync_timeout after the 15th SYNC → resend once, wait_ack.
//   wait_answer — the TakeData (of a GiveMeData) or TakeData2 (of a GiveMeData2) of the same width
//                 and address → answer, idle; any other message → unsolicited, still waiting;
//                 answer_timeout → answer_timeout, idle.
//   broken      — send() refused until reset().
class SerialHostLink {
 public:
  using EventSink = std::function<void(const HostEvent&)>;
  SerialHostLink(const HostLinkConfig& cfg, LineTx::Sink tx, EventSink on_event);
  SerialHostLink(const SerialHostLink&) = delete;
  SerialHostLink& operator=(const SerialHostLink&) = delete;

  // Sends one command (refused while busy, when broken, or when the link forbids it). RT-safe.
  SendStatus send(const Message& m, std::int64_t now_ns);
  // A byte received from the drive(s); t_ns: the end of its stop bits. RT-safe.
  void on_byte(std::uint8_t b, std::int64_t t_ns) { rx_.on_byte(b, t_ns); }
  // Runs the timeouts up to now_ns; call at next_deadline() (or more often). RT-safe.
  void poll(std::int64_t now_ns);
  // When poll() next has work; INT64_MAX when none.
  std::int64_t next_deadline() const;
  void reset();
  bool idle() const { return state_ == State::idle; }
  bool broken() const { return state_ == State::broken; }
  int syncs_sent() const { return syncs_total_; }
  const RxStats& rx_stats() const { return rx_.stats(); }
  const ByteTiming& timing() const { return tx_.timing(); }

 private:
  enum class State : std::uint8_t { idle, wait_ack, wait_echo, wait_resync, wait_answer, broken };
  enum class Transition : std::uint8_t { ack, echo, message, timeout };
  void step(Transition t, std::int64_t t_ns, const Message* m);
  void transmit_command(std::int64_t now_ns);
  void start_recovery(std::int64_t now_ns);
  void emit(HostEventKind k, std::int64_t t_ns, const Message& m);
  void on_rx(const RxEvent& e);
  // Whether m is the answer to the type B command_ (its kind, width and address). RT-safe.
  bool answers(const Message& m) const;

  HostLinkConfig cfg_;
  LineTx tx_;
  EventSink on_event_;
  SerialReceiver rx_;
  State state_ = State::idle;
  Message command_{};
  bool expects_answer_ = false;
  std::int64_t deadline_ = INT64_MAX;
  int syncs_ = 0, resends_ = 0, syncs_total_ = 0;
};

}  // namespace omnitwin::tml
