// Tests bus_emulators/can/transport (spec parsing, open_transport dispatch) and
// transport_mem: delivery to every other member of a named bus and not to the sender,
// isolation between names, the pollable descriptor, bounded queues, and threads.
#include "bus_emulators/can/transport.hpp"
#include "bus_emulators/can/transport_mem.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <thread>

namespace omnitwin::can {
namespace {

using namespace std::chrono_literals;

TEST(TransportSpec, ParsesEachKind) {
  auto t = parse_transport_spec("socketcan:vcan0");
  EXPECT_EQ(t.kind, TransportSpec::Kind::socketcan);
  EXPECT_EQ(t.name, "vcan0");
  t = parse_transport_spec("mem:bus-a");
  EXPECT_EQ(t.kind, TransportSpec::Kind::mem);
  EXPECT_EQ(t.name, "bus-a");
  t = parse_transport_spec("udp:239.74.163.2:43113");
  EXPECT_EQ(t.kind, TransportSpec::Kind::udp);
}

TEST(TransportSpec, BadSpecsThrowWithTheSpecInTheMessage) {
  for (const char* bad : {"", "vcan0", "can:vcan0", "socketcan:", "socketcan:averyveryverylongname0", "socketcan:a/b",
                          "mem:", "MEM:x", "tcp:1.2.3.4:5"}) {
    try {
      open_transport(bad);
      ADD_FAILURE() << "'" << bad << "' was accepted";
    } catch (const TransportError& e) {
      EXPECT_NE(std::string(e.what()).find(std::string("'") + bad + "'"), std::string::npos) << e.what();
    }
  }
}

TEST(MemTransport, DeliversToEveryOtherMemberNotToTheSender) {
  auto a = open_transport("mem:deliver");
  auto b = open_transport("mem:deliver");
  auto c = open_transport("mem:deliver");
  EXPECT_EQ(a->spec(), "mem:deliver");
  ASSERT_TRUE(a->send(make_data(0x181, {1, 2}), 42));
  for (auto* t : {b.get(), c.get()}) {
    auto r = t->receive();
    ASSERT_TRUE(r);
    EXPECT_EQ(r->frame, make_data(0x181, {1, 2}));
    EXPECT_EQ(r->timestamp_ns, 42);
    EXPECT_FALSE(t->receive());
  }
  EXPECT_FALSE(a->receive());
  EXPECT_EQ(a->stats().frames_tx, 1u);
  EXPECT_EQ(b->stats().frames_rx, 1u);
}

TEST(MemTransport, NamesAreSeparateBuses) {
  auto a = open_transport("mem:one");
  auto b = open_transport("mem:two");
  a->send(make_data(1, {}));
  EXPECT_FALSE(b->receive());
}

TEST(MemTransport, PollFdIsReadableExactlyWhileFramesWait) {
  auto a = open_transport("mem:poll");
  auto b = open_transport("mem:poll");
  EXPECT_FALSE(wait_readable(*b, 0ms));
  a->send(make_data(1, {1}));
  a->send(make_remote(2, 3));
  EXPECT_TRUE(wait_readable(*b, 0ms));
  EXPECT_EQ(b->receive()->frame, make_data(1, {1}));
  EXPECT_TRUE(wait_readable(*b, 0ms));
  EXPECT_EQ(b->receive()->frame, make_remote(2, 3));
  EXPECT_FALSE(wait_readable(*b, 0ms));
}

TEST(MemTransport, InvalidFramesAreRefusedAndOverflowIsCounted) {
  MemTransport a("overflow");
  MemTransport b("overflow", 2);
  Frame bad = make_data(0x10, {});
  bad.dlc = 12;
  EXPECT_FALSE(a.send(bad));
  EXPECT_EQ(a.stats().invalid_tx, 1u);
  bad = make_data(0x10, {});
  bad.id = 0x800;
  EXPECT_FALSE(a.send(bad));
  EXPECT_EQ(a.stats().invalid_tx, 2u);
  for (int i = 0; i < 5; ++i) EXPECT_TRUE(a.send(make_data(static_cast<std::uint32_t>(i), {})));
  EXPECT_EQ(b.pending(), 2u);
  EXPECT_EQ(b.stats().rx_dropped, 3u);
  EXPECT_EQ(b.receive()->frame.id, 0u);  // the oldest are kept
  EXPECT_EQ(b.receive()->frame.id, 1u);
}

TEST(MemTransport, LeavingMembersStopReceivingAndTheHubOutlivesNoOne) {
  auto a = open_transport("mem:leave");
  {
    auto b = open_transport("mem:leave");
    a->send(make_data(1, {}));
  }
  EXPECT_TRUE(a->send(make_data(2, {})));  // nobody left to hear it: still fine
  auto c = open_transport("mem:leave");
  a->send(make_data(3, {}));
  EXPECT_EQ(c->receive()->frame.id, 3u);
}

TEST(MemTransport, SendAndReceiveOnDifferentThreads) {
  constexpr int kFrames = 20000;
  auto rx = std::make_unique<MemTransport>("threads", kFrames);
  std::thread producer([] {
    MemTransport tx("threads");
    for (int i = 0; i < kFrames; ++i) tx.send(make_data(static_cast<std::uint32_t>(i % 0x800), {static_cast<std::uint8_t>(i)}));
  });
  int got = 0;
  std::uint32_t expect = 0;
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while (got < kFrames && std::chrono::steady_clock::now() < deadline) {
    if (auto r = rx->receive()) {
      ASSERT_EQ(r->frame.id, expect % 0x800);  // in order
      ++expect;
      ++got;
    } else {
      wait_readable(*rx, 10ms);
    }
  }
  producer.join();
  EXPECT_EQ(got, kFrames);
  EXPECT_EQ(rx->stats().rx_dropped, 0u);
}

}  // namespace
}  // namespace omnitwin::can
