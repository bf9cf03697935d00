// Tests bus_emulators/ethercat/ec_chain: a line of ESCs — BRD counting slaves, the 1 − position
// convention of position addressing across the line, two slaves sharing one logical byte (4 bits
// each), DC receive-time latches along the line (port 0/1 times give the propagation delays),
// drift compensation by FRMW converging with ±50 ppm oscillators, DL status and WKC under a
// link break and a slave's power loss and return, and malformed frames counted without a crash.
#include "bus_emulators/ethercat/ec_chain.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <memory>
#include <random>
#include <vector>

#include "bus_emulators/ethercat/ec_registers.hpp"

namespace omnitwin::ethercat {
namespace {

struct Line {
  std::vector<std::unique_ptr<Esc>> escs;
  EscChain chain;
  explicit Line(int n, std::vector<double> drift = {}, std::vector<std::int64_t> power_on = {}) {
    for (int i = 0; i < n; ++i) {
      EscConfig c;
      if (i < static_cast<int>(drift.size())) c.oscillator_drift = drift[static_cast<std::size_t>(i)];
      if (i < static_cast<int>(power_on.size())) c.power_on_time_ns = power_on[static_cast<std::size_t>(i)];
      escs.push_back(std::make_unique<Esc>(c, nullptr));
      chain.add(escs.back().get());
    }
  }
};

struct Out {
  std::vector<std::uint8_t> data;
  std::uint16_t wkc = 0;
  std::uint16_t adp = 0;
  bool returned = false;
};

Out send(EscChain& ch, Cmd c, std::uint16_t adp, std::uint16_t ado, std::vector<std::uint8_t> d, SimTime t = 0) {
  std::array<std::uint8_t, kMaxPdu> buf{};
  PduBuilder b(buf);
  const int off = b.add(c, 0, adp, ado, static_cast<std::uint16_t>(d.size()), d.data());
  const std::size_t n = b.finish();
  Out o;
  o.returned = ch.process(std::span(buf.data(), n), t);
  o.data.assign(buf.begin() + off, buf.begin() + off + static_cast<std::ptrdiff_t>(d.size()));
  o.wkc = get_u16(buf.data() + off + d.size());
  o.adp = get_u16(buf.data() + off - 8);
  return o;
}

std::vector<std::uint8_t> le16(std::uint16_t v) { return {static_cast<std::uint8_t>(v), static_cast<std::uint8_t>(v >> 8)}; }
std::vector<std::uint8_t> le64(std::uint64_t v) {
  std::vector<std::uint8_t> d(8);
  put_u64(d.data(), v);
  return d;
}

void address_all(Line& l) {
  for (int i = 0; i < static_cast<int>(l.escs.size()); ++i) {
    send(l.chain, Cmd::apwr, static_cast<std::uint16_t>(-i), reg::kStationAddress, le16(static_cast<std::uint16_t>(0x1001 + i)));
  }
}

TEST(EcChain, BroadcastReadCountsSlaves) {
  Line l(5);
  const Out o = send(l.chain, Cmd::brd, 0, 0x0000, {0, 0});
  EXPECT_TRUE(o.returned);
  EXPECT_EQ(o.wkc, 5);
  EXPECT_EQ(o.adp, 5);
  EXPECT_EQ(o.data[0], 0x11);
  EXPECT_EQ(l.chain.stats().frames, 1u);
  EXPECT_EQ(l.chain.stats().returned, 1u);
}

TEST(EcChain, PositionAddressingUsesOneMinusPosition) {
  Line l(3);
  address_all(l);
  EXPECT_EQ(l.escs[0]->station_address(), 0x1001);
  EXPECT_EQ(l.escs[2]->station_address(), 0x1003);
  const Out o = send(l.chain, Cmd::aprd, static_cast<std::uint16_t>(-2), reg::kStationAddress, {0, 0});
  EXPECT_EQ(o.wkc, 1);
  EXPECT_EQ(get_u16(o.data.data()), 0x1003);
  EXPECT_EQ(o.adp, 1);  // 0xFFFE + 3
  EXPECT_EQ(send(l.chain, Cmd::aprd, static_cast<std::uint16_t>(-3), 0, {0}).wkc, 0);
  EXPECT_EQ(send(l.chain, Cmd::fprd, 0x1002, reg::kStationAddress, {0, 0}).wkc, 1);
}

TEST(EcChain, TwoSlavesShareOneLogicalByteFourBitsEach) {
  Line l(2);
  for (int i = 0; i < 2; ++i) {
    Esc& e = *l.escs[static_cast<std::size_t>(i)];
    (void)e;
    // FMMU0: write, logical 0x100 bits (4i .. 4i+3) → physical 0x0F00 bits 0..3.
    std::vector<std::uint8_t> f(16, 0);
    put_u32(f.data(), 0x100);
    put_u16(f.data() + 4, 1);
    f[6] = static_cast<std::uint8_t>(4 * i);
    f[7] = static_cast<std::uint8_t>(4 * i + 3);
    put_u16(f.data() + 8, 0x0F00);
    f[11] = 2;
    f[12] = 1;
    send(l.chain, Cmd::apwr, static_cast<std::uint16_t>(-i), reg::kFmmu0, f);
    // FMMU1: read, logical 0x101 bits (4i ..) ← physical 0x0F10 bits 4..7.
    put_u32(f.data(), 0x101);
    put_u16(f.data() + 8, 0x0F10);
    f[10] = 4;
    f[11] = 1;
    send(l.chain, Cmd::apwr, static_cast<std::uint16_t>(-i), reg::kFmmu0 + 16, f);
    send(l.chain, Cmd::apwr, static_cast<std::uint16_t>(-i), 0x0F10, {static_cast<std::uint8_t>(i == 0 ? 0xA5 : 0x3C)});
  }
  const Out o = send(l.chain, Cmd::lrw, 0x0100, 0x0000, {0x9E, 0x00});
  EXPECT_EQ(o.wkc, 6);  // 2 slaves × (write 2 + read 1)
  EXPECT_EQ(l.escs[0]->read8(0x0F00), 0x0E);  // low nibble of 0x9E
  EXPECT_EQ(l.escs[1]->read8(0x0F00), 0x09);  // high nibble
  EXPECT_EQ(o.data[1], 0x3A);                 // slave 0 bits 4..7 of 0xA5 → low nibble, slave 1 of 0x3C → high
  EXPECT_EQ(o.data[0], 0x9E);
  // A datagram that covers only the inputs byte: reads only.
  EXPECT_EQ(send(l.chain, Cmd::lrd, 0x0101, 0x0000, {0}).wkc, 2);
  EXPECT_EQ(send(l.chain, Cmd::lwr, 0x0100, 0x0000, {0xFF}).wkc, 2);
  EXPECT_EQ(l.escs[0]->read8(0x0F00), 0x0F);
}

TEST(EcChain, ReceiveTimeLatchesGiveThePropagationDelays) {
  Line l(3, {}, {1'000'000, 5'000'000, 42});
  const SimTime t0 = 10'000'000;
  EXPECT_EQ(send(l.chain, Cmd::bwr, 0, reg::kDcReceiveTimePort0, {0, 0, 0, 0}, t0).wkc, 3);
  const std::int64_t fd = 600;
  std::vector<std::uint32_t> p0(3), p1(3);
  for (int i = 0; i < 3; ++i) {
    const Out o = send(l.chain, Cmd::aprd, static_cast<std::uint16_t>(-i), reg::kDcReceiveTimePort0, std::vector<std::uint8_t>(8, 0), t0 + 100'000);
    p0[static_cast<std::size_t>(i)] = get_u32(o.data.data());
    p1[static_cast<std::size_t>(i)] = get_u32(o.data.data() + 4);
    const Out e = send(l.chain, Cmd::aprd, static_cast<std::uint16_t>(-i), reg::kDcReceiveTimeEpu, std::vector<std::uint8_t>(8, 0), t0 + 100'000);
    EXPECT_EQ(static_cast<std::uint32_t>(get_u64(e.data.data())), p0[static_cast<std::size_t>(i)]);
  }
  EXPECT_EQ(p0[0], static_cast<std::uint32_t>(1'000'000 + t0));
  EXPECT_EQ(p0[1], static_cast<std::uint32_t>(5'000'000 + t0 + fd));
  EXPECT_EQ(p0[2], static_cast<std::uint32_t>(42 + t0 + 2 * fd));
  // Round trips below each slave: 4·fd, 2·fd; the master's delay per hop = difference / 2.
  EXPECT_EQ(p1[0] - p0[0], 4 * fd);
  EXPECT_EQ(p1[1] - p0[1], 2 * fd);
  EXPECT_EQ(((p1[0] - p0[0]) - (p1[1] - p0[1])) / 2, fd);
  EXPECT_EQ(l.chain.last_return_time(), t0 + 100'000 + 5 * fd);  // of the last frame: 3 forward, 2 back
}

TEST(EcChain, DriftCompensationConvergesWithFrmw) {
  // Reference clock slave 0 (+20 ppm), the others ±50 ppm, different power-on times.
  Line l(3, {20e-6, 50e-6, -50e-6}, {3'000'000, 17'000'000, 123'456});
  address_all(l);
  SimTime t = 1'000'000;
  send(l.chain, Cmd::bwr, 0, reg::kDcReceiveTimePort0, {0, 0, 0, 0}, t);
  std::vector<std::uint64_t> epu(3);
  std::vector<std::uint32_t> p0(3), p1(3);
  for (int i = 0; i < 3; ++i) {
    const auto a = static_cast<std::uint16_t>(0x1001 + i);
    epu[static_cast<std::size_t>(i)] = get_u64(send(l.chain, Cmd::fprd, a, reg::kDcReceiveTimeEpu, std::vector<std::uint8_t>(8, 0), t).data.data());
    const Out o = send(l.chain, Cmd::fprd, a, reg::kDcReceiveTimePort0, std::vector<std::uint8_t>(8, 0), t);
    p0[static_cast<std::size_t>(i)] = get_u32(o.data.data());
    p1[static_cast<std::size_t>(i)] = get_u32(o.data.data() + 4);
  }
  // Delays as a master computes them, offsets so that system time matches the reference.
  std::vector<std::uint32_t> delay(3, 0);
  delay[1] = ((p1[0] - p0[0]) - (p1[1] - p0[1])) / 2;
  delay[2] = delay[1] + (p1[1] - p0[1]) / 2;
  for (int i = 1; i < 3; ++i) {
    const auto a = static_cast<std::uint16_t>(0x1001 + i);
    const std::uint64_t off = epu[0] + delay[static_cast<std::size_t>(i)] - epu[static_cast<std::size_t>(i)];
    send(l.chain, Cmd::fpwr, a, reg::kDcSystemTimeOffset, le64(off), t);
    std::vector<std::uint8_t> d(4);
    put_u32(d.data(), delay[static_cast<std::size_t>(i)]);
    send(l.chain, Cmd::fpwr, a, reg::kDcSystemTimeDelay, d, t);
    send(l.chain, Cmd::fpwr, a, reg::kDcSpeedCounterStart, le16(0x1000), t);
  }
  EXPECT_EQ(delay[1], 600u);
  EXPECT_EQ(delay[2], 1200u);
  std::int64_t worst_late = 0;
  for (int k = 0; k < 3000; ++k) {
    t += 1'000'000;
    const Out o = send(l.chain, Cmd::frmw, 0x1001, reg::kDcSystemTime, std::vector<std::uint8_t>(8, 0), t);
    ASSERT_EQ(o.wkc, 3);
    if (k >= 2000) {
      for (int i = 1; i < 3; ++i) {
        const std::uint32_t r = l.escs[static_cast<std::size_t>(i)]->read32(reg::kDcSystemTimeDiff);
        worst_late = std::max<std::int64_t>(worst_late, r & 0x7FFFFFFF);
      }
    }
  }
  EXPECT_LT(worst_late, 20);
  for (int i = 1; i < 3; ++i) {
    const std::int64_t d = l.escs[static_cast<std::size_t>(i)]->system_time(t) - l.escs[0]->system_time(t);
    EXPECT_LT(std::llabs(d), 20) << "slave " << i;
  }
  // Without the loop the ±50 ppm clocks would be 3000 × 1 ms × 30..70 ppm = 90..210 µs apart.
}

TEST(EcChain, LinkBreakChangesDlStatusAndWkc) {
  Line l(3);
  EXPECT_EQ(l.escs[0]->read16(reg::kDlStatus) & 0x0F30, 0x0A30);  // middle: both ports open
  EXPECT_EQ(l.escs[2]->read16(reg::kDlStatus) & 0x0F30, 0x0610);  // end: port 1 closed
  l.chain.set_link_break(2);
  EXPECT_EQ(l.chain.reachable(), 2);
  EXPECT_EQ(l.escs[1]->read16(reg::kDlStatus) & 0x0F30, 0x0610);
  EXPECT_EQ(l.escs[2]->read16(reg::kDlStatus) & 0x0F30, 0x0500);  // cut off: no link, both ports closed
  EXPECT_EQ(l.escs[1]->read8(reg::kLostLinkCounter + 1), 1);
  EXPECT_EQ(l.escs[2]->read8(reg::kLostLinkCounter + 0), 1);
  Out o = send(l.chain, Cmd::brd, 0, 0, {0});
  EXPECT_TRUE(o.returned);
  EXPECT_EQ(o.wkc, 2);
  l.chain.set_link_break(0);
  o = send(l.chain, Cmd::brd, 0, 0, {0});
  EXPECT_FALSE(o.returned);
  l.chain.set_link_break(-1);
  EXPECT_EQ(send(l.chain, Cmd::brd, 0, 0, {0}).wkc, 3);
}

TEST(EcChain, PowerLossAndReturn) {
  Line l(3);
  address_all(l);
  send(l.chain, Cmd::bwr, 0, reg::kAlControl, le16(2), 0);
  EXPECT_EQ(l.escs[1]->al_state(), AlState::preop);
  l.chain.set_powered(1, false, 1000);
  EXPECT_EQ(send(l.chain, Cmd::brd, 0, 0, {0}, 2000).wkc, 1);
  EXPECT_EQ(l.escs[0]->read16(reg::kDlStatus) & 0x0F30, 0x0610);
  EXPECT_EQ(send(l.chain, Cmd::fprd, 0x1003, reg::kStationAddress, {0, 0}, 2000).wkc, 0);
  l.chain.set_powered(1, true, 3000);
  EXPECT_EQ(send(l.chain, Cmd::brd, 0, 0, {0}, 4000).wkc, 3);
  EXPECT_EQ(l.escs[1]->station_address(), 0);
  EXPECT_EQ(l.escs[1]->al_state(), AlState::init);
  EXPECT_EQ(l.escs[2]->station_address(), 0x1003);  // the others kept their state
  EXPECT_EQ(l.escs[2]->al_state(), AlState::preop);
}

TEST(EcChain, MalformedFramesAreCountedNeverCrash) {
  Line l(2);
  std::array<std::uint8_t, 4> junk{0x05, 0x20, 0, 0};
  EXPECT_FALSE(l.chain.process(junk, 0));
  EXPECT_EQ(l.chain.stats().malformed, 1u);
  std::mt19937 rng(7);
  std::array<std::uint8_t, 200> buf{};
  int returned = 0;
  for (int k = 0; k < 5000; ++k) {
    const std::size_t n = rng() % buf.size();
    for (std::size_t i = 0; i < n; ++i) buf[i] = static_cast<std::uint8_t>(rng());
    if (k % 2 == 0 && n >= 14) {  // make it parse sometimes: one datagram with a random command
      put_u16(buf.data(), static_cast<std::uint16_t>(0x1000 | (n - 2)));
      put_u16(buf.data() + 8, static_cast<std::uint16_t>(n - 14));
    }
    if (l.chain.process(std::span(buf.data(), n), k)) ++returned;
  }
  EXPECT_GT(returned, 100);
  EXPECT_EQ(l.chain.stats().frames, 5001u);
  EXPECT_EQ(l.chain.stats().malformed + l.chain.stats().returned, 5001u);
}

}  // namespace
}  // namespace omnitwin::ethercat
