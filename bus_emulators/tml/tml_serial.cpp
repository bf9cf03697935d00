// bus_emulators/tml — TML over RS-232 / RS-485: packets and the link cores (see tml_serial.hpp).
#include "bus_emulators/tml/tml_serial.hpp"

#include <algorithm>
#include <limits>
#include <stdexcept>

namespace omnitwin::tml {

namespace {
constexpr std::int64_t kNever = std::numeric_limits<std::int64_t>::max();
constexpr std::int64_t kNsPerSecond = 1'000'000'000;

bool is_length_byte(std::uint8_t b) { return b >= kMinLengthByte && b <= kMaxLengthByte && b % 2 == 0; }
}  // namespace

const char* to_string(Link l) { return l == Link::rs232 ? "RS-232" : "RS-485"; }

// ---- Packet codec ------------------------------------------------------------------------------

std::uint8_t checksum(std::span<const std::uint8_t> bytes) {
  unsigned sum = 0;
  for (const std::uint8_t b : bytes) sum += b;
  return static_cast<std::uint8_t>(sum & 0xFF);
}

Packet encode_packet(const Message& m) {
  Packet p;
  auto put16 = [&](std::uint16_t w) {
    p.bytes[p.size++] = static_cast<std::uint8_t>(w >> 8);
    p.bytes[p.size++] = static_cast<std::uint8_t>(w & 0xFF);
  };
  const auto words = m.words();
  p.bytes[p.size++] = static_cast<std::uint8_t>(4 + 2 * words.size());  // ID code + opcode + data
  put16(m.id_code);
  put16(m.opcode);
  for (const std::uint16_t w : words) put16(w);
  p.bytes[p.size] = checksum(p.view());
  ++p.size;
  return p;
}

PacketStatus decode_packet(std::span<const std::uint8_t> b, Message& out) {
  if (b.empty()) return PacketStatus::too_short;
  if (!is_length_byte(b[0])) return PacketStatus::bad_length;
  if (b.size() != static_cast<std::size_t>(b[0]) + 2) return PacketStatus::size_mismatch;
  if (checksum(b.first(b.size() - 1)) != b.back()) return PacketStatus::bad_checksum;
  auto get16 = [&](std::size_t i) { return static_cast<std::uint16_t>(b[i] << 8 | b[i + 1]); };
  out = Message{};
  out.id_code = get16(1);
  out.opcode = get16(3);
  out.count = static_cast<std::uint8_t>((b[0] - 4) / 2);
  for (std::size_t i = 0; i < out.count; ++i) out.data[i] = get16(5 + 2 * i);
  return PacketStatus::ok;
}

const char* to_string(PacketStatus s) {
  switch (s) {
    case PacketStatus::ok: return "ok";
    case PacketStatus::too_short: return "too short";
    case PacketStatus::bad_length: return "bad length byte (must be 4, 6, 8, 10 or 12)";
    case PacketStatus::size_mismatch: return "byte count does not match the length byte";
    case PacketStatus::bad_checksum: return "bad checksum";
  }
  return "?";
}

// ---- Addressing --------------------------------------------------------------------------------

std::uint16_t host_sender_code(Link link, std::uint8_t host_axis) { return axis_id_code(host_axis, link == Link::rs232); }

bool acknowledged(Link link, const Message& m) {
  const MessageType t = type_of(m);
  if (t != MessageType::a && t != MessageType::b) return false;
  // On RS-485 every drive that takes a group or axis-0 message would answer: their 'O's collide.
  return !(link == Link::rs485 && to_many(m.id_code));
}

LinkCheck check_host_message(Link link, const Message& m) {
  if (!m.valid()) return LinkCheck::invalid;
  const Classified c = classify(m);
  if (c.kind == Kind::give_me_data && is_group(m.id_code)) return LinkCheck::give_me_data_to_group;
  if (link == Link::rs232) return LinkCheck::ok;
  const MessageType t = type_of(m);
  if (t == MessageType::b && is_group(m.id_code)) return LinkCheck::request_to_group_on_rs485;
  if (t == MessageType::b && id_of(m.id_code) == 0) return LinkCheck::request_to_axis_0_on_rs485;
  if (t == MessageType::c) return LinkCheck::type_c_on_rs485;
  const bool sender_host = t == MessageType::b && is_host(c.sender);
  if (is_host(m.id_code) || sender_host) return LinkCheck::host_bit_on_rs485;
  return LinkCheck::ok;
}

const char* to_string(LinkCheck c) {
  switch (c) {
    case LinkCheck::ok: return "ok";
    case LinkCheck::invalid: return "invalid message (ID code bits 15-13/3-1 set, or more than 4 data words)";
    case LinkCheck::give_me_data_to_group: return "GiveMeData goes to one axis only";
    case LinkCheck::request_to_group_on_rs485: return "RS-485: no type B request to a group (answers would collide)";
    case LinkCheck::request_to_axis_0_on_rs485: return "RS-485: no type B request to axis 0 (every drive would answer)";
    case LinkCheck::type_c_on_rs485: return "RS-485: type C messages are forbidden";
    case LinkCheck::host_bit_on_rs485: return "RS-485: the HOST bit must be 0";
  }
  return "?";
}

// ---- Timing ------------------------------------------------------------------------------------

ByteTiming::ByteTiming(std::uint32_t baud) : baud_(baud) {
  if (baud == 0) throw std::invalid_argument("tml::ByteTiming: baud rate 0");
}

std::int64_t ByteTiming::duration_ns(std::size_t n) const {
  const auto bits = static_cast<std::int64_t>(n) * kBitsPerByte;
  return (bits * kNsPerSecond + baud_ / 2) / baud_;
}

std::int64_t LineTx::send(std::span<const std::uint8_t> bytes, std::int64_t now_ns) {
  const std::int64_t start = std::max(now_ns, free_ns_);
  std::int64_t end = start;
  for (std::size_t k = 0; k < bytes.size(); ++k) {
    end = timing_.end_of(start, k);
    if (sink_) sink_(bytes[k], end);
  }
  free_ns_ = end;
  return end;
}

// ---- Receiver ----------------------------------------------------------------------------------

const char* to_string(RxEventKind k) {
  switch (k) {
    case RxEventKind::message: return "message";
    case RxEventKind::ack: return "ack 'O'";
    case RxEventKind::sync: return "SYNC";
    case RxEventKind::bad_checksum: return "bad checksum";
    case RxEventKind::bad_length: return "bad length byte";
    case RxEventKind::junk: return "unexpected byte";
  }
  return "?";
}

void SerialReceiver::emit(RxEventKind kind, std::int64_t t_ns, std::uint8_t b) {
  RxEvent e;
  e.kind = kind, e.t_ns = t_ns, e.byte = b;
  if (sink_) sink_(e);
}

void SerialReceiver::on_byte(std::uint8_t b, std::int64_t t_ns) {
  if (state_ == State::idle) return idle_byte(b, t_ns);
  // Collect the packet; the last byte is its checksum.
  buf_[fill_++] = b;
  if (fill_ < need_) return;
  state_ = State::idle;
  RxEvent e;
  e.t_ns = t_ns;
  if (decode_packet(std::span(buf_.data(), fill_), e.message) == PacketStatus::ok) {
    ++stats_.messages;
    e.kind = RxEventKind::message;
  } else {
    ++stats_.bad_checksums;  // the length was checked when the packet opened
    e.kind = RxEventKind::bad_checksum;
  }
  if (sink_) sink_(e);
}

void SerialReceiver::idle_byte(std::uint8_t b, std::int64_t t_ns) {
  // A length byte opens a packet.
  if (is_length_byte(b)) {
    buf_[0] = b, fill_ = 1, need_ = static_cast<std::size_t>(b) + 2;
    state_ = State::packet;
    return;
  }
  // Host role: 'O' acknowledges, 0x0D is a SYNC echo.
  if (role_ == Role::host && (b == kAckByte || b == kSyncByte)) {
    ++(b == kAckByte ? stats_.acks : stats_.syncs);
    return emit(b == kAckByte ? RxEventKind::ack : RxEventKind::sync, t_ns, b);
  }
  // Drive role: any byte >= 0x0D between packets is a SYNC byte.
  if (role_ == Role::drive && b >= kSyncByte) {
    ++stats_.syncs;
    return emit(RxEventKind::sync, t_ns, b);
  }
  if (b < kSyncByte) {
    ++stats_.bad_lengths;
    return emit(RxEventKind::bad_length, t_ns, b);
  }
  ++stats_.junk;
  emit(RxEventKind::junk, t_ns, b);
}

// ---- Drive side --------------------------------------------------------------------------------

SerialDriveLink::SerialDriveLink(const DriveLinkConfig& cfg, LineTx::Sink tx, MessageSink on_message)
    : cfg_(cfg),
      tx_(cfg.baud, std::move(tx)),
      on_message_(std::move(on_message)),
      rx_(Role::drive, [this](const RxEvent& e) { on_event(e); }) {}

bool SerialDriveLink::for_us(std::uint16_t id_code) const {
  if (is_group(id_code)) {
    const std::uint8_t mask = groups_ ? groups_() : cfg_.groups;
    return is_broadcast(id_code) || (id_of(id_code) & mask) != 0;
  }
  return id_of(id_code) == 0 || id_of(id_code) == cfg_.axis;
}

void SerialDriveLink::on_event(const RxEvent& e) {
  switch (e.kind) {
    case RxEventKind::message:
      // ID code bits 15–13 and 3–1 are zero (seed ch. 2): a malformed one is for nobody, no 'O'.
      if (!id_code_valid(e.message.id_code)) {
        ++stats_.invalid_id_codes;
        return;
      }
      // RS-485 is multi-drop: only the addressed drives take it; the RS-232 relay takes all.
      if (cfg_.link == Link::rs485 && !for_us(e.message.id_code)) {
        ++stats_.not_for_us;
        return;
      }
      // Acknowledge first: an answer sent from the sink must follow the 'O' on the line.
      if (acknowledged(cfg_.link, e.message)) {
        tx_.send(kAckByte, e.t_ns);
        ++stats_.acks_sent;
      }
      ++stats_.delivered;
      if (on_message_) on_message_(e.message, e.t_ns);
      return;
    case RxEventKind::sync:
      // RS-232: echo so the host knows the link is in step again (RS-485: our choice, silent).
      if (cfg_.link == Link::rs232) {
        tx_.send(kSyncByte, e.t_ns);
        ++stats_.syncs_echoed;
      }
      return;
    default: return;  // bad checksum, bad length: no acknowledgement (counted by the receiver)
  }
}

// ---- Host side ---------------------------------------------------------------------------------

const char* to_string(HostEventKind k) {
  switch (k) {
    case HostEventKind::acked: return "acked";
    case HostEventKind::sent_unacknowledged: return "sent (no ack expected)";
    case HostEventKind::answer: return "answer";
    case HostEventKind::answer_timeout: return "answer timeout";
    case HostEventKind::resent: return "resent";
    case HostEventKind::link_broken: return "link broken";
    case HostEventKind::unsolicited: return "unsolicited";
  }
  return "?";
}

const char* to_string(SendStatus s) {
  switch (s) {
    case SendStatus::ok: return "ok";
    case SendStatus::busy: return "busy";
    case SendStatus::link_broken: return "link broken";
    case SendStatus::not_allowed: return "not allowed on this link";
  }
  return "?";
}

SerialHostLink::SerialHostLink(const HostLinkConfig& cfg, LineTx::Sink tx, EventSink on_event)
    : cfg_(cfg),
      tx_(cfg.baud, std::move(tx)),
      on_event_(std::move(on_event)),
      rx_(Role::host, [this](const RxEvent& e) { on_rx(e); }) {}

SendStatus SerialHostLink::send(const Message& m, std::int64_t now_ns) {
  if (state_ == State::broken) return SendStatus::link_broken;
  if (state_ != State::idle) return SendStatus::busy;
  if (check_host_message(cfg_.link, m) != LinkCheck::ok) return SendStatus::not_allowed;
  command_ = m;
  expects_answer_ = type_of(m) == MessageType::b;
  syncs_ = resends_ = 0;
  transmit_command(now_ns);
  // An RS-485 group message is not acknowledged: done once it has left.
  if (!acknowledged(cfg_.link, m)) {
    state_ = State::idle, deadline_ = kNever;
    emit(HostEventKind::sent_unacknowledged, tx_.free_at(), m);
  }
  return SendStatus::ok;
}

void SerialHostLink::transmit_command(std::int64_t now_ns) {
  const std::int64_t end = tx_.send(encode_packet(command_).view(), now_ns);
  state_ = State::wait_ack;
  deadline_ = end + cfg_.ack_timeout_ns;  // counted from the end of the checksum byte
}

void SerialHostLink::start_recovery(std::int64_t now_ns) {
  syncs_ = 0;
  if (cfg_.link == Link::rs232) {
    // One SYNC byte, then wait for its echo.
    const std::int64_t end = tx_.send(kSyncByte, now_ns);
    ++syncs_, ++syncs_total_;
    state_ = State::wait_echo, deadline_ = end + cfg_.sync_timeout_ns;
    return;
  }
  // RS-485: max_sync SYNC bytes in one burst, wait, then resend.
  std::array<std::uint8_t, 64> burst{};
  const auto n = static_cast<std::size_t>(std::clamp(cfg_.max_sync, 1, 64));
  std::fill_n(burst.begin(), n, kSyncByte);
  const std::int64_t end = tx_.send(std::span(burst.data(), n), now_ns);
  syncs_ = static_cast<int>(n), syncs_total_ += static_cast<int>(n);
  state_ = State::wait_resync, deadline_ = end + cfg_.sync_timeout_ns;
}

void SerialHostLink::poll(std::int64_t now_ns) {
  while (deadline_ != kNever && now_ns >= deadline_) step(Transition::timeout, deadline_, nullptr);
}

std::int64_t SerialHostLink::next_deadline() const { return deadline_; }

void SerialHostLink::reset() {
  state_ = State::idle, deadline_ = kNever;
  syncs_ = resends_ = 0;
  rx_.reset();
}

void SerialHostLink::emit(HostEventKind k, std::int64_t t_ns, const Message& m) {
  HostEvent e;
  e.kind = k, e.t_ns = t_ns, e.message = m;
  if (on_event_) on_event_(e);
}

bool SerialHostLink::answers(const Message& m) const {
  // GiveMeData (B004/B005) → TakeData (B404/B405), GiveMeData2 (B204/B205) → TakeData2
  // (D4xx/D5xx), of the same width and address.
  const Classified q = classify(command_), a = classify(m);
  const Kind want = q.kind == Kind::give_me_data ? Kind::take_data : Kind::take_data2;
  return a.kind == want && a.wide == q.wide && a.address == q.address;
}

void SerialHostLink::on_rx(const RxEvent& e) {
  switch (e.kind) {
    case RxEventKind::ack: return step(Transition::ack, e.t_ns, nullptr);
    case RxEventKind::sync: return step(Transition::echo, e.t_ns, nullptr);
    case RxEventKind::message: return step(Transition::message, e.t_ns, &e.message);
    default: return;  // a bad answer: counted; the answer timeout tells the caller to ask again
  }
}

void SerialHostLink::step(Transition t, std::int64_t t_ns, const Message* m) {
  switch (t) {
    case Transition::ack:
      if (state_ != State::wait_ack) return;  // a stray 'O'
      if (expects_answer_) {
        state_ = State::wait_answer, deadline_ = t_ns + cfg_.answer_timeout_ns;
        return;
      }
      state_ = State::idle, deadline_ = kNever;
      return emit(HostEventKind::acked, t_ns, command_);
    case Transition::echo:
      if (state_ != State::wait_echo) return;
      // In step again: resend the last command (a bounded number of times).
      if (resends_ >= cfg_.max_resends) {
        state_ = State::broken, deadline_ = kNever;
        return emit(HostEventKind::link_broken, t_ns, command_);
      }
      ++resends_;
      transmit_command(t_ns);
      return emit(HostEventKind::resent, t_ns, command_);
    case Transition::message: {
      // Only the answer to the request ends the wait; a type C TakeData2 may arrive before it.
      if (state_ == State::wait_answer && answers(*m)) {
        state_ = State::idle, deadline_ = kNever;
        return emit(HostEventKind::answer, t_ns, *m);
      }
      return emit(HostEventKind::unsolicited, t_ns, *m);
    }
    case Transition::timeout:
      switch (state_) {
        case State::wait_ack:
          // RS-485 resends once only; otherwise recover with SYNC bytes.
          if (cfg_.link == Link::rs485 && resends_ > 0) {
            state_ = State::broken, deadline_ = kNever;
            return emit(HostEventKind::link_broken, t_ns, command_);
          }
          return start_recovery(t_ns);
        case State::wait_echo:
          if (syncs_ >= cfg_.max_sync) {
            state_ = State::broken, deadline_ = kNever;
            return emit(HostEventKind::link_broken, t_ns, command_);
          }
          ++syncs_, ++syncs_total_;
          deadline_ = tx_.send(kSyncByte, t_ns) + cfg_.sync_timeout_ns;
          return;
        case State::wait_resync:
          ++resends_;
          transmit_command(t_ns);
          return emit(HostEventKind::resent, t_ns, command_);
        case State::wait_answer:
          state_ = State::idle, deadline_ = kNever;
          return emit(HostEventKind::answer_timeout, t_ns, command_);
        default: deadline_ = kNever; return;
      }
  }
}

}  // namespace omnitwin::tml
