// Tests bus_emulators/ethercat/transport/ec_transport_udp: EtherCAT over UDP on loopback: the
// PDU is the whole UDP payload, the master sends from an ephemeral port to HOST:PORT and the
// slaves answer the sender; datagrams too short to be a PDU (or declaring more than arrived)
// are dropped and counted, other EtherCAT types too; trailing bytes are trimmed; set-up errors
// name the spec. Every test uses its own port in 48800–48899.
#include "bus_emulators/ethercat/transport/ec_transport_udp.hpp"

#include "bus_emulators/ethercat/ec_frame.hpp"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <vector>

namespace omnitwin::ethercat {
namespace {

using namespace std::chrono_literals;

std::vector<std::uint8_t> pdu_of(Cmd cmd, std::uint8_t index, std::uint16_t data_len) {
  std::vector<std::uint8_t> data(data_len);
  for (std::size_t i = 0; i < data.size(); ++i) data[i] = static_cast<std::uint8_t>(3 * i + 1);
  std::vector<std::uint8_t> buf(kMaxPdu);
  PduBuilder b(buf);
  EXPECT_GE(b.add(cmd, index, 0, 0x0130, data_len, data.data()), 0);
  buf.resize(b.finish());
  return buf;
}

std::unique_ptr<UdpTransport> open_udp(const std::string& spec, Role role) {
  return std::make_unique<UdpTransport>(parse_transport_spec(spec), role);
}

// A plain UDP socket (the test's own sender of odd datagrams) bound to an ephemeral port.
class RawUdp {
 public:
  RawUdp() : fd_(::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0)) {}
  ~RawUdp() { ::close(fd_); }
  bool send_to(std::uint16_t port, const void* data, std::size_t n) const {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    return ::sendto(fd_, data, n, 0, reinterpret_cast<sockaddr*>(&a), sizeof a) == static_cast<ssize_t>(n);
  }
  std::uint16_t port() const {
    sockaddr_in a{};
    socklen_t len = sizeof a;
    ::getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len);
    return ntohs(a.sin_port);
  }

 private:
  int fd_;
};

TEST(EcUdpTransport, MasterAndSlavesExchangeOnLoopback) {
  auto slaves = open_udp("udp:127.0.0.1:48800", Role::slaves);
  auto master = open_udp("udp:127.0.0.1:48800", Role::master);
  EXPECT_EQ(slaves->local_port(), 48800);
  EXPECT_NE(master->local_port(), 48800);
  EXPECT_NE(master->local_port(), 0);
  EXPECT_EQ(slaves->describe(), "udp:127.0.0.1:48800 (slaves, local port 48800)");

  const auto out = pdu_of(Cmd::aprd, 0x11, 2);
  ASSERT_TRUE(master->send(out));
  std::array<std::uint8_t, kMaxPdu> buf{};
  const int n = slaves->receive(buf, 1s);
  ASSERT_EQ(n, static_cast<int>(out.size()));  // no padding over UDP
  EXPECT_TRUE(std::equal(out.begin(), out.end(), buf.begin()));

  std::vector<std::uint8_t> back(buf.begin(), buf.begin() + n);
  PduView v;
  ASSERT_EQ(parse_pdu(back, v), PduError::ok);
  v.datagrams[0].set_adp(1);  // position address incremented by one slave
  v.datagrams[0].set_wkc(1);
  ASSERT_TRUE(slaves->send(back));
  const int m = master->receive(buf, 1s);
  ASSERT_EQ(m, static_cast<int>(back.size()));
  EXPECT_TRUE(std::equal(back.begin(), back.end(), buf.begin()));
  EXPECT_EQ(master->receive(buf, 0ns), 0);
  EXPECT_EQ(slaves->receive(buf, 0ns), 0);
  EXPECT_EQ(master->stats().sent, 1u);
  EXPECT_EQ(master->stats().received, 1u);
  EXPECT_EQ(slaves->stats().received, 1u);
  EXPECT_EQ(slaves->stats().sent, 1u);
}

TEST(EcUdpTransport, SlavesAnswerWhoeverSentTheLastPdu) {
  auto slaves = open_udp("udp:127.0.0.1:48801", Role::slaves);
  auto m1 = open_udp("udp:127.0.0.1:48801", Role::master);
  auto m2 = open_udp("udp:127.0.0.1:48801", Role::master);
  std::array<std::uint8_t, kMaxPdu> buf{};
  const auto a = pdu_of(Cmd::brd, 1, 2);
  const auto b = pdu_of(Cmd::brd, 2, 2);
  m1->send(a);
  ASSERT_EQ(slaves->receive(buf, 1s), 16);
  slaves->send(std::span(buf.data(), 16));
  m2->send(b);
  ASSERT_EQ(slaves->receive(buf, 1s), 16);
  slaves->send(std::span(buf.data(), 16));
  ASSERT_EQ(m1->receive(buf, 1s), 16);
  EXPECT_EQ(buf[3], 1);
  ASSERT_EQ(m2->receive(buf, 1s), 16);
  EXPECT_EQ(buf[3], 2);
  EXPECT_EQ(m1->receive(buf, 0ns), 0);
}

TEST(EcUdpTransport, TruncatedAndForeignDatagramsAreDroppedAndCounted) {
  auto slaves = open_udp("udp:127.0.0.1:48802", Role::slaves);
  RawUdp sender;
  const std::uint8_t one[1] = {0x0e};
  const std::uint8_t three[3] = {0x0e, 0x10, 0x07};                       // header, then cut
  std::array<std::uint8_t, 14> cut{0x20, 0x10};                            // declares 32 bytes
  std::array<std::uint8_t, 16> gateway{0x0e, 0x50};                        // type 5
  ASSERT_TRUE(sender.send_to(48802, one, sizeof one));
  ASSERT_TRUE(sender.send_to(48802, three, sizeof three));
  ASSERT_TRUE(sender.send_to(48802, cut.data(), cut.size()));
  ASSERT_TRUE(sender.send_to(48802, gateway.data(), gateway.size()));
  ASSERT_TRUE(sender.send_to(48802, nullptr, 0));                          // empty datagram
  auto good = pdu_of(Cmd::fpwr, 0x33, 4);
  good.insert(good.end(), {0xAA, 0xBB, 0xCC});  // trailing bytes beyond the header length
  ASSERT_TRUE(sender.send_to(48802, good.data(), good.size()));
  std::array<std::uint8_t, kMaxPdu> buf{};
  ASSERT_EQ(slaves->receive(buf, 1s), 18);  // the good one, trimmed to 2 + header length
  EXPECT_EQ(buf[2], static_cast<std::uint8_t>(Cmd::fpwr));
  EXPECT_EQ(buf[3], 0x33);
  EXPECT_EQ(slaves->stats().dropped_malformed, 4u);
  EXPECT_EQ(slaves->stats().dropped_foreign, 1u);
  EXPECT_EQ(slaves->stats().received, 1u);
  EXPECT_EQ(slaves->receive(buf, 0ns), 0);
}

TEST(EcUdpTransport, ADatagramLargerThanTheCallersBufferIsMalformed) {
  auto slaves = open_udp("udp:127.0.0.1:48803", Role::slaves);
  auto master = open_udp("udp:127.0.0.1:48803", Role::master);
  master->send(pdu_of(Cmd::lrd, 1, 200));
  std::array<std::uint8_t, 64> small{};
  EXPECT_EQ(slaves->receive(small, 100ms), 0);
  EXPECT_EQ(slaves->stats().dropped_malformed, 1u);
}

TEST(EcUdpTransport, SendErrorsAreCountedNotThrown) {
  auto slaves = open_udp("udp:127.0.0.1:48804", Role::slaves);
  const auto p = pdu_of(Cmd::brd, 1, 2);
  EXPECT_FALSE(slaves->send(p));  // nobody to answer yet
  EXPECT_EQ(slaves->stats().send_errors, 1u);
  auto master = open_udp("udp:127.0.0.1:48804", Role::master);
  std::vector<std::uint8_t> big(kMaxPdu + 1);
  EXPECT_FALSE(master->send(big));
  EXPECT_EQ(master->stats().send_errors, 1u);
  EXPECT_EQ(master->stats().sent, 0u);
}

TEST(EcUdpTransport, PortInUseIsATransportErrorNamingTheSpec) {
  auto first = open_udp("udp:127.0.0.1:48805", Role::slaves);
  try {
    open_udp("udp:127.0.0.1:48805", Role::slaves);
    FAIL() << "a second slaves end bound the same port";
  } catch (const TransportError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("udp:127.0.0.1:48805"), std::string::npos) << msg;
    EXPECT_NE(msg.find("bind"), std::string::npos) << msg;
  }
}

TEST(EcUdpTransport, WorksOverIpv6Loopback) {
  std::unique_ptr<UdpTransport> slaves;
  try {
    slaves = open_udp("udp:[::1]:48806", Role::slaves);
  } catch (const TransportError& e) {
    GTEST_SKIP() << "no IPv6 loopback here: " << e.what();
  }
  auto master = open_udp("udp:[::1]:48806", Role::master);
  const auto out = pdu_of(Cmd::brd, 6, 2);
  ASSERT_TRUE(master->send(out));
  std::array<std::uint8_t, kMaxPdu> buf{};
  ASSERT_EQ(slaves->receive(buf, 1s), 16);
  ASSERT_TRUE(slaves->send(std::span(buf.data(), 16)));
  ASSERT_EQ(master->receive(buf, 1s), 16);
  EXPECT_TRUE(std::equal(out.begin(), out.end(), buf.begin()));
}

}  // namespace
}  // namespace omnitwin::ethercat
