// Tests bus_emulators/ethercat/transport/ec_echo: the bare echo answers every PDU with the very
// same bytes (in process, over UDP, over a veth pair), counts what it echoed, and stops
// promptly when asked.
#include "bus_emulators/ethercat/transport/ec_echo.hpp"

#include "bus_emulators/ethercat/ec_frame.hpp"
#include "bus_emulators/ethercat/transport/ec_transport_raw.hpp"
#include "tests/support/veth.hpp"

#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <thread>
#include <vector>

namespace omnitwin::ethercat {
namespace {

using namespace std::chrono_literals;

std::vector<std::uint8_t> pdu_of(std::uint8_t index, std::uint16_t data_len) {
  std::vector<std::uint8_t> data(data_len);
  for (std::size_t i = 0; i < data.size(); ++i) data[i] = static_cast<std::uint8_t>(index * 7 + i);
  std::vector<std::uint8_t> buf(kMaxPdu);
  PduBuilder b(buf);
  EXPECT_GE(b.add(Cmd::lrw, index, 0, 0x0001, data_len, data.data()), 0);
  buf.resize(b.finish());
  return buf;
}

// Sends PDUs of several sizes through `master` and expects each back byte for byte.
void expect_echoes(EcTransport& master, EchoThread& echo) {
  std::array<std::uint8_t, kMaxPdu> buf{};
  const std::uint16_t sizes[] = {2, 46, 986, 1400};
  std::uint8_t index = 0;
  for (const std::uint16_t len : sizes) {
    const auto out = pdu_of(index++, len);
    ASSERT_TRUE(master.send(out));
    const int n = master.receive(buf, 2s);
    ASSERT_EQ(n, static_cast<int>(out.size())) << "data length " << len;
    EXPECT_TRUE(std::equal(out.begin(), out.end(), buf.begin())) << "data length " << len;
  }
  EXPECT_EQ(master.receive(buf, 50ms), 0);  // one answer per frame, no more
  echo.stop();  // the count is published after each send: read it once the thread is done
  EXPECT_EQ(echo.echoed(), std::size(sizes));
}

TEST(EcEcho, EchoesInProcess) {
  EchoThread echo("mem:ec-echo");
  auto master = open_transport("mem:ec-echo", Role::master);
  expect_echoes(*master, echo);
  EXPECT_EQ(echo.transport().stats().received, 4u);
  EXPECT_EQ(echo.transport().stats().sent, 4u);
}

TEST(EcEcho, EchoesOverUdp) {
  EchoThread echo("udp:127.0.0.1:48820");
  auto master = open_transport("udp:127.0.0.1:48820", Role::master);
  expect_echoes(*master, echo);
}

TEST(EcEcho, EchoesOverAVethPair) {
  if (const auto why = testing::VethPair::unavailable_reason()) GTEST_SKIP() << *why;
  testing::VethPair veth;
  EchoThread echo("raw:" + veth.b());
  auto master = open_transport("raw:" + veth.a(), Role::master);
  expect_echoes(*master, echo);
}

TEST(EcEcho, StopsPromptlyAndRunEchoReturnsItsCount) {
  auto slaves = open_transport("mem:ec-echo-stop", Role::slaves);
  auto master = open_transport("mem:ec-echo-stop", Role::master);
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> live{0};
  std::uint64_t total = 0;
  std::thread t([&] { total = run_echo(*slaves, stop, 5ms, &live); });
  std::array<std::uint8_t, kMaxPdu> buf{};
  for (std::uint8_t i = 0; i < 3; ++i) {
    master->send(pdu_of(i, 2));
    ASSERT_EQ(master->receive(buf, 2s), 16);
  }
  const auto t0 = std::chrono::steady_clock::now();
  stop = true;
  t.join();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 1s);
  EXPECT_EQ(total, 3u);
  EXPECT_EQ(live.load(), 3u);
  EXPECT_THROW(EchoThread(std::unique_ptr<EcTransport>{}), TransportError);
}

}  // namespace
}  // namespace omnitwin::ethercat
