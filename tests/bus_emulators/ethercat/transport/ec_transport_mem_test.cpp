// Tests bus_emulators/ethercat/transport/ec_transport_mem: the in-process pair: exchange in
// both directions with the bytes unchanged, the bounded queue (capacity, overflow counted,
// order kept), one end per role and name, sends with no peer, waiting with a timeout across
// threads, the eventfd, and the receive-side PDU checks.
#include "bus_emulators/ethercat/transport/ec_transport_mem.hpp"

#include "bus_emulators/ethercat/ec_frame.hpp"

#include <gtest/gtest.h>
#include <poll.h>

#include <array>
#include <chrono>
#include <thread>
#include <vector>

namespace omnitwin::ethercat {
namespace {

using namespace std::chrono_literals;

// A PDU with one datagram of `data_len` bytes (value i + seed at byte i), index `index`.
std::vector<std::uint8_t> pdu_of(Cmd cmd, std::uint8_t index, std::uint16_t data_len, std::uint8_t seed = 0) {
  std::vector<std::uint8_t> data(data_len);
  for (std::size_t i = 0; i < data.size(); ++i) data[i] = static_cast<std::uint8_t>(i + seed);
  std::vector<std::uint8_t> buf(kMaxPdu);
  PduBuilder b(buf);
  EXPECT_GE(b.add(cmd, index, 0x1001, 0x0130, data_len, data.data()), 0);
  buf.resize(b.finish());
  return buf;
}

TEST(EcMemTransport, ExchangesPdusBothWays) {
  MemTransport master("mem-exchange", Role::master);
  MemTransport slaves("mem-exchange", Role::slaves);
  const auto out = pdu_of(Cmd::fprd, 0x42, 4);
  ASSERT_TRUE(master.send(out));
  std::array<std::uint8_t, kMaxPdu> buf{};
  const int n = slaves.receive(buf, 0ns);
  ASSERT_EQ(n, static_cast<int>(out.size()));
  EXPECT_TRUE(std::equal(out.begin(), out.end(), buf.begin()));
  // The slaves answer: data filled in, WKC 1.
  std::vector<std::uint8_t> back(buf.begin(), buf.begin() + n);
  PduView v;
  ASSERT_EQ(parse_pdu(back, v), PduError::ok);
  v.datagrams[0].data()[0] = 0xAB;
  v.datagrams[0].set_wkc(1);
  ASSERT_TRUE(slaves.send(back));
  const int m = master.receive(buf, 0ns);
  ASSERT_EQ(m, static_cast<int>(back.size()));
  EXPECT_TRUE(std::equal(back.begin(), back.end(), buf.begin()));
  PduView r;
  ASSERT_EQ(parse_pdu(std::span(buf.data(), static_cast<std::size_t>(m)), r), PduError::ok);
  EXPECT_EQ(r.datagrams[0].wkc(), 1);
  EXPECT_EQ(r.datagrams[0].index(), 0x42);
  // Nothing else queued either way; the master does not hear its own frame.
  EXPECT_EQ(master.receive(buf, 0ns), 0);
  EXPECT_EQ(slaves.receive(buf, 0ns), 0);
  EXPECT_EQ(master.stats().sent, 1u);
  EXPECT_EQ(master.stats().received, 1u);
  EXPECT_EQ(slaves.stats().sent, 1u);
  EXPECT_EQ(slaves.stats().received, 1u);
}

TEST(EcMemTransport, BoundedQueueDropsAndCountsOverflowKeepingOrder) {
  MemTransport master("mem-capacity", Role::master);
  MemTransport slaves("mem-capacity", Role::slaves, 4);
  EXPECT_EQ(slaves.capacity(), 4u);
  for (std::uint8_t i = 0; i < 6; ++i) EXPECT_TRUE(master.send(pdu_of(Cmd::brd, i, 2)));
  EXPECT_EQ(slaves.pending(), 4u);
  EXPECT_EQ(slaves.stats().dropped_overflow, 2u);
  std::array<std::uint8_t, kMaxPdu> buf{};
  for (std::uint8_t i = 0; i < 4; ++i) {
    ASSERT_EQ(slaves.receive(buf, 0ns), 16);
    EXPECT_EQ(buf[3], i) << "datagram index (byte 3 of the PDU)";
  }
  EXPECT_EQ(slaves.receive(buf, 0ns), 0);
  // Room again after the queue drained.
  EXPECT_TRUE(master.send(pdu_of(Cmd::brd, 9, 2)));
  ASSERT_EQ(slaves.receive(buf, 0ns), 16);
  EXPECT_EQ(buf[3], 9);
  EXPECT_EQ(slaves.stats().dropped_overflow, 2u);
  EXPECT_THROW(MemTransport("mem-capacity-0", Role::master, 0), TransportError);
}

TEST(EcMemTransport, OneEndPerRoleAndName) {
  auto first = std::make_unique<MemTransport>("mem-roles", Role::master);
  try {
    MemTransport second("mem-roles", Role::master);
    FAIL() << "a second master end was accepted";
  } catch (const TransportError& e) {
    EXPECT_NE(std::string(e.what()).find("mem:mem-roles"), std::string::npos) << e.what();
  }
  first.reset();
  MemTransport again("mem-roles", Role::master);  // the name is free again
  MemTransport other("mem-roles-2", Role::master);  // another name is another pair
  EXPECT_THROW(MemTransport("", Role::slaves), TransportError);
}

TEST(EcMemTransport, SendWithoutPeerIsLostLikeOnAnUnpluggedCable) {
  MemTransport master("mem-nopeer", Role::master);
  EXPECT_TRUE(master.send(pdu_of(Cmd::brd, 1, 2)));
  MemTransport slaves("mem-nopeer", Role::slaves);
  std::array<std::uint8_t, kMaxPdu> buf{};
  EXPECT_EQ(slaves.receive(buf, 0ns), 0);
  // The slaves end always answers to the master end; oversized PDUs are refused.
  std::vector<std::uint8_t> big(kMaxPdu + 1, 0);
  EXPECT_FALSE(master.send(big));
  EXPECT_EQ(master.stats().send_errors, 1u);
}

TEST(EcMemTransport, ReceiveWaitsForAPduFromAnotherThread) {
  MemTransport master("mem-wait", Role::master);
  MemTransport slaves("mem-wait", Role::slaves);
  std::array<std::uint8_t, kMaxPdu> buf{};
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(slaves.receive(buf, 30ms), 0);  // times out
  EXPECT_GE(std::chrono::steady_clock::now() - t0, 30ms);
  const auto out = pdu_of(Cmd::lrw, 3, 40, 7);
  std::thread sender([&] {
    std::this_thread::sleep_for(20ms);
    master.send(out);
  });
  const int n = slaves.receive(buf, 5s);
  sender.join();
  ASSERT_EQ(n, static_cast<int>(out.size()));
  EXPECT_TRUE(std::equal(out.begin(), out.end(), buf.begin()));
}

TEST(EcMemTransport, FdIsReadableWhileQueueNotEmpty) {
  MemTransport master("mem-fd", Role::master);
  MemTransport slaves("mem-fd", Role::slaves);
  pollfd p{slaves.fd(), POLLIN, 0};
  EXPECT_EQ(::poll(&p, 1, 0), 0);
  master.send(pdu_of(Cmd::brd, 1, 2));
  master.send(pdu_of(Cmd::brd, 2, 2));
  EXPECT_EQ(::poll(&p, 1, 0), 1);
  std::array<std::uint8_t, kMaxPdu> buf{};
  slaves.receive(buf, 0ns);
  EXPECT_EQ(::poll(&p, 1, 0), 1);  // one still waiting
  slaves.receive(buf, 0ns);
  EXPECT_EQ(::poll(&p, 1, 0), 0);
}

TEST(EcMemTransport, DropsAndCountsWhatIsNotAPdu) {
  MemTransport master("mem-bad", Role::master);
  MemTransport slaves("mem-bad", Role::slaves);
  const std::array<std::uint8_t, 3> tiny{0x01, 0x10, 0x00};
  std::array<std::uint8_t, 16> mailbox_gateway{0x0e, 0x50};
  master.send(tiny);
  master.send(mailbox_gateway);
  auto good = pdu_of(Cmd::aprd, 5, 2);
  good.resize(good.size() + 5, 0xEE);  // trailing bytes past the header length
  master.send(good);
  std::array<std::uint8_t, kMaxPdu> buf{};
  EXPECT_EQ(slaves.receive(buf, 0ns), 16);  // the good one, trimmed to its header length
  EXPECT_EQ(buf[3], 5);
  EXPECT_EQ(slaves.stats().dropped_malformed, 1u);
  EXPECT_EQ(slaves.stats().dropped_foreign, 1u);
  EXPECT_EQ(slaves.stats().received, 1u);
  // A caller buffer too small for the PDU: malformed for this caller, not a crash.
  master.send(pdu_of(Cmd::aprd, 6, 100));
  std::array<std::uint8_t, 20> small{};
  EXPECT_EQ(slaves.receive(small, 0ns), 0);
  EXPECT_EQ(slaves.stats().dropped_malformed, 2u);
}

}  // namespace
}  // namespace omnitwin::ethercat
