// Tests bus_emulators/ethercat/transport/ec_transport: spec parsing (kinds, defaults, IPv6
// brackets, the errors and their messages naming the spec), open_transport() dispatch by kind,
// and check_pdu(), the one rule every transport applies to what it receives.
#include "bus_emulators/ethercat/transport/ec_transport.hpp"

#include "bus_emulators/ethercat/ec_frame.hpp"
#include "bus_emulators/ethercat/transport/ec_transport_mem.hpp"
#include "bus_emulators/ethercat/transport/ec_transport_udp.hpp"

#include <gtest/gtest.h>

#include <array>
#include <string>
#include <vector>

namespace omnitwin::ethercat {
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

TEST(EcTransportSpec, ParsesEachKind) {
  TransportSpec r = parse_transport_spec("raw:eth1");
  EXPECT_EQ(r.kind, TransportSpec::Kind::raw);
  EXPECT_EQ(r.name, "eth1");
  EXPECT_EQ(r.canonical(), "raw:eth1");

  TransportSpec u = parse_transport_spec("udp:192.168.1.7:40000");
  EXPECT_EQ(u.kind, TransportSpec::Kind::udp);
  EXPECT_EQ(u.name, "192.168.1.7");
  EXPECT_EQ(u.port, 40000);
  EXPECT_EQ(u.canonical(), "udp:192.168.1.7:40000");

  TransportSpec d = parse_transport_spec("udp:localhost");
  EXPECT_EQ(d.name, "localhost");
  EXPECT_EQ(d.port, 0x88A4);  // 34980, the EtherCAT UDP port
  EXPECT_EQ(d.canonical(), "udp:localhost:34980");

  TransportSpec v6 = parse_transport_spec("udp:[::1]:48800");
  EXPECT_EQ(v6.name, "::1");
  EXPECT_EQ(v6.port, 48800);
  EXPECT_EQ(v6.canonical(), "udp:[::1]:48800");
  EXPECT_EQ(parse_transport_spec("udp:[fe80::1]").port, 34980);

  TransportSpec m = parse_transport_spec("mem:bench");
  EXPECT_EQ(m.kind, TransportSpec::Kind::mem);
  EXPECT_EQ(m.name, "bench");
}

TEST(EcTransportSpec, RejectsBadSpecsNamingThem) {
  for (const char* spec : {"raw:", "raw:averyveryverylongname0", "raw:a/b", "udp:", "udp::34980", "udp:1.2.3.4:",
                           "udp:1.2.3.4:65536", "udp:1.2.3.4:12ab", "udp:::1:34980", "udp:[::1",
                           "udp:[::1]34980", "mem:", "eth0", "can:x", ""}) {
    const std::string msg = spec_error(spec);
    EXPECT_NE(msg, "") << spec << " was accepted";
    EXPECT_NE(msg.find("'" + std::string(spec) + "'"), std::string::npos) << msg;
  }
  EXPECT_NE(spec_error("raw:averyveryverylongname0").find("longer than 15"), std::string::npos);
  EXPECT_NE(spec_error("udp:1.2.3.4:65536").find("1..65535"), std::string::npos);
  EXPECT_NE(spec_error("udp:::1:34980").find("brackets"), std::string::npos);
  EXPECT_NE(spec_error("tcp:x").find("unknown transport 'tcp'"), std::string::npos);
}

TEST(EcTransportOpen, DispatchesByKind) {
  auto m = open_transport("mem:ec-transport-open", Role::master);
  auto s = open_transport("mem:ec-transport-open", Role::slaves);
  EXPECT_NE(dynamic_cast<MemTransport*>(m.get()), nullptr);
  EXPECT_EQ(m->describe(), "mem:ec-transport-open (master)");
  EXPECT_EQ(s->describe(), "mem:ec-transport-open (slaves)");
  auto u = open_transport("udp:127.0.0.1:48890", Role::slaves);
  ASSERT_NE(dynamic_cast<UdpTransport*>(u.get()), nullptr);
  EXPECT_EQ(dynamic_cast<UdpTransport*>(u.get())->local_port(), 48890);
  EXPECT_GE(u->fd(), 0);
  EXPECT_THROW(open_transport("bogus:x", Role::master), TransportError);
}

// Port 0 on the slaves' side binds a free port (a concurrent run's segment of its own); a
// master cannot be sent to port 0.
TEST(EcTransportOpen, SlavesOnPortZeroGetAFreePort) {
  auto a = open_transport("udp:127.0.0.1:0", Role::slaves);
  auto b = open_transport("udp:127.0.0.1:0", Role::slaves);
  const auto pa = dynamic_cast<UdpTransport*>(a.get())->local_port();
  const auto pb = dynamic_cast<UdpTransport*>(b.get())->local_port();
  EXPECT_NE(pa, 0);
  EXPECT_NE(pa, pb);
  EXPECT_THROW(open_transport("udp:127.0.0.1:0", Role::master), TransportError);
}

TEST(EcTransportCheckPdu, AcceptsType1AndTrimsToTheHeaderLength) {
  std::array<std::uint8_t, 60> buf{};  // a BRD of 2 bytes, then Ethernet padding
  PduBuilder b(buf);
  ASSERT_GE(b.add(Cmd::brd, 7, 0, 0x0130, 2), 0);
  const std::size_t n = b.finish();
  ASSERT_EQ(n, 16u);
  std::size_t size = 0;
  EXPECT_EQ(check_pdu(buf.data(), buf.size(), size), PduCheck::ok);
  EXPECT_EQ(size, 16u);
  EXPECT_EQ(check_pdu(buf.data(), 16, size), PduCheck::ok);
}

TEST(EcTransportCheckPdu, SortsOutForeignAndMalformed) {
  std::size_t size = 99;
  // Type 5 (mailbox gateway) and type 4 (network variables): not ours.
  std::array<std::uint8_t, 16> t5{0x0e, 0x50};
  EXPECT_EQ(check_pdu(t5.data(), t5.size(), size), PduCheck::foreign);
  std::array<std::uint8_t, 16> t4{0x0e, 0x40};
  EXPECT_EQ(check_pdu(t4.data(), t4.size(), size), PduCheck::foreign);
  // Type 1 but: fewer than 2 bytes, fewer than 14 bytes, a header length of 0, a header
  // length beyond the bytes present.
  std::array<std::uint8_t, 16> ok{0x0e, 0x10};
  EXPECT_EQ(check_pdu(ok.data(), 1, size), PduCheck::malformed);
  EXPECT_EQ(check_pdu(ok.data(), 13, size), PduCheck::malformed);
  std::array<std::uint8_t, 46> empty{0x00, 0x10};
  EXPECT_EQ(check_pdu(empty.data(), empty.size(), size), PduCheck::malformed);
  std::array<std::uint8_t, 46> longer{0x64, 0x10};  // declares 100 bytes
  EXPECT_EQ(check_pdu(longer.data(), longer.size(), size), PduCheck::malformed);
  EXPECT_EQ(size, 99u);  // untouched unless ok
  EXPECT_EQ(check_pdu(ok.data(), ok.size(), size), PduCheck::ok);
  EXPECT_EQ(size, 16u);
}

}  // namespace
}  // namespace omnitwin::ethercat
