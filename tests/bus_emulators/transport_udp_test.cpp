// Tests bus_emulators/can/transport_udp: spec parsing, exchange over IPv4 and IPv6 multicast
// on this host, group isolation, own-frame suppression, bad datagrams counted (never a
// crash), batched sends (segmented) and receives (several per call) giving the very same
// datagrams in order, own datagrams dropped in the kernel, and interoperability with python-can's own `udp_multicast` interface (Debian's
// python3-can, run with /usr/bin/python3) in both directions.
//
// Parallel safety: every test process uses its own port, reserved from the kernel's
// ephemeral range for the life of the test, and groups derived from its pid, so that tests
// running at the same time never hear each other (python-can binds ("", PORT) and hears every
// group on its port, so the port is what must differ).
#include "bus_emulators/can/can_msgpack.hpp"
#include "bus_emulators/can/transport.hpp"
#include "bus_emulators/can/transport_udp.hpp"

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#ifndef OMNITWIN_SOURCE_DIR
#error "OMNITWIN_SOURCE_DIR must be defined (tests/CMakeLists.txt does it through omnitwin_test_support)"
#endif

namespace omnitwin::can {
namespace {

using namespace std::chrono_literals;

// Holds a UDP port from the kernel's ephemeral range (bound on 127.0.0.1 with SO_REUSEADDR,
// so our multicast sockets can share it) so that no concurrent test is handed the same one.
class ReservedPort {
 public:
  ReservedPort() {
    fd_ = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    const int one = 1;
    ::setsockopt(fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0) {
      socklen_t len = sizeof a;
      ::getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len);
      port_ = ntohs(a.sin_port);
    }
  }
  ~ReservedPort() { ::close(fd_); }
  ReservedPort(const ReservedPort&) = delete;
  ReservedPort& operator=(const ReservedPort&) = delete;
  int port() const { return port_; }

 private:
  int fd_ = -1;
  int port_ = 0;
};

// 239.255.X.Y / ff15::6f74:X:Y from the pid and a per-test salt.
std::string group_v4(int salt = 0) {
  const unsigned p = static_cast<unsigned>(::getpid());
  return "239." + std::to_string(200 + (salt % 50)) + "." + std::to_string((p >> 8) & 0xFF) + "." + std::to_string(p & 0xFF);
}
std::string group_v6(int salt = 0) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "ff15::6f74:%x:%x", salt, static_cast<unsigned>(::getpid()) & 0xFFFFF);
  return buf;
}
std::string spec_v4(const std::string& g, int port, const std::string& opts = "") {
  return "udp:" + g + ":" + std::to_string(port) + opts;
}
std::string spec_v6(const std::string& g, int port, const std::string& opts = "") {
  return "udp:[" + g + "]:" + std::to_string(port) + opts;
}

std::vector<Frame> sample_frames() {
  Frame err;
  err.kind = FrameKind::error;
  err.id = 0x004;
  err.dlc = 8;
  err.data = {0, 0x10, 0, 0, 0, 0, 0, 0};
  return {make_data(0x000, {0x02, 0x00}), make_data(0x701, {0x05}), make_data(0x1ABCDEF0, {1, 2, 3, 4, 5, 6, 7, 8}, true),
          make_remote(0x181, 8), make_remote(0x18FF00AA, 0, true), make_data(0x7FF, {}), err};
}

// ---- spec parsing ------------------------------------------------------------------------

TEST(UdpTransportSpec, ParsesGroupsPortsAndOptions) {
  auto t = parse_transport_spec("udp:239.74.163.2:43113");
  EXPECT_EQ(t.kind, TransportSpec::Kind::udp);
  EXPECT_EQ(t.name, "239.74.163.2");
  EXPECT_EQ(t.port, 43113);
  EXPECT_FALSE(t.ipv6);
  EXPECT_EQ(t.ttl, 1);
  t = parse_transport_spec("udp:239.1.2.3");
  EXPECT_EQ(t.port, kPythonCanUdpPort);
  t = parse_transport_spec("udp:[ff15:7079:7468:6f6e:6465:6d6f:6d63:6173]:5000?ttl=4&iface=lo&own=1");
  EXPECT_TRUE(t.ipv6);
  EXPECT_EQ(t.name, "ff15:7079:7468:6f6e:6465:6d6f:6d63:6173");
  EXPECT_EQ(t.port, 5000);
  EXPECT_EQ(t.ttl, 4);
  EXPECT_EQ(t.iface, "lo");
  EXPECT_TRUE(t.receive_own);
  t = parse_transport_spec("udp:");
  EXPECT_EQ(t.name, kPythonCanGroupV6);  // python-can's default channel
  EXPECT_EQ(t.port, kPythonCanUdpPort);
}

TEST(UdpTransportSpec, RejectsBadSpecsWithAReason) {
  for (const char* bad : {"udp:10.0.0.1:43113", "udp:239.1.2.3:65536", "udp:239.1.2.3:x",
                          "udp:239.1.2.3:", "udp:[ff15::1", "udp:[fe80::1]:1", "udp:ff15::1:43113",
                          "udp:example.org:1", "udp:239.1.2.3:1?ttl=300", "udp:239.1.2.3:1?color=red",
                          "udp:239.1.2.3:1?ttl", "udp:[ff15::1]x"}) {
    try {
      parse_transport_spec(bad);
      ADD_FAILURE() << bad << " was accepted";
    } catch (const TransportError& e) {
      EXPECT_NE(std::string(e.what()).find("bad CAN transport spec"), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(open_transport("udp:239.1.2.3:1?iface=nosuchif0"), TransportError);
}

// ---- our transport against itself -------------------------------------------------------

void exchange(const std::string& spec) {
  auto a = open_transport(spec);
  auto b = open_transport(spec);
  EXPECT_FALSE(wait_readable(*b, 0ms));
  const auto frames = sample_frames();
  for (std::size_t i = 0; i < frames.size(); ++i) ASSERT_TRUE(a->send(frames[i], 1'000'000'000LL * static_cast<std::int64_t>(i) + 250));
  for (std::size_t i = 0; i < frames.size(); ++i) {
    auto r = receive_within(*b, 2s);
    ASSERT_TRUE(r) << "frame " << i << " did not arrive on " << spec;
    EXPECT_EQ(r->frame, frames[i]) << to_string(r->frame);
    EXPECT_EQ(r->timestamp_ns, 1'000'000'000LL * static_cast<std::int64_t>(i) + 250);
  }
  // The sender does not hear itself.
  EXPECT_FALSE(receive_within(*a, 50ms));
  EXPECT_EQ(a->stats().frames_tx, frames.size());
  EXPECT_EQ(b->stats().frames_rx, frames.size());
  EXPECT_EQ(a->stats().frames_rx, 0u);
}

TEST(UdpTransport, ExchangesEveryFrameKindOverIpv4) {
  ReservedPort port;
  exchange(spec_v4(group_v4(1), port.port()));
}

TEST(UdpTransport, ExchangesEveryFrameKindOverIpv6) {
  ReservedPort port;
  exchange(spec_v6(group_v6(1), port.port()));
}

TEST(UdpTransport, OwnFramesOnlyWithOwnOption) {
  ReservedPort port;
  auto t = open_transport(spec_v4(group_v4(2), port.port(), "?own=1"));
  ASSERT_TRUE(t->send(make_data(0x123, {9})));
  auto r = receive_within(*t, 2s);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->frame, make_data(0x123, {9}));
  EXPECT_EQ(t->spec(), spec_v4(group_v4(2), port.port(), "?own=1"));
}

// Port 0: each transport gets a free port of its own, spec() names it, and a second
// transport opened with that spec shares the bus (the master joins the twin's port), while
// one opened on port 0 again does not hear it (isolation of concurrent lockstep runs).
TEST(UdpTransport, PortZeroIsAFreePortOfItsOwnThatOthersCanJoin) {
  auto a = open_transport(spec_v4(group_v4(3), 0));
  auto b = open_transport(spec_v4(group_v4(3), 0));
  const std::string named = a->spec();
  ASSERT_TRUE(named.starts_with("udp:" + group_v4(3) + ":")) << named;
  EXPECT_NE(named, spec_v4(group_v4(3), 0));
  EXPECT_NE(named, b->spec());
  auto joined = open_transport(named);
  ASSERT_TRUE(joined->send(make_data(0x102, {7})));
  auto r = receive_within(*a, 2s);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->frame, make_data(0x102, {7}));
  EXPECT_FALSE(receive_within(*b, 200ms));
}

// A frame train with runs of equal-size datagrams, shorter ones closing runs, longer ones
// starting new runs, and one invalid frame in the middle (refused and counted, as by send()).
std::vector<Frame> train(std::size_t n) {
  std::vector<Frame> out;
  for (std::size_t i = 0; i < n; ++i) {
    const auto k = static_cast<std::uint8_t>(i);
    switch (i % 7) {
      case 0:
      case 1:
      case 2: out.push_back(make_data(0x202 + (i % 3), {k, 1, 2, 3, 4, 5})); break;  // equal sizes
      case 3: out.push_back(make_remote(0x004, 0)); break;                          // shorter
      case 4: out.push_back(make_data(0x1ABCDEF0, {k, 1, 2, 3, 4, 5, 6, 7}, true)); break;  // longer
      case 5: out.push_back(make_data(0x102, {k})); break;
      default: out.push_back(make_data(0x102, {k})); break;
    }
  }
  return out;
}

// Joins `group`:`port` with a plain socket, to see the datagrams exactly as they travel.
class RawListener {
 public:
  RawListener(const std::string& group, int port) {
    fd_ = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    const int one = 1, zero = 0;
    ::setsockopt(fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    ::setsockopt(fd_, IPPROTO_IP, IP_MULTICAST_ALL, &zero, sizeof zero);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    ::inet_pton(AF_INET, group.c_str(), &a.sin_addr);
    EXPECT_EQ(::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    ip_mreqn m{};
    m.imr_multiaddr = a.sin_addr;
    EXPECT_EQ(::setsockopt(fd_, IPPROTO_IP, IP_ADD_MEMBERSHIP, &m, sizeof m), 0);
    const timeval tv{2, 0};
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  }
  ~RawListener() { ::close(fd_); }
  RawListener(const RawListener&) = delete;
  RawListener& operator=(const RawListener&) = delete;
  std::vector<std::uint8_t> next() {
    std::vector<std::uint8_t> b(5000);
    const ssize_t n = ::recv(fd_, b.data(), b.size(), 0);
    b.resize(n > 0 ? static_cast<std::size_t>(n) : 0);
    return b;
  }

 private:
  int fd_ = -1;
};

TEST(UdpTransport, SendManyPutsTheSameDatagramsOnTheWireAsSend) {
  ReservedPort port;
  const std::string group = group_v4(8);
  UdpTransport tx(parse_transport_spec(spec_v4(group, port.port())));
  RawListener raw(group, port.port());
  auto frames = train(40);
  Frame bad = make_data(1, {});
  bad.dlc = 9;  // invalid: refused, not sent
  std::vector<TimedFrame> batch;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    batch.push_back(TimedFrame{frames[i], 1'000'000'000LL + static_cast<std::int64_t>(i) * 1000});
    if (i == 17) batch.push_back(TimedFrame{bad, 0});
  }
  EXPECT_EQ(tx.send_many(batch), frames.size());
  EXPECT_EQ(tx.stats().frames_tx, frames.size());
  EXPECT_EQ(tx.stats().invalid_tx, 1u);
  // (segmented_sends() stays true on Linux >= 4.18 with a device that offloads checksums, or
  // lo; elsewhere the same datagrams go out one by one.)
  if (!tx.segmented_sends()) std::printf("note: this host refused segmented UDP sends\n");
  for (const TimedFrame& tf : batch) {
    if (tf.frame == bad) continue;
    EXPECT_EQ(raw.next(), msgpack_wire::encode(tf.frame, static_cast<double>(tf.timestamp_ns) * 1e-9))
        << to_string(tf.frame);
  }
}

TEST(UdpTransport, BurstsArriveWholeAndInOrder) {
  // More datagrams than one segmented send carries and one receive call fetches.
  for (const bool ipv6 : {false, true}) {
    ReservedPort port;
    const std::string spec = ipv6 ? spec_v6(group_v6(9), port.port()) : spec_v4(group_v4(9), port.port());
    auto a = open_transport(spec);
    auto b = open_transport(spec);
    const auto frames = train(150);
    std::vector<TimedFrame> batch;
    for (std::size_t i = 0; i < frames.size(); ++i) batch.push_back(TimedFrame{frames[i], static_cast<std::int64_t>(i) * 1000});
    ASSERT_EQ(a->send_many(batch), frames.size()) << spec;
    for (std::size_t i = 0; i < frames.size(); ++i) {
      auto r = receive_within(*b, 2s);
      ASSERT_TRUE(r) << "frame " << i << " did not arrive on " << spec;
      EXPECT_EQ(r->frame, frames[i]) << i;
      EXPECT_EQ(r->timestamp_ns, static_cast<std::int64_t>(i) * 1000);
    }
    EXPECT_FALSE(receive_within(*b, 20ms));
    EXPECT_FALSE(receive_within(*a, 20ms));  // none of its own
  }
}

TEST(UdpTransport, OwnDatagramsNeverReachTheReceiveSocket) {
  for (const bool ipv6 : {false, true}) {
    ReservedPort port;
    const std::string spec = ipv6 ? spec_v6(group_v6(10), port.port()) : spec_v4(group_v4(10), port.port());
    UdpTransport a(parse_transport_spec(spec));
    auto b = open_transport(spec);
    EXPECT_TRUE(a.kernel_drops_own()) << spec;
    for (int i = 0; i < 5; ++i) ASSERT_TRUE(a.send(make_data(0x100, {static_cast<std::uint8_t>(i)})));
    ASSERT_TRUE(receive_within(*b, 2s));  // the others hear them…
    EXPECT_FALSE(wait_readable(a, 50ms)) << spec;  // …the kernel kept them from the sender
    ASSERT_TRUE(b->send(make_data(0x200, {1})));  // and what others send still arrives
    auto r = receive_within(a, 2s);
    ASSERT_TRUE(r) << spec;
    EXPECT_EQ(r->frame, make_data(0x200, {1}));
    // own=1 installs no filter: the sender hears itself.
    UdpTransport own(parse_transport_spec(spec + "?own=1"));
    EXPECT_FALSE(own.kernel_drops_own());
  }
}

TEST(UdpTransport, GroupsOnOnePortDoNotHearEachOther) {
  ReservedPort port;
  auto a = open_transport(spec_v4(group_v4(3), port.port()));
  auto b = open_transport(spec_v4(group_v4(4), port.port()));
  auto a2 = open_transport(spec_v4(group_v4(3), port.port()));
  ASSERT_TRUE(a->send(make_data(0x100, {1})));
  auto r = receive_within(*a2, 2s);
  ASSERT_TRUE(r);  // same group: delivered
  EXPECT_FALSE(receive_within(*b, 100ms));  // other group: never
  EXPECT_EQ(b->stats().frames_rx + b->stats().malformed_rx, 0u);
}

TEST(UdpTransport, BadDatagramsAreCountedAndSkipped) {
  ReservedPort port;
  const std::string spec = spec_v4(group_v4(5), port.port());
  UdpTransport tx(parse_transport_spec(spec));
  auto rx = open_transport(spec);
  auto raw = [&](std::vector<std::uint8_t> b) { ASSERT_TRUE(tx.send_raw(b.data(), b.size())); };
  // Re-encodes f with the value byte after `key` replaced (python-can's encodings of
  // dlc, is_* and small identifiers are single bytes).
  auto patched = [](const Frame& f, const std::string& key, std::size_t offset, std::uint8_t value) {
    auto b = msgpack_wire::encode(f, 0.0);
    std::vector<std::uint8_t> k{static_cast<std::uint8_t>(0xa0 | key.size())};
    k.insert(k.end(), key.begin(), key.end());
    const auto it = std::search(b.begin(), b.end(), k.begin(), k.end());
    EXPECT_NE(it, b.end()) << key;
    if (it != b.end()) *(it + static_cast<std::ptrdiff_t>(k.size() + offset)) = value;
    return b;
  };
  raw({0xde, 0xad, 0xbe, 0xef});                                // not msgpack
  raw({0x93, 0x01, 0x02, 0x03});                                // msgpack, not a map
  raw(std::vector<std::uint8_t>(5000, 0x80));                   // larger than python-can reads
  raw(patched(make_data(0x10, {1, 2}), "dlc", 0, 0x05));             // dlc 5, 2 data bytes
  raw(patched(make_data(0x10, {1, 2}), "dlc", 0, 0x09));             // dlc 9
  raw(patched(make_data(0x10, {1, 2}), "is_extended_id", 0, 0xc2));  // unchanged: still valid
  raw(patched(make_data(0x7FF, {}), "arbitration_id", 1, 0x08));     // cd 07 ff -> cd 08 ff: id too big
  raw(patched(make_data(0x10, {}), "is_fd", 0, 0xc3));               // a CAN FD frame
  ASSERT_TRUE(tx.send(make_data(0x42, {4, 2})));                // and a good one last

  std::vector<Frame> got;
  const auto deadline = std::chrono::steady_clock::now() + 2s;
  while (got.size() < 2 && std::chrono::steady_clock::now() < deadline) {
    if (auto r = rx->receive()) got.push_back(r->frame);
    else wait_readable(*rx, 100ms);
  }
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0], make_data(0x10, {1, 2}));
  EXPECT_EQ(got[1], make_data(0x42, {4, 2}));
  const TransportStats s = rx->stats();
  EXPECT_EQ(s.malformed_rx, 3u);
  EXPECT_EQ(s.wrong_dlc_rx, 2u);
  EXPECT_EQ(s.bad_id_rx, 1u);
  EXPECT_EQ(s.unsupported_rx, 1u);
  EXPECT_EQ(s.frames_rx, 2u);

  // Invalid frames are refused at send and counted.
  Frame bad = make_data(1, {});
  bad.dlc = 9;
  EXPECT_FALSE(tx.send(bad));
  EXPECT_EQ(tx.stats().invalid_tx, 1u);
}

// ---- python-can interop ------------------------------------------------------------------

const char* kPython = "/usr/bin/python3";

bool python_can_available(std::string& why) {
  if (::access(kPython, X_OK) != 0) {
    why = "/usr/bin/python3 is missing";
    return false;
  }
  const std::string cmd = std::string(kPython) +
                          " -c 'import can, msgpack; from can.interfaces.udp_multicast import UdpMulticastBus' >/dev/null 2>&1";
  if (std::system(cmd.c_str()) != 0) {
    why = "python3-can (with python3-msgpack) is not installed for /usr/bin/python3 (apt-get install python3-can python3-msgpack)";
    return false;
  }
  return true;
}

std::string script() { return std::string(OMNITWIN_SOURCE_DIR) + "/tests/data/can/python_can_udp.py"; }

// python-can's print format for a frame (see python_can_udp.py).
std::string python_line(const Frame& f) {
  char id[16];
  std::snprintf(id, sizeof id, "%x", f.id);
  std::string data;
  for (int i = 0; i < (f.kind == FrameKind::remote ? 0 : f.dlc); ++i) {
    char b[3];
    std::snprintf(b, sizeof b, "%02x", f.data[static_cast<std::size_t>(i)]);
    data += b;
  }
  return std::string("RX id=") + id + " ext=" + (f.extended ? "1" : "0") + " rtr=" + (f.kind == FrameKind::remote ? "1" : "0") +
         " err=" + (f.kind == FrameKind::error ? "1" : "0") + " fd=0 dlc=" + std::to_string(f.dlc) + " data=" + data;
}

std::string python_arg(const Frame& f) {
  char id[16];
  std::snprintf(id, sizeof id, "%x", f.id);
  std::string flags = std::string(f.extended ? "x" : "") + (f.kind == FrameKind::remote ? "r" : "") + (f.kind == FrameKind::error ? "e" : "");
  std::string data;
  for (int i = 0; i < (f.kind == FrameKind::remote ? 0 : f.dlc); ++i) {
    char b[3];
    std::snprintf(b, sizeof b, "%02x", f.data[static_cast<std::size_t>(i)]);
    data += b;
  }
  return std::string(id) + ":" + flags + ":" + std::to_string(f.dlc) + ":" + data;
}

struct Child {
  FILE* pipe = nullptr;
  ~Child() {
    if (pipe) ::pclose(pipe);
  }
  std::string line() {
    char buf[512];
    if (!pipe || !std::fgets(buf, sizeof buf, pipe)) return {};
    std::string s(buf);
    while (!s.empty() && (s.back() == '\n' || s.back() == '\r')) s.pop_back();
    return s;
  }
  int close() {
    const int st = ::pclose(pipe);
    pipe = nullptr;
    return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  }
};

void python_receives(const std::string& group, const std::string& our_spec, int port, bool batched = false) {
  std::string why;
  if (!python_can_available(why)) GTEST_SKIP() << "skipped: " << why;
  auto frames = sample_frames();
  if (batched) {  // runs of equal-size datagrams too, as segmented sends carry them
    const auto more = train(20);
    frames.insert(frames.end(), more.begin(), more.end());
  }
  Child py;
  const std::string cmd = std::string(kPython) + " " + script() + " recv " + group + " " + std::to_string(port) + " " +
                          std::to_string(frames.size()) + " 10 2>&1";
  py.pipe = ::popen(cmd.c_str(), "r");
  ASSERT_NE(py.pipe, nullptr);
  const std::string ready = py.line();
  ASSERT_EQ(ready, "READY") << "python-can did not start: " << ready;
  auto t = open_transport(our_spec);
  if (batched) {
    std::vector<TimedFrame> batch;
    for (const Frame& f : frames) batch.push_back(TimedFrame{f, 5'000'000'000LL});
    ASSERT_EQ(t->send_many(batch), frames.size());
  } else {
    for (const Frame& f : frames) ASSERT_TRUE(t->send(f, 5'000'000'000LL));
  }
  for (const Frame& f : frames) EXPECT_EQ(py.line(), python_line(f));
  EXPECT_EQ(py.close(), 0);
}

void python_sends(const std::string& group, const std::string& our_spec, int port) {
  std::string why;
  if (!python_can_available(why)) GTEST_SKIP() << "skipped: " << why;
  auto t = open_transport(our_spec);  // joined before python sends
  const auto frames = sample_frames();
  std::string cmd = std::string(kPython) + " " + script() + " send " + group + " " + std::to_string(port);
  for (const Frame& f : frames) cmd += " " + python_arg(f);
  cmd += " 2>&1";
  Child py;
  py.pipe = ::popen(cmd.c_str(), "r");
  ASSERT_NE(py.pipe, nullptr);
  std::string out, l;
  while (!(l = py.line()).empty()) out += l + "\n";
  ASSERT_EQ(py.close(), 0) << out;
  EXPECT_EQ(out, "SENT " + std::to_string(frames.size()) + "\n");
  const auto now_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count();
  for (const Frame& f : frames) {
    auto r = receive_within(*t, 5s);
    ASSERT_TRUE(r) << "no frame from python-can; expected " << to_string(f);
    EXPECT_EQ(r->frame, f) << to_string(r->frame);
    if (f.kind == FrameKind::error) {
      EXPECT_EQ(r->frame.data, f.data);
    }
    EXPECT_NEAR(static_cast<double>(r->timestamp_ns), static_cast<double>(now_ns), 60e9);  // python stamped time.time()
  }
  const TransportStats s = t->stats();
  EXPECT_EQ(s.malformed_rx + s.wrong_dlc_rx + s.bad_id_rx + s.unsupported_rx, 0u);
}

TEST(UdpPythonCanInterop, PythonCanReceivesOurFramesIpv4) {
  ReservedPort port;
  python_receives(group_v4(6), spec_v4(group_v4(6), port.port()), port.port());
}

TEST(UdpPythonCanInterop, PythonCanReceivesOurFramesIpv6) {
  ReservedPort port;
  python_receives(group_v6(6), spec_v6(group_v6(6), port.port()), port.port());
}

TEST(UdpPythonCanInterop, PythonCanReceivesOurBatchedFramesIpv4) {
  ReservedPort port;
  python_receives(group_v4(11), spec_v4(group_v4(11), port.port()), port.port(), true);
}

TEST(UdpPythonCanInterop, PythonCanReceivesOurBatchedFramesIpv6) {
  ReservedPort port;
  python_receives(group_v6(11), spec_v6(group_v6(11), port.port()), port.port(), true);
}

TEST(UdpPythonCanInterop, WeReceivePythonCanFramesExactlyIpv4) {
  ReservedPort port;
  python_sends(group_v4(7), spec_v4(group_v4(7), port.port()), port.port());
}

TEST(UdpPythonCanInterop, WeReceivePythonCanFramesExactlyIpv6) {
  ReservedPort port;
  python_sends(group_v6(7), spec_v6(group_v6(7), port.port()), port.port());
}

}  // namespace
}  // namespace omnitwin::can
