// Tests twin/line_transport: the scenario's transport choice for a frame bus turned into the
// slaves' spec and the master's --iface. raw:IFACE gives the master its own interface (raw:
// added when the scenario left it out); udp and mem are used as given with the master's iface
// left to the opened transport; veth makes a pair of the run's own (as root) whose ends go to
// the two sides; auto is veth where a pair can be made, else UDP on loopback: a free port in
// lockstep, the documented one in realtime.
#include "twin/line_transport.hpp"

#include <gtest/gtest.h>

#include "bus_emulators/ethercat/transport/ec_veth.hpp"

namespace omnitwin::twin {
namespace {

TEST(LineTransport, RawGivesTheMasterItsOwnInterface) {
  const LineTransport a = choose_line_transport("raw:eth1", "eth2", true, "udp:127.0.0.1:1");
  EXPECT_EQ(a.slaves_spec, "raw:eth1");
  EXPECT_EQ(a.master_iface, "raw:eth2");
  EXPECT_EQ(choose_line_transport("raw:eth1", "raw:eth3", true, "").master_iface, "raw:eth3");
  EXPECT_EQ(a.veth, nullptr);
}

TEST(LineTransport, UdpAndMemAreUsedAsGiven) {
  const LineTransport u = choose_line_transport("udp:127.0.0.1:4000", "", false, "udp:127.0.0.1:1");
  EXPECT_EQ(u.slaves_spec, "udp:127.0.0.1:4000");
  EXPECT_EQ(u.master_iface, "") << "the opened transport names it";
  EXPECT_EQ(choose_line_transport("mem:x", "", true, "").slaves_spec, "mem:x");
}

TEST(LineTransport, AutoIsVethWhereAPairCanBeMadeElseUdpOnLoopback) {
  const auto why = ethercat::VethPair::unavailable_reason();
  const LineTransport lockstep = choose_line_transport("auto", "", true, "udp:127.0.0.1:34997");
  const LineTransport realtime = choose_line_transport("auto", "", false, "udp:127.0.0.1:34997");
  if (why) {
    EXPECT_EQ(lockstep.slaves_spec, "udp:127.0.0.1:0") << "lockstep: a free port of its own";
    EXPECT_EQ(realtime.slaves_spec, "udp:127.0.0.1:34997") << "realtime: the documented port";
    return;
  }
  for (const LineTransport* t : {&lockstep, &realtime}) {
    ASSERT_NE(t->veth, nullptr);
    EXPECT_EQ(t->slaves_spec, "raw:" + t->veth->b());
    EXPECT_EQ(t->master_iface, "raw:" + t->veth->a());
  }
  EXPECT_NE(lockstep.veth->a(), realtime.veth->a()) << "a pair per run";
}

}  // namespace
}  // namespace omnitwin::twin
