// Tests bus_emulators/mechatrolink3/transport/m3_transport: spec parsing (kinds, the default
// port 34997, port 0, IPv6 brackets, bad specs rejected with the spec named), open_transport()
// dispatch by kind (spec() naming the real port of "udp:HOST:0"), and check_frame(), the one
// framing rule every transport applies to what it receives (a bad FCS is not its business).
#include "bus_emulators/mechatrolink3/transport/m3_transport.hpp"

#include "bus_emulators/mechatrolink3/transport/m3_transport_mem.hpp"
#include "bus_emulators/mechatrolink3/transport/m3_transport_udp.hpp"

#include <gtest/gtest.h>

#include <array>
#include <string>
#include <vector>

namespace omnitwin::m3 {
namespace {

// The TransportError message for `spec`, or "" when none was thrown.
std::string spec_error(std::string_view spec) {
  try {
    parse_transport_spec(spec);
  } catch (const TransportError& e) {
    return e.what();
  }
  return "";
}

// A CMD frame of `n` data bytes to the first slave, followed by `extra` zero bytes.
std::vector<std::uint8_t> command(std::size_t n, std::size_t extra = 0) {
  std::vector<std::uint8_t> data(n, 0x5A);
  std::vector<std::uint8_t> out(kMaxFrame + extra, 0);
  const FrameSpec f{.dst = kFirstSlave, .src = kC1Master, .type = FrameType::cyclic_command, .data = data};
  out.resize(encode(f, out) + extra);
  return out;
}

TEST(M3TransportSpec, ParsesEachKind) {
  const TransportSpec r = parse_transport_spec("raw:eth1");
  EXPECT_EQ(r.kind, TransportSpec::Kind::raw);
  EXPECT_EQ(r.name, "eth1");
  EXPECT_EQ(r.canonical(), "raw:eth1");

  const TransportSpec u = parse_transport_spec("udp:192.168.1.7:40000");
  EXPECT_EQ(u.kind, TransportSpec::Kind::udp);
  EXPECT_EQ(u.name, "192.168.1.7");
  EXPECT_EQ(u.port, 40000);
  EXPECT_EQ(u.canonical(), "udp:192.168.1.7:40000");

  const TransportSpec d = parse_transport_spec("udp:localhost");
  EXPECT_EQ(d.port, 34997);  // 0x88B5, as the EtherType
  EXPECT_EQ(d.canonical(), "udp:localhost:34997");
  EXPECT_EQ(parse_transport_spec("udp:127.0.0.1:0").port, 0);

  const TransportSpec v6 = parse_transport_spec("udp:[::1]:48900");
  EXPECT_EQ(v6.name, "::1");
  EXPECT_EQ(v6.canonical(), "udp:[::1]:48900");
  EXPECT_EQ(parse_transport_spec("udp:[fe80::1]").port, 34997);

  const TransportSpec m = parse_transport_spec("mem:line");
  EXPECT_EQ(m.kind, TransportSpec::Kind::mem);
  EXPECT_EQ(m.canonical(), "mem:line");
}

TEST(M3TransportSpec, RejectsBadSpecsNamingThem) {
  for (const char* spec : {"raw:", "raw:averyveryverylongname0", "raw:a/b", "udp:", "udp::34997", "udp:1.2.3.4:",
                           "udp:1.2.3.4:65536", "udp:1.2.3.4:12ab", "udp:::1:34997", "udp:[::1",
                           "udp:[::1]34997", "mem:", "eth0", "can:x", ""}) {
    const std::string msg = spec_error(spec);
    EXPECT_NE(msg, "") << spec << " was accepted";
    EXPECT_NE(msg.find("MECHATROLINK-III transport spec '" + std::string(spec) + "'"), std::string::npos) << msg;
  }
  EXPECT_NE(spec_error("raw:averyveryverylongname0").find("longer than 15"), std::string::npos);
  EXPECT_NE(spec_error("udp:1.2.3.4:65536").find("1..65535"), std::string::npos);
  EXPECT_NE(spec_error("udp:::1:34997").find("brackets"), std::string::npos);
  EXPECT_NE(spec_error("tcp:x").find("unknown transport 'tcp'"), std::string::npos);
  try {
    open_transport("bogus:x", Role::master);
    FAIL() << "opened a bogus spec";
  } catch (const TransportError& e) {
    EXPECT_NE(std::string(e.what()).find("'bogus:x'"), std::string::npos) << e.what();
  }
}

TEST(M3TransportOpen, DispatchesByKind) {
  auto m = open_transport("mem:m3-transport-open", Role::master);
  auto s = open_transport("mem:m3-transport-open", Role::slaves);
  EXPECT_NE(dynamic_cast<MemTransport*>(m.get()), nullptr);
  EXPECT_EQ(m->spec(), "mem:m3-transport-open");
  EXPECT_EQ(m->describe(), "mem:m3-transport-open (master)");
  EXPECT_EQ(s->describe(), "mem:m3-transport-open (slaves)");
  auto u = open_transport("udp:127.0.0.1:0", Role::slaves);
  ASSERT_NE(dynamic_cast<UdpTransport*>(u.get()), nullptr);
  EXPECT_GE(u->fd(), 0);
  EXPECT_THROW(open_transport("raw:", Role::master), TransportError);
}

// Port 0 on the slaves' side binds a free port that spec() and describe() name, so the master
// can be given it; a master cannot send to port 0.
TEST(M3TransportOpen, SlavesOnPortZeroGetAFreePortThatSpecNames) {
  auto a = open_transport("udp:127.0.0.1:0", Role::slaves);
  auto b = open_transport("udp:127.0.0.1:0", Role::slaves);
  const auto pa = dynamic_cast<UdpTransport*>(a.get())->local_port();
  const auto pb = dynamic_cast<UdpTransport*>(b.get())->local_port();
  EXPECT_NE(pa, 0);
  EXPECT_NE(pa, pb);
  EXPECT_EQ(a->spec(), "udp:127.0.0.1:" + std::to_string(pa));
  EXPECT_EQ(a->describe(), "udp:127.0.0.1:" + std::to_string(pa) + " (slaves, local port " + std::to_string(pa) + ")");
  auto master = open_transport(a->spec(), Role::master);
  EXPECT_EQ(master->spec(), a->spec());  // the master names where it sends
  try {
    open_transport("udp:127.0.0.1:0", Role::master);
    FAIL() << "a master was opened towards port 0";
  } catch (const TransportError& e) {
    EXPECT_NE(std::string(e.what()).find("udp:127.0.0.1:0"), std::string::npos) << e.what();
  }
}

TEST(M3TransportCheckFrame, TrimsToTheDataLength) {
  const auto padded = command(8, 29);  // 17 bytes of frame, then padding
  std::size_t size = 0;
  EXPECT_EQ(check_frame(padded.data(), padded.size(), size), FrameCheck::ok);
  EXPECT_EQ(size, 17u);
  EXPECT_EQ(check_frame(padded.data(), 17, size), FrameCheck::ok);
  const auto big = command(64);
  EXPECT_EQ(check_frame(big.data(), big.size(), size), FrameCheck::ok);
  EXPECT_EQ(size, kMaxFrame);
}

TEST(M3TransportCheckFrame, PassesWhatOnlyTheStationCanRefuse) {
  std::size_t size = 0;
  auto corrupted = command(16);
  corrupted[9] ^= 0x04;  // a bit flipped on the line: the FCS no longer matches
  FrameView v;
  ASSERT_EQ(decode(corrupted, v), FrameStatus::bad_fcs);
  EXPECT_EQ(check_frame(corrupted.data(), corrupted.size(), size), FrameCheck::ok);
  EXPECT_EQ(size, corrupted.size());
  auto odd = command(16);
  odd[3] = 0x7E;  // an unknown type, reserved control bits, a bad address: the station's call
  odd[2] = 0xE0;
  odd[0] = 0x00;
  EXPECT_EQ(check_frame(odd.data(), odd.size(), size), FrameCheck::ok);
}

TEST(M3TransportCheckFrame, RefusesWhatCannotBeAFrame) {
  std::size_t size = 99;
  const auto f = command(16);
  EXPECT_EQ(check_frame(f.data(), kMinFrame - 1, size), FrameCheck::malformed);  // shorter than header + FCS
  EXPECT_EQ(check_frame(f.data(), f.size() - 1, size), FrameCheck::malformed);   // data length beyond the bytes
  std::vector<std::uint8_t> over(200, 0);
  over[4] = 65;  // more than 64 bytes of data, even with the bytes there
  EXPECT_EQ(check_frame(over.data(), over.size(), size), FrameCheck::malformed);
  EXPECT_EQ(size, 99u);  // untouched unless ok
}

}  // namespace
}  // namespace omnitwin::m3
