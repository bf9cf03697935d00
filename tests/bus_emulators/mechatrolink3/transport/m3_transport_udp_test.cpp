// Tests bus_emulators/mechatrolink3/transport/m3_transport_udp: M-III over UDP on loopback with
// the slaves on a free port (port 0): the datagram is exactly the frame (no padding), the master
// sends from an ephemeral port to HOST:PORT and the slaves answer the sender of the last frame;
// a corrupted-FCS frame passes untouched; datagrams that cannot be a frame are dropped and
// counted, trailing bytes trimmed; send errors are counted, set-up errors name the spec; a
// frame's age (the kernel's receive stamp) says how long it waited before receive().
#include "bus_emulators/mechatrolink3/transport/m3_transport_udp.hpp"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <memory>
#include <thread>
#include <vector>

#include "tests/support/receive_stamps.hpp"

namespace omnitwin::m3 {
namespace {

using namespace std::chrono_literals;

std::vector<std::uint8_t> frame_of(FrameType type, std::uint8_t dst, std::uint8_t src, std::size_t n) {
  std::vector<std::uint8_t> data(n);
  for (std::size_t i = 0; i < n; ++i) data[i] = static_cast<std::uint8_t>(3 * i + 1);
  std::vector<std::uint8_t> out(kMaxFrame);
  out.resize(encode(FrameSpec{.dst = dst, .src = src, .type = type, .data = data}, out));
  EXPECT_GT(out.size(), 0u);
  return out;
}
std::vector<std::uint8_t> command(std::size_t n = 32) {
  return frame_of(FrameType::cyclic_command, kFirstSlave, kC1Master, n);
}

std::unique_ptr<UdpTransport> open_udp(const std::string& spec, Role role) {
  return std::make_unique<UdpTransport>(parse_transport_spec(spec), role);
}

// A slaves end on a free loopback port and a master sending to it.
struct Segment {
  std::unique_ptr<UdpTransport> slaves = open_udp("udp:127.0.0.1:0", Role::slaves);
  std::unique_ptr<UdpTransport> master = open_udp(slaves->spec(), Role::master);
};

// A plain UDP socket (the test's own sender of odd datagrams) bound to an ephemeral port.
class PlainUdp {
 public:
  PlainUdp() : fd_(::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0)) {}
  ~PlainUdp() { ::close(fd_); }
  bool send_to(std::uint16_t port, const std::vector<std::uint8_t>& d) const {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    return ::sendto(fd_, d.data(), d.size(), 0, reinterpret_cast<sockaddr*>(&a), sizeof a) ==
           static_cast<ssize_t>(d.size());
  }
  // The next datagram within a second, or an empty vector.
  std::vector<std::uint8_t> next() const {
    timeval tv{1, 0};
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    std::vector<std::uint8_t> b(2048);
    const ssize_t n = ::recv(fd_, b.data(), b.size(), 0);
    b.resize(n > 0 ? static_cast<std::size_t>(n) : 0);
    return b;
  }

 private:
  int fd_;
};

TEST(M3UdpTransport, MasterAndSlavesExchangeOnLoopback) {
  Segment s;
  EXPECT_NE(s.slaves->local_port(), 0);
  EXPECT_NE(s.master->local_port(), s.slaves->local_port());
  EXPECT_NE(s.master->local_port(), 0);
  const auto cmd = command();
  ASSERT_TRUE(s.master->send(cmd));
  std::array<std::uint8_t, kMaxFrame> buf{};
  ASSERT_EQ(s.slaves->receive(buf, 1s), static_cast<int>(cmd.size()));
  EXPECT_TRUE(std::equal(cmd.begin(), cmd.end(), buf.begin()));

  const auto rsp = frame_of(FrameType::cyclic_response, kC1Master, kFirstSlave, 32);
  ASSERT_TRUE(s.slaves->send(rsp));
  ASSERT_EQ(s.master->receive(buf, 1s), static_cast<int>(rsp.size()));
  EXPECT_TRUE(std::equal(rsp.begin(), rsp.end(), buf.begin()));
  EXPECT_EQ(s.master->receive(buf, 0ns), 0);
  EXPECT_EQ(s.master->stats().sent, 1u);
  EXPECT_EQ(s.master->stats().received, 1u);
  EXPECT_EQ(s.slaves->stats().sent, 1u);
  EXPECT_EQ(s.slaves->stats().received, 1u);
}

TEST(M3UdpTransport, AFramesAgeIsHowLongItWaitedBeforeReceive) {
  Segment s;
  ASSERT_TRUE(omnitwin::testing::wait_for_receive_stamps(*s.master, *s.slaves, command()));
  ASSERT_TRUE(s.master->send(command()));
  std::this_thread::sleep_for(20ms);
  std::array<std::uint8_t, kMaxFrame> buf{};
  ASSERT_GT(s.slaves->receive(buf, 1s), 0);
  EXPECT_GE(s.slaves->last_age_ns(), 19'000'000) << "it came before the 20 ms sleep";
  EXPECT_LT(s.slaves->last_age_ns(), 2'000'000'000);
  ASSERT_TRUE(s.master->send(command()));
  ASSERT_GT(s.slaves->receive(buf, 1s), 0);
  EXPECT_LT(s.slaves->last_age_ns(), 19'000'000) << "taken as it came";
}

TEST(M3UdpTransport, OneFramePerDatagramWithoutPadding) {
  auto slaves = open_udp("udp:127.0.0.1:0", Role::slaves);
  PlainUdp peer;
  const auto detect = frame_of(FrameType::detect, kFirstSlave, kC1Master, 0);  // 9 bytes
  ASSERT_TRUE(peer.send_to(slaves->local_port(), detect));
  std::array<std::uint8_t, kMaxFrame> buf{};
  ASSERT_EQ(slaves->receive(buf, 1s), 9);
  // The reply goes to the sender of the last frame, exactly its bytes.
  const auto reply = frame_of(FrameType::delay_reply, kC1Master, kFirstSlave, 0);
  ASSERT_TRUE(slaves->send(reply));
  EXPECT_EQ(peer.next(), reply);
}

TEST(M3UdpTransport, ACorruptedFrameReachesTheStationUntouched) {
  Segment s;
  auto bad = command(64);
  bad[40] ^= 0x01;
  bad[kMaxFrame - 1] ^= 0x10;  // and the FCS itself
  ASSERT_TRUE(s.master->send(bad));
  std::array<std::uint8_t, kMaxFrame> buf{};
  ASSERT_EQ(s.slaves->receive(buf, 1s), static_cast<int>(kMaxFrame));
  EXPECT_TRUE(std::equal(bad.begin(), bad.end(), buf.begin()));
  FrameView v;
  EXPECT_EQ(decode(std::span(buf.data(), kMaxFrame), v), FrameStatus::bad_fcs);
  EXPECT_EQ(s.slaves->stats().dropped_malformed, 0u);
}

TEST(M3UdpTransport, DropsAndCountsDatagramsThatCannotBeAFrame) {
  auto slaves = open_udp("udp:127.0.0.1:0", Role::slaves);
  PlainUdp peer;
  const std::uint16_t port = slaves->local_port();
  ASSERT_TRUE(peer.send_to(port, {0x03, 0x01, 0x00, 0x02}));  // shorter than header + FCS
  auto overlong = command(16);
  overlong[4] = 32;  // declares more data than arrived
  ASSERT_TRUE(peer.send_to(port, overlong));
  std::vector<std::uint8_t> huge(100, 0);
  huge[4] = 80;  // over 64 bytes of data
  ASSERT_TRUE(peer.send_to(port, huge));
  auto trailing = command(8);
  const std::size_t size = trailing.size();
  trailing.resize(size + 5, 0xEE);
  ASSERT_TRUE(peer.send_to(port, trailing));
  std::array<std::uint8_t, kMaxFrame> buf{};
  ASSERT_EQ(slaves->receive(buf, 1s), static_cast<int>(size));  // the good one, trimmed
  EXPECT_EQ(slaves->stats().dropped_malformed, 3u);
  EXPECT_EQ(slaves->stats().dropped_foreign, 0u);
  EXPECT_EQ(slaves->stats().received, 1u);
  EXPECT_EQ(slaves->receive(buf, 0ns), 0);
}

TEST(M3UdpTransport, SendErrorsAreCountedNotThrown) {
  auto slaves = open_udp("udp:127.0.0.1:0", Role::slaves);
  EXPECT_FALSE(slaves->send(command()));  // nobody to answer yet
  EXPECT_EQ(slaves->stats().send_errors, 1u);
  auto master = open_udp(slaves->spec(), Role::master);
  EXPECT_FALSE(master->send(std::vector<std::uint8_t>(kMaxFrame + 1)));
  EXPECT_FALSE(master->send(std::vector<std::uint8_t>(kMinFrame - 1)));
  EXPECT_EQ(master->stats().send_errors, 2u);
  EXPECT_EQ(master->stats().sent, 0u);
}

TEST(M3UdpTransport, PortInUseIsATransportErrorNamingTheSpec) {
  auto first = open_udp("udp:127.0.0.1:0", Role::slaves);
  const std::string spec = first->spec();
  try {
    open_udp(spec, Role::slaves);
    FAIL() << "a second slaves end bound the same port";
  } catch (const TransportError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(spec), std::string::npos) << msg;
    EXPECT_NE(msg.find("bind"), std::string::npos) << msg;
  }
  try {
    open_udp("udp:no-such-host.invalid:0", Role::slaves);
    FAIL() << "resolved an invalid host";
  } catch (const TransportError& e) {
    EXPECT_NE(std::string(e.what()).find("udp:no-such-host.invalid:0"), std::string::npos) << e.what();
  }
}

TEST(M3UdpTransport, WorksOverIpv6Loopback) {
  std::unique_ptr<UdpTransport> slaves;
  try {
    slaves = open_udp("udp:[::1]:0", Role::slaves);
  } catch (const TransportError& e) {
    GTEST_SKIP() << "no IPv6 loopback here: " << e.what();
  }
  EXPECT_EQ(slaves->spec(), "udp:[::1]:" + std::to_string(slaves->local_port()));
  auto master = open_udp(slaves->spec(), Role::master);
  const auto out = command();
  ASSERT_TRUE(master->send(out));
  std::array<std::uint8_t, kMaxFrame> buf{};
  ASSERT_EQ(slaves->receive(buf, 1s), static_cast<int>(out.size()));
  ASSERT_TRUE(slaves->send(std::span(buf.data(), out.size())));
  ASSERT_EQ(master->receive(buf, 1s), static_cast<int>(out.size()));
  EXPECT_TRUE(std::equal(out.begin(), out.end(), buf.begin()));
}

}  // namespace
}  // namespace omnitwin::m3
