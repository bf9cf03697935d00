// controller programs — `omni-tml`: the Technosoft Binary Code Viewer (seed 003 chapter 6) on
// the command line, over the codecs in bus_emulators/tml.
//
//   omni-tml encode --protocol rs232|rs485|tmlcan|techcan|raw --axis N [--group] [--host N]
//                   [--value HEX] [--from N] 'KPP=5' | '?KPP' | '??KPP' | --raw OPCODE [DATA...]
//     prints the instruction in words, the bytes (or CAN frame) to send and the expected
//     answer: 'O' on serial links (not for RS-485 group or axis 0 messages) and, for a query, the
//     TakeData (?NAME) or TakeData2 (??NAME) that comes back (from a group or axis 0: the answer
//     of axis --from); without --value its value and checksum bytes are shown as ??. With
//     --group, N is a group number 1-8 (0 = broadcast).
//   omni-tml decode --protocol P INPUT...
//     serial: hex bytes (packets, 'O' 4F, SYNC 0D); CAN: ID#DATA as can-utils' cansend writes
//     it (3 hex digits: 11-bit, 8: 29-bit); raw: hex words, opcode first.
//   omni-tml send --protocol rs232|rs485 --port PATH [--baud B] | --protocol tmlcan|techcan
//                 --iface SPEC, then the instruction as for encode
//     sends it to a drive and prints what came back: 'O' and the answer on a serial line (with
//     the seed's SYNC-byte recovery when the 'O' is lost), on CAN the frames that answer its
//     query (other traffic on the bus, e.g. a running master's answers, is only counted).
//   omni-tml drive --protocol rs232|rs485 [--axis N] [--host N] [--baud B] [--duration S]
//                  [--drop AXIS ...] [--relay SPEC [--relay-protocol tmlcan|techcan]]
//     runs one emulated IDM drive (bus_emulators/tml, on the shared drive core with a model
//     shaft) on a pseudo-terminal and prints its path: any serial program can talk TML to it.
//     With --drop (RS-485) more drives share the line (multi-drop). With --relay it is the relay axis: the host's messages for other axes go onto that CAN
//     bus and their answers come back over the line.
// encode and decode are pure text: nothing is sent anywhere. Exit codes: 0 ok; 2 bad usage or
// input (a one-line message on stderr naming what is wrong); 3 no answer / link broken.
#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <cctype>
#include <cerrno>
#include <cstring>
#include <memory>
#include <charconv>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include <fcntl.h>
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <chrono>
#include <csignal>

#include "bus_emulators/can/transport.hpp"
#include "bus_emulators/drive/axis_model.hpp"
#include "bus_emulators/tml/tml_can.hpp"
#include "bus_emulators/tml/tml_drive.hpp"
#include "bus_emulators/tml/tml_message.hpp"
#include "bus_emulators/tml/tml_pty.hpp"
#include "bus_emulators/tml/tml_relay.hpp"
#include "bus_emulators/tml/tml_serial.hpp"
#include "controller/programs/cli_checks.hpp"

using namespace omnitwin;
using namespace omnitwin::tml;

namespace {

constexpr int kExitOk = 0, kExitUsage = 2, kExitNoAnswer = 3;

// A bad-input failure: main prints it and exits 2.
struct InputError {
  std::string what;
};

struct Options {
  std::string protocol = "rs232";
  int axis = 255;
  int host = 255;
  bool group = false;
  bool raw = false;
  std::string value;  // hex; empty: unknown
  int from = -1;      // the answering axis of a group query
  std::vector<std::string> input;
  std::string port;             // send: the serial device
  std::string iface;            // send: the CAN transport spec
  std::uint32_t baud = 9600;
  double timeout_ms = 500;      // send: how long to wait for answers
  double duration = -1;         // drive: seconds, < 0 = until Ctrl-C
  std::string relay;            // drive: the CAN transport the relay axis forwards to ("" = none)
  std::string relay_protocol = "tmlcan";
  std::vector<int> drops;       // drive, RS-485: more drives on the same line (axis IDs)
};

// ---- Text helpers ------------------------------------------------------------------------------

std::string hex_bytes(std::span<const std::uint8_t> b) {
  std::string s;
  for (const auto x : b) s += fmt::format("{}{:02X}", s.empty() ? "" : " ", x);
  return s;
}

std::uint32_t parse_hex(std::string_view s, std::uint64_t max, const char* what) {
  if (s.starts_with("0x") || s.starts_with("0X")) s.remove_prefix(2);
  std::uint64_t v = 0;
  const auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v, 16);
  if (s.empty() || ec != std::errc{} || p != s.data() + s.size() || v > max)
    throw InputError{fmt::format("{} '{}' is not a hex number up to 0x{:X}", what, s, max)};
  return static_cast<std::uint32_t>(v);
}

// Hex digits (spaces, commas and 0x prefixes allowed between bytes) → bytes.
std::vector<std::uint8_t> parse_hex_bytes(const std::vector<std::string>& args) {
  std::string digits;
  for (const auto& a : args) {
    for (std::size_t i = 0; i < a.size(); ++i) {
      if (a[i] == '0' && i + 1 < a.size() && (a[i + 1] == 'x' || a[i + 1] == 'X')) { ++i; continue; }
      if (std::isxdigit(static_cast<unsigned char>(a[i]))) digits += a[i];
      else if (a[i] != ' ' && a[i] != ',' && a[i] != ':') throw InputError{fmt::format("'{}' is not a hex digit", a[i])};
    }
  }
  if (digits.empty() || digits.size() % 2) throw InputError{"the bytes must be an even number of hex digits"};
  std::vector<std::uint8_t> out;
  for (std::size_t i = 0; i < digits.size(); i += 2) out.push_back(static_cast<std::uint8_t>(parse_hex(digits.substr(i, 2), 0xFF, "byte")));
  return out;
}

// `ID#DATA` or `ID#R` (cansend): 3 hex digits are an 11-bit ID, 8 a 29-bit one.
can::Frame parse_cansend(const std::string& s) {
  const auto hash = s.find('#');
  if (hash == std::string::npos) throw InputError{fmt::format("'{}' is not ID#DATA", s)};
  const std::string id = s.substr(0, hash), data = s.substr(hash + 1);
  if (id.size() != 3 && id.size() != 8) throw InputError{fmt::format("CAN ID '{}' must have 3 (11-bit) or 8 (29-bit) hex digits", id)};
  can::Frame f;
  f.extended = id.size() == 8;
  f.id = parse_hex(id, f.extended ? 0x1FFFFFFF : 0x7FF, "CAN ID");
  if (data == "R" || data == "r") {
    f.kind = can::FrameKind::remote;
    return f;
  }
  const auto bytes = data.empty() ? std::vector<std::uint8_t>{} : parse_hex_bytes({data});
  if (bytes.size() > 8) throw InputError{fmt::format("'{}' has more than 8 data bytes", s)};
  std::copy(bytes.begin(), bytes.end(), f.data.begin());
  f.dlc = static_cast<std::uint8_t>(bytes.size());
  return f;
}

std::string cansend(const can::Frame& f) {
  std::string s = f.extended ? fmt::format("{:08X}#", f.id) : fmt::format("{:03X}#", f.id);
  for (int i = 0; i < f.payload_size(); ++i) s += fmt::format("{:02X}", f.data[i]);
  return s;
}

// ---- Encoding ----------------------------------------------------------------------------------

// The message on the chosen protocol as a list of bytes (serial) or a frame (CAN).
std::string wire_text(const std::string& protocol, const Message& m) {
  if (protocol == "rs232" || protocol == "rs485") return hex_bytes(encode_packet(m).view());
  if (protocol == "raw") return to_string(m).substr(5);  // opcode and data words (no ID code)
  can::Frame f;
  const CanStatus st = protocol == "tmlcan" ? encode_tmlcan(m, f) : encode_techcan(m, f);
  if (st != CanStatus::ok) throw InputError{fmt::format("{} cannot carry this message: {}", protocol, to_string(st))};
  return fmt::format("{}   (ID 0x{:0{}X}, {} data bytes)", cansend(f), f.id, f.extended ? 8 : 3, f.dlc);
}

// The wire text of an answer; without a known value the bytes that depend on it are "??".
std::string answer_text(const std::string& protocol, Message (*make)(std::uint32_t, const void*), const void* ctx,
                        const std::optional<std::uint32_t>& value) {
  if (value) return wire_text(protocol, make(*value, ctx));
  const std::string a = wire_text(protocol, make(0, ctx)), b = wire_text(protocol, make(0xFFFFFFFF, ctx));
  std::string out = a;
  for (std::size_t i = 0; i < a.size() && i < b.size(); ++i)
    if (a[i] != b[i]) out[i] = '?';
  return out;
}

struct Query {
  Classified c;
  std::uint16_t answering;  // ID code of the answering axis
};

Message make_take_data(std::uint32_t v, const void* ctx) {
  const auto& q = *static_cast<const Query*>(ctx);
  return take_data(q.c.sender, q.answering, q.c.address, v, q.c.wide);
}

Message make_take_data2(std::uint32_t v, const void* ctx) {
  const auto& q = *static_cast<const Query*>(ctx);
  return take_data2(q.c.sender, id_of(q.answering), q.c.address, v, q.c.wide);
}

Message build_message(const Options& o, std::uint16_t dest, std::uint16_t sender) {
  Message m;
  m.id_code = dest;
  if (o.raw) {
    if (o.input.empty() || o.input.size() > 1 + kMaxDataWords) throw InputError{"--raw takes an opcode and 0-4 data words (hex)"};
    m.opcode = static_cast<std::uint16_t>(parse_hex(o.input[0], 0xFFFF, "opcode"));
    for (std::size_t i = 1; i < o.input.size(); ++i) m.data[m.count++] = static_cast<std::uint16_t>(parse_hex(o.input[i], 0xFFFF, "data word"));
    return m;
  }
  if (o.input.size() != 1) throw InputError{"give one instruction: 'NAME=VALUE', '?NAME' or '??NAME' (or --raw)"};
  TextInstruction t;
  if (std::string e = parse_text(o.input[0], t); !e.empty()) throw InputError{e};
  if (std::string e = build_text(t, dest, sender, m); !e.empty()) throw InputError{e};
  return m;
}

void print_expected(const Options& o, const Message& m) {
  const bool serial = o.protocol == "rs232" || o.protocol == "rs485";
  const Link link = o.protocol == "rs485" ? Link::rs485 : Link::rs232;
  if (serial) {
    fmt::print("expect:    {}\n", acknowledged(link, m)
                                      ? "4F   ('O': received, checksum good)"
                                      : "nothing (RS-485 group or axis 0 message: no acknowledgement)");
  }
  const Classified c = classify(m);
  if (c.kind != Kind::give_me_data && c.kind != Kind::give_me_data2) {
    if (!serial) fmt::print("expect:    no answer (type A)\n");
    return;
  }
  if (is_group(m.id_code) && o.from < 0) {
    fmt::print("answer:    one TakeData2 from each group member, lower axis IDs first (give --from N to see one)\n");
    return;
  }
  // Every drive that hears axis 0 answers with its own axis ID, which the tool does not know.
  if (id_of(m.id_code) == 0 && o.from < 0) {
    fmt::print("answer:    one {} from each drive that hears axis 0, with its own axis ID (give --from N to see one)\n",
               c.kind == Kind::give_me_data ? "TakeData" : "TakeData2");
    return;
  }
  const Query q{c, axis_id_code(static_cast<std::uint8_t>(o.from >= 0 ? o.from : id_of(m.id_code)))};
  const auto make = c.kind == Kind::give_me_data ? make_take_data : make_take_data2;
  std::optional<std::uint32_t> value;
  if (!o.value.empty()) value = parse_hex(o.value, c.wide ? 0xFFFFFFFFull : 0xFFFF, "--value");
  fmt::print("answer:    {}   ({})\n", answer_text(o.protocol, make, &q, value),
             c.kind == Kind::give_me_data ? "TakeData" : "TakeData2");
  if (!value) fmt::print("           ?? = the value bytes (and checksum); --value HEX fills them in\n");
  else fmt::print("           {}\n", describe(make(*value, &q)));
}

// The destination ID code of --axis (and --group), checked: group_mask() makes a group number
// over 8 a 0 mask, i.e. a broadcast to every drive (found in review: `send --group` did).
std::uint16_t destination(const Options& o) {
  if (o.axis < 0 || o.axis > 255 || o.host < 0 || o.host > 255) throw InputError{"--axis and --host take 0-255"};
  if (o.group && o.axis > 8) throw InputError{"with --group, --axis is a group number 1-8 (0 = broadcast)"};
  return o.group ? group_id_code(group_mask(o.axis)) : axis_id_code(static_cast<std::uint8_t>(o.axis));
}

int run_encode(const Options& o) {
  const std::uint16_t dest = destination(o);
  const auto host_axis = static_cast<std::uint8_t>(o.host);
  const std::uint16_t sender = o.protocol == "rs232" ? host_id_code(host_axis) : axis_id_code(host_axis);
  const Message m = build_message(o, dest, sender);
  if (o.protocol == "rs232" || o.protocol == "rs485") {
    const Link link = o.protocol == "rs485" ? Link::rs485 : Link::rs232;
    if (const LinkCheck lc = check_host_message(link, m); lc != LinkCheck::ok) throw InputError{to_string(lc)};
  }
  const std::string send = wire_text(o.protocol, m);  // may fail: nothing printed yet
  fmt::print("message:   {}\n", describe(m, o.protocol != "raw"));
  fmt::print("send:      {}\n", send);
  print_expected(o, m);
  return kExitOk;
}

// ---- Decoding ----------------------------------------------------------------------------------

int decode_serial(const Options& o) {
  const auto bytes = parse_hex_bytes(o.input);
  for (std::size_t i = 0; i < bytes.size();) {
    const std::uint8_t b = bytes[i];
    if (b == kAckByte || b == kSyncByte) {
      fmt::print("{:02X}         {}\n", b, b == kAckByte ? "acknowledgement 'O'" : "SYNC");
      ++i;
      continue;
    }
    if (b < kMinLengthByte || b > kMaxLengthByte || b % 2) throw InputError{fmt::format("byte {}: 0x{:02X} is not a length byte, 'O' or SYNC", i, b)};
    const std::size_t n = static_cast<std::size_t>(b) + 2;
    if (i + n > bytes.size()) throw InputError{fmt::format("byte {}: packet of {} bytes, only {} left", i, n, bytes.size() - i)};
    const std::span packet(bytes.data() + i, n);
    Message m;
    if (const PacketStatus st = decode_packet(packet, m); st != PacketStatus::ok) {
      const std::uint8_t want = checksum(packet.first(n - 1));
      throw InputError{st == PacketStatus::bad_checksum
                           ? fmt::format("byte {}: bad checksum 0x{:02X} (sum mod 256 is 0x{:02X})", i + n - 1, packet.back(), want)
                           : fmt::format("byte {}: {}", i, to_string(st))};
    }
    fmt::print("{}\n           {}\n", hex_bytes(packet), describe(m));
    i += n;
  }
  return kExitOk;
}

int decode_can(const Options& o) {
  for (const auto& s : o.input) {
    const can::Frame f = parse_cansend(s);
    if (o.protocol == "tmlcan") {
      Message m;
      if (const CanStatus st = decode_tmlcan(f, m); st != CanStatus::ok) throw InputError{fmt::format("{}: {}", s, to_string(st))};
      fmt::print("{}\n           {}\n", cansend(f), describe(m));
      continue;
    }
    TechCanMessage t;
    if (const CanStatus st = decode_techcan(f, t); st != CanStatus::ok) throw InputError{fmt::format("{}: {}", s, to_string(st))};
    std::string words;
    for (const std::uint16_t w : t.message.words()) words += fmt::format(" {:04X}", w);
    std::string text = t.kind == TechCanKind::pong ? fmt::format("PONG from axis {}, words:{}", t.cob_number, words)
                                                   : describe(t.message, t.destination_known);
    if (!t.destination_known && t.kind != TechCanKind::pong)
      text += fmt::format(", destination not carried (COB-ID axis {})", t.cob_number);
    fmt::print("{}   TechCAN {}\n           {}\n", cansend(f), to_string(t.kind), text);
  }
  return kExitOk;
}

int decode_raw(const Options& o) {
  if (o.input.empty() || o.input.size() > 1 + kMaxDataWords) throw InputError{"raw: give an opcode and 0-4 data words (hex)"};
  Message m;
  m.opcode = static_cast<std::uint16_t>(parse_hex(o.input[0], 0xFFFF, "opcode"));
  for (std::size_t i = 1; i < o.input.size(); ++i) m.data[m.count++] = static_cast<std::uint16_t>(parse_hex(o.input[i], 0xFFFF, "data word"));
  fmt::print("{}\n           {} (the raw form has no ID code)\n", to_string(m).substr(5), describe(m, false));
  return kExitOk;
}

int run_decode(const Options& o) {
  if (o.input.empty()) throw InputError{"nothing to decode"};
  if (o.protocol == "rs232" || o.protocol == "rs485") return decode_serial(o);
  if (o.protocol == "raw") return decode_raw(o);
  return decode_can(o);
}

// ---- Sending -----------------------------------------------------------------------------------

std::int64_t now_ns() { return TmlPty::monotonic_ns(); }

// The serial device raw, 8N2 at the baud rate (a plain serial program's set-up).
int open_serial(const std::string& path, std::uint32_t baud) {
  const int fd = ::open(path.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK);
  if (fd < 0) throw InputError{fmt::format("--port {}: {}", path, std::strerror(errno))};
  termios tio{};
  ::tcgetattr(fd, &tio);
  ::cfmakeraw(&tio);
  tio.c_cflag |= CSTOPB | CLOCAL | CREAD;
  tio.c_cflag &= ~PARENB;
  const speed_t sp = baud == 115200 ? B115200 : baud == 57600 ? B57600 : baud == 38400 ? B38400 : baud == 19200 ? B19200 : B9600;
  ::cfsetispeed(&tio, sp);
  ::cfsetospeed(&tio, sp);
  ::tcsetattr(fd, TCSANOW, &tio);
  return fd;
}

int send_serial(const Options& o, const Message& m) {
  const int fd = open_serial(o.port, o.baud);
  HostLinkConfig cfg;
  const bool rs485 = o.protocol == "rs485";
  cfg.link = rs485 ? Link::rs485 : Link::rs232;
  cfg.baud = o.baud;
  // Across processes and a pseudo-terminal the 'O' takes longer than on a wire: OUR CHOICE.
  cfg.ack_timeout_ns = cfg.sync_timeout_ns = 20'000'000;
  cfg.answer_timeout_ns = static_cast<std::int64_t>(o.timeout_ms * 1e6);
  bool done = false;
  int code = kExitOk;
  SerialHostLink link(cfg, [fd](std::uint8_t b, std::int64_t) { (void)!::write(fd, &b, 1); }, [&](const HostEvent& e) {
    switch (e.kind) {
      case HostEventKind::acked: fmt::print("received:  4F ('O')\n"), done = true; break;
      case HostEventKind::sent_unacknowledged: fmt::print("sent (no acknowledgement on RS-485 for a group or axis 0)\n"), done = true; break;
      case HostEventKind::answer: fmt::print("received:  4F ('O') and {}\n           {}\n", hex_bytes(encode_packet(e.message).view()), describe(e.message)), done = true; break;
      case HostEventKind::answer_timeout: fmt::print("received:  4F ('O'), then no answer\n"), done = true, code = kExitNoAnswer; break;
      // RS-232: a SYNC byte came back; RS-485 drives echo nothing: 15 SYNC bytes, then the resend.
      case HostEventKind::resent: fmt::print("no 'O': {}, command sent again\n", rs485 ? "15 SYNC bytes sent" : "SYNC bytes echoed"); break;
      case HostEventKind::link_broken: fmt::print("link broken: {}\n", rs485 ? "no 'O', nor after 15 SYNC bytes and a resend" : "no 'O' and no SYNC echo"), done = true, code = kExitNoAnswer; break;
      case HostEventKind::unsolicited: fmt::print("unsolicited: {}\n", describe(e.message)); break;
    }
  });
  fmt::print("send:      {}\n", hex_bytes(encode_packet(m).view()));
  if (link.send(m, now_ns()) != SendStatus::ok) throw InputError{"the link refuses this message"};
  const std::int64_t give_up = now_ns() + static_cast<std::int64_t>((o.timeout_ms + 500) * 1e6);
  while (!done && now_ns() < give_up) {
    pollfd p{fd, POLLIN, 0};
    const std::int64_t wait = std::min<std::int64_t>(link.next_deadline() - now_ns(), 10'000'000);
    ::poll(&p, 1, static_cast<int>(std::max<std::int64_t>(0, wait) / 1'000'000));
    std::uint8_t buf[64];
    for (ssize_t n; (n = ::read(fd, buf, sizeof buf)) > 0;)
      for (ssize_t i = 0; i < n; ++i) link.on_byte(buf[i], now_ns());
    link.poll(now_ns());
  }
  ::close(fd);
  if (!done) fmt::print("no answer within {} ms\n", o.timeout_ms), code = kExitNoAnswer;
  return code;
}

// Whether `a` answers the data request `q`: the TakeData of a GiveMeData or the TakeData2 of a
// GiveMeData2, of the same width and address, from the queried axis (any sender for a group or
// axis 0) and, where the frame carries it, to the requester's ID code (q's data 1).
bool answers_query(const Message& q, const Message& a, bool destination_known) {
  const Classified cq = classify(q), ca = classify(a);
  const Kind want = cq.kind == Kind::give_me_data ? Kind::take_data : Kind::take_data2;
  if (ca.kind != want || !ca.complete || ca.wide != cq.wide || ca.address != cq.address) return false;
  // TakeData: data 1 is the sender's ID code; TakeData2: the opcode's low byte is its axis.
  const std::uint8_t sender = want == Kind::take_data ? id_of(ca.sender) : static_cast<std::uint8_t>(ca.sender);
  if (!to_many(q.id_code) && sender != id_of(q.id_code)) return false;
  return !destination_known || a.id_code == cq.sender;
}

int send_can(const Options& o, const Message& m) {
  std::unique_ptr<can::Transport> tr;
  try {
    tr = can::open_transport(o.iface);
  } catch (const can::TransportError& e) {
    throw InputError{fmt::format("--iface {}: {}", o.iface, e.what())};
  }
  can::Frame f;
  const CanStatus st = o.protocol == "tmlcan" ? encode_tmlcan(m, f) : encode_techcan(m, f);
  if (st != CanStatus::ok) throw InputError{to_string(st)};
  fmt::print("send:      {}\n", cansend(f));
  if (!tr->send(f, 0)) return fmt::print("the transport refused the frame\n"), kExitNoAnswer;
  const bool query = classify(m).kind == Kind::give_me_data || classify(m).kind == Kind::give_me_data2;
  int answers = 0, others = 0;
  const auto end = std::chrono::steady_clock::now() + std::chrono::microseconds(static_cast<std::int64_t>(o.timeout_ms * 1e3));
  while (std::chrono::steady_clock::now() < end) {
    auto r = tr->receive();
    if (!r) {
      can::wait_readable(*tr, std::chrono::milliseconds(10));
      continue;
    }
    Message a;
    TechCanMessage t;
    const bool ok = o.protocol == "tmlcan" ? decode_tmlcan(r->frame, a) == CanStatus::ok
                                           : (decode_techcan(r->frame, t) == CanStatus::ok && (a = t.message, true));
    // TMLCAN carries the answer's destination; TechCAN's TakeData/TakeData2 do not.
    if (!ok || !query || !answers_query(m, a, o.protocol == "tmlcan" || t.destination_known)) {
      ++others;  // other traffic on the bus (a running master's answers, other hosts')
      continue;
    }
    fmt::print("received:  {}\n           {}\n", cansend(r->frame), describe(a, o.protocol == "tmlcan"));
    ++answers;
  }
  if (others > 0) fmt::print("({} other frames on the bus meanwhile, not answers to this query)\n", others);
  if (query && answers == 0) return fmt::print("no answer within {} ms\n", o.timeout_ms), kExitNoAnswer;
  return kExitOk;
}

int run_send(const Options& o) {
  const bool serial = o.protocol == "rs232" || o.protocol == "rs485";
  if (o.protocol == "raw") throw InputError{"send needs a line protocol: rs232, rs485, tmlcan or techcan"};
  if (serial ? o.port.empty() : o.iface.empty()) throw InputError{serial ? "send on a serial line needs --port PATH" : "send on CAN needs --iface SPEC"};
  const std::uint16_t dest = destination(o);
  const auto host_axis = static_cast<std::uint8_t>(o.host);
  const Message m = build_message(o, dest, o.protocol == "rs232" ? host_id_code(host_axis) : axis_id_code(host_axis));
  fmt::print("message:   {}\n", describe(m));
  return serial ? send_serial(o, m) : send_can(o, m);
}

// ---- An emulated drive on a pseudo-terminal ----------------------------------------------------------

volatile std::sig_atomic_t g_stop = 0;

int run_drive(const Options& o) {
  if (o.protocol != "rs232" && o.protocol != "rs485") throw InputError{"drive runs on a serial line: rs232 or rs485"};
  if (o.axis < 1 || o.axis > 255 || o.host < 1 || o.host > 255) throw InputError{"--axis and --host take 1-255"};
  DriveSetup ds;
  ds.axis = static_cast<std::uint8_t>(o.axis);
  ds.host_axis = static_cast<std::uint8_t>(o.host);
  ds.protocol = o.protocol == "rs485" ? Protocol::rs485 : Protocol::rs232;
  TmlDrive drive(ds, nullptr);
  TmlPty pty(drive, o.baud);
  drive::AxisModel shaft;  // the drive turns a model shaft (no MuJoCo here)
  // RS-485 multi-drop: more drives on the same line, each with its own shaft.
  if (!o.drops.empty() && o.protocol != "rs485") throw InputError{"--drop needs --protocol rs485 (a multi-drop line)"};
  std::vector<std::unique_ptr<TmlDrive>> drops;
  std::vector<drive::AxisModel> drop_shafts(o.drops.size());
  for (const int a : o.drops) {
    if (a < 1 || a > 255 || a == o.axis) throw InputError{fmt::format("--drop {}: an axis ID 1-255 other than --axis", a)};
    DriveSetup d = ds;
    d.axis = static_cast<std::uint8_t>(a);
    drops.push_back(std::make_unique<TmlDrive>(d, nullptr));
    pty.add_drop(*drops.back());
    drops.back()->power_on(0);
  }
  // The relay axis: messages for other axes onto CAN, the answers for the host back.
  std::unique_ptr<can::Transport> bus;
  std::unique_ptr<TmlRelay> relay;
  if (!o.relay.empty()) {
    try {
      bus = can::open_transport(o.relay);
    } catch (const can::TransportError& e) {
      throw InputError{fmt::format("--relay {}: {}", o.relay, e.what())};
    }
    relay = std::make_unique<TmlRelay>(
        drive, o.relay_protocol == "techcan" ? Protocol::techcan : Protocol::tmlcan,
        [&bus](const can::Frame& f, SimTime) { return bus->send(f, 0); },
        [&pty](const Message& m, SimTime t) { pty.to_host(m, t); });
    pty.set_host_sink([&relay](const Message& m, std::int64_t t) { relay->from_host(m, t); });
  }
  std::signal(SIGINT, [](int) { g_stop = 1; });
  std::signal(SIGTERM, [](int) { g_stop = 1; });
  const std::int64_t t0 = now_ns(), period = static_cast<std::int64_t>(ds.sample_period_s * 1e9);
  drive.power_on(0);
  std::string more;
  for (const int a : o.drops) more += fmt::format(", {}", a);
  fmt::print("omni-tml: drive axis {}{} ({}, 8N2 at {} bit/s) on {}{} ({})\n", o.axis, more, o.protocol, o.baud,
             pty.slave_path(), bus ? fmt::format(", relay axis to {} on {}", o.relay_protocol, bus->spec()) : "",
             o.duration < 0 ? std::string("Ctrl-C ends") : fmt::format("ends after {:g} s, or Ctrl-C", o.duration));
  std::fflush(stdout);
  std::int64_t next = t0;
  while (!g_stop && (o.duration < 0 || now_ns() - t0 < static_cast<std::int64_t>(o.duration * 1e9))) {
    const std::int64_t now = now_ns();
    pty.service(now);
    if (bus)
      while (auto r = bus->receive()) relay->from_can(r->frame, now - t0);
    if (now >= next) {
      const drive::Command c = drive.step(now - t0, shaft.feedback());
      shaft.step(c, ds.sample_period_s);
      for (std::size_t k = 0; k < drops.size(); ++k)
        drop_shafts[k].step(drops[k]->step(now - t0, drop_shafts[k].feedback()), ds.sample_period_s);
      next += period;
      continue;
    }
    pty.wait(now, std::min({next, pty.next_due(), bus ? now + 200'000 : next}) - now);  // the CAN side: polled every 0.2 ms
  }
  // Each drive on the line its own counts, and the relay what it carried (they were missing:
  // a relayed or multi-drop exchange ended "0 messages handled"; found in a docs walkthrough).
  const DriveStats& s = drive.stats();
  fmt::print("omni-tml: drive end: {} messages handled, {} answers, {} checksum errors\n", s.handled, s.answers_sent,
             pty.checksum_errors());
  for (std::size_t k = 0; k < drops.size(); ++k)
    fmt::print("omni-tml: drive end, axis {} (drop): {} messages handled, {} answers\n", o.drops[k],
               drops[k]->stats().handled, drops[k]->stats().answers_sent);
  if (relay)
    fmt::print("omni-tml: relay end: {} messages onto CAN, {} answers back to the host\n", relay->stats().to_can,
               relay->stats().to_host);
  return kExitOk;
}

void add_common(CLI::App* sub, Options& o) {
  sub->add_option("--protocol,-p", o.protocol, "rs232, rs485, tmlcan, techcan or raw")
      ->check(CLI::IsMember({"rs232", "rs485", "tmlcan", "techcan", "raw"}))
      ->capture_default_str();
}

// --baud: only the rates open_serial() and the pty set (found in review: 0 aborted in the line
// timing, any other rate opened the port at 9600 while printing the rate asked for).
void add_baud(CLI::App* sub, Options& o) {
  sub->add_option("--baud", o.baud, "serial bit rate (9600, 19200, 38400, 57600, 115200)")
      ->check(CLI::IsMember(std::vector<std::uint32_t>{9600, 19200, 38400, 57600, 115200}))
      ->capture_default_str();
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"omni-tml: the Technosoft TML Binary Code Viewer (seed 003) on the command line"};
  app.require_subcommand(1);
  Options o;
  CLI::App* enc = app.add_subcommand("encode", "bytes to send for a TML instruction, and the expected answer");
  add_common(enc, o);
  enc->add_option("--axis,-a", o.axis, "destination axis ID 0-255 (with --group: group number 1-8, 0 = broadcast)")->capture_default_str();
  enc->add_option("--host", o.host, "the host's axis ID (RS-232: the relay drive's, HOST bit set)")->capture_default_str();
  enc->add_flag("--group,-g", o.group, "--axis is a group number");
  enc->add_flag("--raw", o.raw, "the instruction is OPCODE [DATA...] in hex");
  enc->add_option("--value", o.value, "query: the value the drive returns (hex), to show the whole answer");
  enc->add_option("--from", o.from, "group query: the member axis whose answer to show");
  enc->add_option("INSTRUCTION", o.input, "'NAME=VALUE', '?NAME', '??NAME' (or with --raw: OPCODE DATA...)")->required();
  CLI::App* dec = app.add_subcommand("decode", "a received packet or frame in words");
  add_common(dec, o);
  dec->add_option("INPUT", o.input, "serial: hex bytes; tmlcan/techcan: ID#DATA; raw: hex words")->required();
  CLI::App* send = app.add_subcommand("send", "send an instruction to a drive and print its answer");
  add_common(send, o);
  send->add_option("--port", o.port, "rs232/rs485: the serial device (e.g. the path omni-tml drive prints)");
  send->add_option("--iface", o.iface, "tmlcan/techcan: the CAN transport (udp:GROUP:PORT, socketcan:IFACE)");
  add_baud(send, o);
  send->add_option("--axis,-a", o.axis, "destination axis ID (with --group: group number)")->capture_default_str();
  send->add_option("--host", o.host, "the host's axis ID")->capture_default_str();
  send->add_flag("--group,-g", o.group, "--axis is a group number");
  send->add_flag("--raw", o.raw, "the instruction is OPCODE [DATA...] in hex");
  send->add_option("--timeout-ms", o.timeout_ms, "how long to wait for answers")
      ->check(controller::time_check(controller::kMaxRunSeconds * 1e3))
      ->capture_default_str();
  send->add_option("INSTRUCTION", o.input, "'NAME=VALUE', '?NAME', '??NAME' (or with --raw: OPCODE DATA...)")->required();
  CLI::App* drv = app.add_subcommand("drive", "run one emulated IDM drive on a pseudo-terminal");
  add_common(drv, o);
  drv->add_option("--axis,-a", o.axis, "the drive's axis ID")->capture_default_str();
  drv->add_option("--host", o.host, "the host's axis ID")->capture_default_str();
  add_baud(drv, o);
  drv->add_option("--duration", o.duration, "seconds (default: until Ctrl-C)")
      ->check(controller::time_check(controller::kMaxRunSeconds));
  drv->add_option("--drop", o.drops, "RS-485: more drives on the same line (axis IDs)");
  drv->add_option("--relay", o.relay, "be the relay axis: forward other axes' messages to this CAN transport");
  drv->add_option("--relay-protocol", o.relay_protocol, "the relay's CAN protocol: tmlcan or techcan")
      ->check(CLI::IsMember({"tmlcan", "techcan"}))
      ->capture_default_str();
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "omni-tml: " << e.what() << "\n";
    return kExitUsage;
  }
  try {
    if (send->parsed()) return run_send(o);
    if (drv->parsed()) return run_drive(o);
    return enc->parsed() ? run_encode(o) : run_decode(o);
  } catch (const InputError& e) {
    std::cerr << "omni-tml: " << e.what << "\n";
    return kExitUsage;
  }
}
