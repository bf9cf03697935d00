// Tests bus_emulators/mechatrolink3/transport/m3_transport_mem: the in-process pair: commands and
// responses both ways with the bytes unchanged, a corrupted-FCS frame passed through untouched,
// trailing bytes trimmed, what cannot be a frame dropped and counted, the bounded queue
// (capacity, overflow counted, order kept), one end per role and name, sends with no peer or
// of a bad size, waiting with a timeout across threads, and the eventfd.
#include "bus_emulators/mechatrolink3/transport/m3_transport_mem.hpp"

#include <gtest/gtest.h>
#include <poll.h>

#include <array>
#include <chrono>
#include <thread>
#include <vector>

namespace omnitwin::m3 {
namespace {

using namespace std::chrono_literals;

// A frame of `n` data bytes (value i + seed at byte i) from `src` to `dst`.
std::vector<std::uint8_t> frame_of(FrameType type, std::uint8_t dst, std::uint8_t src, std::size_t n,
                                   std::uint8_t seed = 0) {
  std::vector<std::uint8_t> data(n);
  for (std::size_t i = 0; i < n; ++i) data[i] = static_cast<std::uint8_t>(i + seed);
  std::vector<std::uint8_t> out(kMaxFrame);
  out.resize(encode(FrameSpec{.dst = dst, .src = src, .type = type, .sequence = seed, .data = data}, out));
  EXPECT_GT(out.size(), 0u);
  return out;
}
std::vector<std::uint8_t> command(std::uint8_t seed = 0) {
  return frame_of(FrameType::cyclic_command, kFirstSlave, kC1Master, 16, seed);
}

TEST(M3MemTransport, ExchangesFramesBothWays) {
  MemTransport master("m3-mem-exchange", Role::master);
  MemTransport slaves("m3-mem-exchange", Role::slaves);
  const auto cmd = command(3);
  ASSERT_TRUE(master.send(cmd));
  std::array<std::uint8_t, kMaxFrame> buf{};
  const int n = slaves.receive(buf, 0ns);
  ASSERT_EQ(n, static_cast<int>(cmd.size()));
  EXPECT_TRUE(std::equal(cmd.begin(), cmd.end(), buf.begin()));
  FrameView v;
  ASSERT_EQ(decode(std::span(buf.data(), static_cast<std::size_t>(n)), v), FrameStatus::ok);
  EXPECT_EQ(v.type, FrameType::cyclic_command);

  const auto rsp = frame_of(FrameType::cyclic_response, kC1Master, kFirstSlave, 16, 3);
  ASSERT_TRUE(slaves.send(rsp));
  ASSERT_EQ(master.receive(buf, 0ns), static_cast<int>(rsp.size()));
  EXPECT_TRUE(std::equal(rsp.begin(), rsp.end(), buf.begin()));
  // Nothing else queued either way; the master does not hear its own frame.
  EXPECT_EQ(master.receive(buf, 0ns), 0);
  EXPECT_EQ(slaves.receive(buf, 0ns), 0);
  EXPECT_EQ(master.stats().sent, 1u);
  EXPECT_EQ(master.stats().received, 1u);
  EXPECT_EQ(slaves.stats().sent, 1u);
  EXPECT_EQ(slaves.stats().received, 1u);
}

TEST(M3MemTransport, ACorruptedFrameReachesTheStationUntouched) {
  MemTransport master("m3-mem-corrupt", Role::master);
  MemTransport slaves("m3-mem-corrupt", Role::slaves);
  auto bad = command();
  bad[7] ^= 0x80;
  ASSERT_TRUE(master.send(bad));
  std::array<std::uint8_t, kMaxFrame> buf{};
  ASSERT_EQ(slaves.receive(buf, 0ns), static_cast<int>(bad.size()));
  EXPECT_TRUE(std::equal(bad.begin(), bad.end(), buf.begin()));
  FrameView v;
  EXPECT_EQ(decode(std::span(buf.data(), bad.size()), v), FrameStatus::bad_fcs);  // the station finds it
  EXPECT_EQ(slaves.stats().dropped_malformed, 0u);
}

TEST(M3MemTransport, DropsAndCountsWhatCannotBeAFrame) {
  MemTransport master("m3-mem-bad", Role::master);
  MemTransport slaves("m3-mem-bad", Role::slaves);
  auto overlong = command();
  overlong[4] = 48;  // declares more data than the 16 bytes there
  master.send(overlong);
  auto trailing = frame_of(FrameType::sync, kBroadcast, kC1Master, 8);
  const std::size_t sync_size = trailing.size();
  trailing.resize(trailing.size() + 6, 0xEE);  // bytes after the FCS
  master.send(trailing);
  std::array<std::uint8_t, kMaxFrame> buf{};
  EXPECT_EQ(slaves.receive(buf, 0ns), static_cast<int>(sync_size));  // trimmed to the frame
  EXPECT_EQ(slaves.stats().dropped_malformed, 1u);
  EXPECT_EQ(slaves.stats().received, 1u);
  // A caller buffer too small for the frame: malformed for this caller, not a crash.
  master.send(command());
  std::array<std::uint8_t, 12> small{};
  EXPECT_EQ(slaves.receive(small, 0ns), 0);
  EXPECT_EQ(slaves.stats().dropped_malformed, 2u);
  EXPECT_EQ(slaves.stats().dropped_foreign, 0u);  // nothing in process is another protocol
}

TEST(M3MemTransport, BoundedQueueDropsAndCountsOverflowKeepingOrder) {
  MemTransport master("m3-mem-capacity", Role::master);
  MemTransport slaves("m3-mem-capacity", Role::slaves, 4);
  EXPECT_EQ(slaves.capacity(), 4u);
  for (std::uint8_t i = 0; i < 6; ++i) EXPECT_TRUE(master.send(command(i)));
  EXPECT_EQ(slaves.pending(), 4u);
  EXPECT_EQ(slaves.stats().dropped_overflow, 2u);
  std::array<std::uint8_t, kMaxFrame> buf{};
  for (std::uint8_t i = 0; i < 4; ++i) {
    ASSERT_EQ(slaves.receive(buf, 0ns), 25);
    EXPECT_EQ(buf[2], i) << "message control: the sequence number";
  }
  EXPECT_EQ(slaves.receive(buf, 0ns), 0);
  EXPECT_TRUE(master.send(command(9)));  // room again after the queue drained
  ASSERT_EQ(slaves.receive(buf, 0ns), 25);
  EXPECT_EQ(buf[2], 9);
  EXPECT_THROW(MemTransport("m3-mem-capacity-0", Role::master, 0), TransportError);
}

TEST(M3MemTransport, OneEndPerRoleAndName) {
  auto first = std::make_unique<MemTransport>("m3-mem-roles", Role::master);
  try {
    MemTransport second("m3-mem-roles", Role::master);
    FAIL() << "a second master end was accepted";
  } catch (const TransportError& e) {
    EXPECT_NE(std::string(e.what()).find("mem:m3-mem-roles"), std::string::npos) << e.what();
  }
  first.reset();
  MemTransport again("m3-mem-roles", Role::master);  // the name is free again
  EXPECT_THROW(MemTransport("", Role::slaves), TransportError);
}

TEST(M3MemTransport, SendWithoutPeerIsLostAndBadSizesAreRefused) {
  MemTransport master("m3-mem-nopeer", Role::master);
  EXPECT_TRUE(master.send(command()));
  MemTransport slaves("m3-mem-nopeer", Role::slaves);
  std::array<std::uint8_t, kMaxFrame> buf{};
  EXPECT_EQ(slaves.receive(buf, 0ns), 0);
  const std::vector<std::uint8_t> tiny(kMinFrame - 1, 0), big(kMaxFrame + 1, 0);
  EXPECT_FALSE(master.send(tiny));
  EXPECT_FALSE(master.send(big));
  EXPECT_EQ(master.stats().send_errors, 2u);
  EXPECT_EQ(slaves.pending(), 0u);
}

TEST(M3MemTransport, ReceiveWaitsForAFrameFromAnotherThread) {
  MemTransport master("m3-mem-wait", Role::master);
  MemTransport slaves("m3-mem-wait", Role::slaves);
  std::array<std::uint8_t, kMaxFrame> buf{};
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(slaves.receive(buf, 30ms), 0);  // times out
  EXPECT_GE(std::chrono::steady_clock::now() - t0, 30ms);
  const auto out = frame_of(FrameType::event_command, kFirstSlave, kC1Master, 64, 7);
  std::thread sender([&] {
    std::this_thread::sleep_for(20ms);
    master.send(out);
  });
  const int n = slaves.receive(buf, 5s);
  sender.join();
  ASSERT_EQ(n, static_cast<int>(kMaxFrame));
  EXPECT_TRUE(std::equal(out.begin(), out.end(), buf.begin()));
}

TEST(M3MemTransport, FdIsReadableWhileQueueNotEmpty) {
  MemTransport master("m3-mem-fd", Role::master);
  MemTransport slaves("m3-mem-fd", Role::slaves);
  pollfd p{slaves.fd(), POLLIN, 0};
  EXPECT_EQ(::poll(&p, 1, 0), 0);
  master.send(command(1));
  master.send(command(2));
  EXPECT_EQ(::poll(&p, 1, 0), 1);
  std::array<std::uint8_t, kMaxFrame> buf{};
  slaves.receive(buf, 0ns);
  EXPECT_EQ(::poll(&p, 1, 0), 1);  // one still waiting
  slaves.receive(buf, 0ns);
  EXPECT_EQ(::poll(&p, 1, 0), 0);
}

}  // namespace
}  // namespace omnitwin::m3
