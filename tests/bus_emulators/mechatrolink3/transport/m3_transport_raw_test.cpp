// Tests bus_emulators/mechatrolink3/transport/m3_transport_raw: M-III on raw Ethernet over a veth
// pair (master on end a, slaves on end b; the EtherCAT transports' VethPair, made and deleted
// by each test, also when it fails): commands and responses with the frame bytes unchanged; the
// frames on the wire are m3::encapsulate()'s (station MACs, EtherType 0x88B5, padded to 60) and
// receive() removes the padding; a frame with a bad FCS goes out and arrives untouched; neither
// end receives its own frames; frames of another EtherType and what cannot be a frame are
// dropped and counted; a frame's age (the kernel's receive stamp) says how long it waited before
// receive(); a second sender counted and refused when asked; set-up errors (missing interface, not Ethernet, missing privilege) name the spec. Needs root for veth pairs and raw sockets (CI runs as root); skips with the reason
// otherwise.
#include "bus_emulators/mechatrolink3/transport/m3_transport_raw.hpp"

#include "tests/support/receive_stamps.hpp"
#include "tests/support/veth.hpp"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <linux/if_ether.h>
#include <linux/if_packet.h>
#include <net/if.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <fstream>
#include <optional>
#include <thread>
#include <vector>

namespace omnitwin::m3 {
namespace {

using namespace std::chrono_literals;
// How long a frame that must arrive may take: the wait ends when it comes, so this costs a passing
// test nothing; on a loaded CI host (two cores, realtime runs beside it) 1 s was once too short.
constexpr auto kArrives = 5s;
using testing::VethPair;

std::vector<std::uint8_t> frame_of(FrameType type, std::uint8_t dst, std::uint8_t src, std::size_t n) {
  std::vector<std::uint8_t> data(n);
  for (std::size_t i = 0; i < n; ++i) data[i] = static_cast<std::uint8_t>(5 * i + 2);
  std::vector<std::uint8_t> out(kMaxFrame);
  out.resize(encode(FrameSpec{.dst = dst, .src = src, .type = type, .data = data}, out));
  EXPECT_GT(out.size(), 0u);
  return out;
}
std::vector<std::uint8_t> command(std::size_t n = 16, std::uint8_t dst = kFirstSlave) {
  return frame_of(FrameType::cyclic_command, dst, kC1Master, n);
}
std::vector<std::uint8_t> response(std::size_t n = 16) {
  return frame_of(FrameType::cyclic_response, kC1Master, kFirstSlave, n);
}
std::vector<std::uint8_t> encapsulated(const std::vector<std::uint8_t>& frame) {
  std::vector<std::uint8_t> eth(kEthHeaderSize + kMaxFrame);
  eth.resize(encapsulate(frame, eth));
  EXPECT_GT(eth.size(), 0u);
  return eth;
}

// An Ethernet frame to broadcast with `ethertype` and `payload`, zero padded to `min_size`.
std::vector<std::uint8_t> ethernet(std::uint16_t ethertype, const std::vector<std::uint8_t>& payload,
                                   std::size_t min_size = kMinEthFrame) {
  // Built in one buffer of its final size (growing a 14-byte vector trips GCC 12's
  // -Warray-bounds false positive).
  std::vector<std::uint8_t> f(std::max(min_size, kEthHeaderSize + payload.size()), 0);
  const Mac src = station_mac(kC1Master);
  std::fill(f.begin(), f.begin() + 6, std::uint8_t{0xff});
  std::copy(src.begin(), src.end(), f.begin() + 6);
  f[12] = static_cast<std::uint8_t>(ethertype >> 8);
  f[13] = static_cast<std::uint8_t>(ethertype);
  std::copy(payload.begin(), payload.end(), f.begin() + kEthHeaderSize);
  return f;
}

// The test's own view of the wire: an ETH_P_ALL packet socket on one interface that sees every
// frame (incoming and outgoing) and can inject arbitrary ones.
class Wire {
 public:
  explicit Wire(const std::string& ifname) {
    fd_ = ::socket(AF_PACKET, SOCK_RAW | SOCK_CLOEXEC, htons(ETH_P_ALL));
    if (fd_ < 0) throw std::runtime_error("wire socket");
    sockaddr_ll sll{};
    sll.sll_family = AF_PACKET;
    sll.sll_protocol = htons(ETH_P_ALL);
    sll.sll_ifindex = static_cast<int>(::if_nametoindex(ifname.c_str()));
    if (::bind(fd_, reinterpret_cast<sockaddr*>(&sll), sizeof sll) != 0) throw std::runtime_error("wire bind");
  }
  ~Wire() { ::close(fd_); }
  Wire(const Wire&) = delete;
  Wire& operator=(const Wire&) = delete;
  void inject(const std::vector<std::uint8_t>& frame) const {
    ASSERT_EQ(::send(fd_, frame.data(), frame.size(), 0), static_cast<ssize_t>(frame.size()));
  }
  // The next incoming M-III frame (EtherType 0x88B5) seen within `timeout`.
  std::optional<std::vector<std::uint8_t>> next_m3(std::chrono::milliseconds timeout) const {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      timeval tv{0, 20'000};
      ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
      std::vector<std::uint8_t> b(2048);
      sockaddr_ll from{};
      socklen_t len = sizeof from;
      const ssize_t n = ::recvfrom(fd_, b.data(), b.size(), 0, reinterpret_cast<sockaddr*>(&from), &len);
      if (n < 14 || from.sll_pkttype == PACKET_OUTGOING) continue;
      b.resize(static_cast<std::size_t>(n));
      if (((b[12] << 8) | b[13]) == kEtherType) return b;
    }
    return std::nullopt;
  }

 private:
  int fd_ = -1;
};

// An interface's kernel counters, for failure messages: where a frame that never came was lost.
std::string counters(const std::string& ifname) {
  std::string out = ifname + ":";
  for (const char* c : {"tx_packets", "tx_dropped", "rx_packets", "rx_dropped"}) {
    std::ifstream f("/sys/class/net/" + ifname + "/statistics/" + c);
    std::string v;
    std::getline(f, v);
    out += std::string(" ") + c + " " + v;
  }
  std::ifstream f("/sys/class/net/" + ifname + "/operstate");
  std::string state;
  std::getline(f, state);
  return out + ", operstate " + state;
}

class M3RawTransport : public ::testing::Test {
 protected:
  void SetUp() override {
    if (const auto why = VethPair::unavailable_reason()) GTEST_SKIP() << *why;
    veth_.emplace();  // deleted when the fixture goes, whatever the test's outcome
  }
  std::optional<VethPair> veth_;
};

TEST_F(M3RawTransport, MasterAndSlavesExchangeOverAVethPair) {
  RawTransport master(veth_->a(), Role::master);
  RawTransport slaves(veth_->b(), Role::slaves);
  EXPECT_EQ(master.spec(), "raw:" + veth_->a());
  EXPECT_EQ(master.describe().rfind("raw:" + veth_->a() + " (master, ", 0), 0u) << master.describe();
  std::array<std::uint8_t, kMaxFrame> buf{};
  for (const std::size_t n : {std::size_t{8}, std::size_t{32}, std::size_t{64}}) {
    SCOPED_TRACE(n);
    const auto cmd = command(n);
    ASSERT_TRUE(master.send(cmd));
    ASSERT_EQ(slaves.receive(buf, kArrives), static_cast<int>(cmd.size()));
    EXPECT_TRUE(std::equal(cmd.begin(), cmd.end(), buf.begin()));
    const auto rsp = response(n);
    ASSERT_TRUE(slaves.send(rsp));
    ASSERT_EQ(master.receive(buf, kArrives), static_cast<int>(rsp.size()));
    EXPECT_TRUE(std::equal(rsp.begin(), rsp.end(), buf.begin()));
  }
  EXPECT_EQ(master.stats().sent, 3u);
  EXPECT_EQ(master.stats().received, 3u);
  EXPECT_EQ(slaves.stats().sent, 3u);
  EXPECT_EQ(slaves.stats().received, 3u);
  EXPECT_EQ(master.stats().send_errors, 0u);
  EXPECT_TRUE(master.kernel_filter());
}

TEST_F(M3RawTransport, AFramesAgeIsHowLongItWaitedBeforeReceive) {
  RawTransport master(veth_->a(), Role::master);
  RawTransport slaves(veth_->b(), Role::slaves);
  ASSERT_TRUE(omnitwin::testing::wait_for_receive_stamps(master, slaves, command(32)));
  ASSERT_TRUE(master.send(command(32)));
  std::this_thread::sleep_for(20ms);
  std::array<std::uint8_t, kMaxFrame> buf{};
  ASSERT_GT(slaves.receive(buf, kArrives), 0);
  EXPECT_GE(slaves.last_age_ns(), 19'000'000) << "it came before the 20 ms sleep";
  EXPECT_LT(slaves.last_age_ns(), 2'000'000'000);
}

TEST_F(M3RawTransport, FramesOnTheWireAreTheEncapsulationAndPaddingIsRemoved) {
  RawTransport master(veth_->a(), Role::master);
  RawTransport slaves(veth_->b(), Role::slaves);
  Wire wire_a(veth_->a());
  Wire wire_b(veth_->b());
  std::array<std::uint8_t, kMaxFrame> buf{};
  // A SYNC to all stations: broadcast MAC, from the C1 master's station MAC, padded to 60.
  const auto sync = frame_of(FrameType::sync, kBroadcast, kC1Master, 8);
  ASSERT_TRUE(master.send(sync));
  const auto seen = wire_b.next_m3(kArrives);
  ASSERT_TRUE(seen);
  EXPECT_EQ(*seen, encapsulated(sync));
  EXPECT_EQ(seen->size(), kMinEthFrame);
  EXPECT_EQ(slaves.receive(buf, kArrives), 17);  // the frame, not the 46 bytes of Ethernet payload
  // A response back: unicast to the master's station MAC, from the slave's.
  const auto rsp = response(64);
  ASSERT_TRUE(slaves.send(rsp));
  const auto back = wire_a.next_m3(kArrives);
  ASSERT_TRUE(back);
  EXPECT_EQ(*back, encapsulated(rsp));
  EXPECT_EQ(back->size(), kEthHeaderSize + kMaxFrame);  // no padding needed
  const Mac to = station_mac(kC1Master), from = station_mac(kFirstSlave);
  EXPECT_TRUE(std::equal(to.begin(), to.end(), back->begin()));
  EXPECT_TRUE(std::equal(from.begin(), from.end(), back->begin() + 6));
  EXPECT_EQ(master.receive(buf, kArrives), static_cast<int>(kMaxFrame));
  // Injected with the padding and an Ethernet FCS a capture kept (64 bytes): trimmed too.
  const auto detect = frame_of(FrameType::detect, kFirstSlave, kC1Master, 0);
  wire_a.inject(ethernet(kEtherType, detect, kMinEthFrame + 4));
  ASSERT_EQ(slaves.receive(buf, kArrives), 9);
  EXPECT_TRUE(std::equal(detect.begin(), detect.end(), buf.begin()));
}

// The slaves take the first source MAC as the master's; frames from another station's MAC
// (a C2 master, 02h) are counted as foreign and, when asked, refused.
TEST_F(M3RawTransport, ASecondSenderIsCountedAndRefusedWhenAsked) {
  for (bool refuse : {false, true}) {
    RawTransport master(veth_->a(), Role::master);
    RawTransport slaves(veth_->b(), Role::slaves);
    slaves.set_refuse_foreign_senders(refuse);
    Wire wire_a(veth_->a());
    std::array<std::uint8_t, kMaxFrame> buf{};
    ASSERT_TRUE(master.send(command()));
    ASSERT_GT(slaves.receive(buf, kArrives), 0);
    wire_a.inject(encapsulated(frame_of(FrameType::cyclic_command, kFirstSlave, 0x02, 16)));
    ASSERT_TRUE(master.send(command()));
    int got = 0;
    while (slaves.receive(buf, 200ms) > 0) ++got;
    EXPECT_EQ(got, refuse ? 1 : 2) << refuse;
    EXPECT_EQ(slaves.stats().foreign_sender, 1u) << refuse;
    EXPECT_EQ(slaves.stats().refused_sender, refuse ? 1u : 0u);
  }
}

TEST_F(M3RawTransport, ACorruptedFrameGoesOutAndArrivesUntouched) {
  RawTransport master(veth_->a(), Role::master);
  RawTransport slaves(veth_->b(), Role::slaves);
  Wire wire_b(veth_->b());
  auto bad = command(32);
  bad[20] ^= 0x08;  // the FCS no longer matches
  ASSERT_TRUE(master.send(bad));  // encapsulate() would refuse it; the transport does not
  const auto seen = wire_b.next_m3(kArrives);
  ASSERT_TRUE(seen);
  EXPECT_TRUE(std::equal(bad.begin(), bad.end(), seen->begin() + kEthHeaderSize));
  EXPECT_EQ((*seen)[5], kFirstSlave);  // the station MACs still come from the address bytes
  std::array<std::uint8_t, kMaxFrame> buf{};
  ASSERT_EQ(slaves.receive(buf, kArrives), static_cast<int>(bad.size()));
  EXPECT_TRUE(std::equal(bad.begin(), bad.end(), buf.begin()));
  FrameView v;
  EXPECT_EQ(decode(std::span(buf.data(), bad.size()), v), FrameStatus::bad_fcs);  // the station's finding
  EXPECT_EQ(slaves.stats().dropped_malformed, 0u);
}

TEST_F(M3RawTransport, NeitherEndReceivesItsOwnFrames) {
  for (const bool bypass : {true, false}) {
    SCOPED_TRACE(bypass ? "qdisc bypass" : "no qdisc bypass");
    RawTransport master(veth_->a(), Role::master, RawOptions{.qdisc_bypass = bypass});
    Wire wire_b(veth_->b());
    std::array<std::uint8_t, kMaxFrame> buf{};
    ASSERT_TRUE(master.send(command()));
    ASSERT_TRUE(wire_b.next_m3(kArrives)) << "the frame was not sent at all";
    EXPECT_EQ(master.receive(buf, 100ms), 0);  // no slaves: nothing comes back, not our own frame
    EXPECT_EQ(master.stats().received, 0u);

    RawTransport slaves(veth_->b(), Role::slaves, RawOptions{.qdisc_bypass = bypass});
    ASSERT_TRUE(master.send(command()));
    ASSERT_EQ(slaves.receive(buf, kArrives), 25);
    ASSERT_TRUE(slaves.send(response()));
    EXPECT_EQ(slaves.receive(buf, 100ms), 0);  // its own response is not a new frame
    ASSERT_EQ(master.receive(buf, kArrives), 25);
    EXPECT_EQ(buf[3], static_cast<std::uint8_t>(FrameType::cyclic_response));
    EXPECT_EQ(master.receive(buf, 100ms), 0);
  }
}

// Injects, from end a: an IPv4 frame, three 0x88B5 frames that cannot be M-III frames, then a
// good one; the slaves on end b get the good one only.
void inject_bad_then_good(const Wire& wire, const std::vector<std::uint8_t>& good) {
  wire.inject(ethernet(0x0800, std::vector<std::uint8_t>(40, 0x45)));
  wire.inject(ethernet(kEtherType, {0x03, 0x01, 0x00, 0x02, 0x08}, kEthHeaderSize + 5));  // header only
  auto overlong = command(16);
  overlong[4] = 64;  // declares 64 bytes of data in a 60-byte Ethernet frame
  wire.inject(ethernet(kEtherType, overlong));
  wire.inject(ethernet(kEtherType, command(8), 100));  // 83 bytes after a 17-byte frame
  wire.inject(ethernet(kEtherType, good));
}

TEST_F(M3RawTransport, ForeignAndMalformedFramesAreDroppedAndCounted) {
  for (const bool filter : {true, false}) {
    SCOPED_TRACE(filter ? "kernel filter" : "no kernel filter");
    RawTransport slaves(veth_->b(), Role::slaves, RawOptions{.kernel_filter = filter});
    EXPECT_EQ(slaves.kernel_filter(), filter);
    Wire wire_a(veth_->a());
    const auto good = command(48);
    inject_bad_then_good(wire_a, good);
    std::array<std::uint8_t, kMaxFrame> buf{};
    ASSERT_EQ(slaves.receive(buf, kArrives), static_cast<int>(good.size()))
        << "dropped here: " << slaves.stats().dropped_malformed << " malformed, " << slaves.stats().dropped_foreign
        << " foreign; " << counters(veth_->a()) << "; " << counters(veth_->b());
    EXPECT_TRUE(std::equal(good.begin(), good.end(), buf.begin()));
    EXPECT_EQ(slaves.receive(buf, 100ms), 0);
    const auto s = slaves.stats();
    EXPECT_EQ(s.received, 1u);
    EXPECT_EQ(s.dropped_malformed, 3u);  // 0x88B5 passes the kernel filter; framing is ours
    // The IPv4 frame: dropped in the kernel where the filter is on, else here, counted.
    EXPECT_EQ(s.dropped_foreign, filter ? 0u : 1u);
  }
}

TEST_F(M3RawTransport, SendErrorsAreCountedNotThrown) {
  RawTransport master(veth_->a(), Role::master);
  EXPECT_FALSE(master.send(std::vector<std::uint8_t>(kMinFrame - 1)));
  EXPECT_FALSE(master.send(std::vector<std::uint8_t>(kMaxFrame + 1)));
  EXPECT_EQ(master.stats().send_errors, 2u);
  EXPECT_EQ(master.stats().sent, 0u);
}

TEST(M3RawTransportErrors, MissingInterfaceNamesTheSpec) {
  if (::geteuid() != 0) GTEST_SKIP() << "without root the privilege error comes first";
  try {
    open_transport("raw:otnosuchif0", Role::master);
    FAIL() << "opened a missing interface";
  } catch (const TransportError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("raw:otnosuchif0"), std::string::npos) << msg;
    EXPECT_NE(msg.find("no network interface 'otnosuchif0'"), std::string::npos) << msg;
  }
  try {
    RawTransport lo("lo", Role::slaves);
    FAIL() << "opened the loopback interface";
  } catch (const TransportError& e) {
    EXPECT_NE(std::string(e.what()).find("raw:lo"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("not an Ethernet interface"), std::string::npos) << e.what();
  }
}

TEST(M3RawTransportErrors, MissingPrivilegeSaysWhatIsNeeded) {
  // A child process that gives up root (and with it CAP_NET_RAW) opens a raw transport.
  if (::geteuid() != 0) GTEST_SKIP() << "needs root to drop privileges in a child";
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    if (::setgid(65534) != 0 || ::setuid(65534) != 0) ::_exit(3);
    try {
      RawTransport t("lo", Role::master);
      ::_exit(2);
    } catch (const TransportError& e) {
      const std::string msg = e.what();
      ::_exit(msg.find("raw:lo") != std::string::npos && msg.find("needs root or CAP_NET_RAW") != std::string::npos ? 0 : 1);
    }
  }
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  if (WEXITSTATUS(status) == 3) GTEST_SKIP() << "this environment does not let root become nobody (setuid)";
  EXPECT_EQ(WEXITSTATUS(status), 0) << "1: wrong message, 2: opened without privilege";
}

}  // namespace
}  // namespace omnitwin::m3
