// Tests bus_emulators/tml/tml_relay: the relay axis between a host on RS-232 and drives on CAN
// (seed 003 chapter 2): a host query for another axis goes onto CAN and its answer, addressed to
// the host (relay axis + HOST bit), comes back; the relay's own axis is served locally and not
// forwarded; TMLCAN and TechCAN. Found in review: through TechCAN, whose TakeData/TakeData2 carry
// no destination, the answers reached the host with ID code 0000; the bytes on RS-232 are checked.
#include "bus_emulators/tml/tml_relay.hpp"

#include <gtest/gtest.h>

#include <memory>
#include <vector>

#include "bus_emulators/tml/tml_can_node.hpp"
#include "bus_emulators/tml/tml_serial.hpp"

namespace omnitwin::tml {
namespace {

struct Rig {
  explicit Rig(Protocol p) {
    DriveSetup own;
    own.axis = 20;
    own.host_axis = 20;
    own.protocol = Protocol::rs232;
    relay_drive = std::make_unique<TmlDrive>(own, [this](const Message& m, SimTime) { host.push_back(m); });
    relay_drive->power_on(0);
    DriveSetup other;
    other.axis = 5;
    other.host_axis = 20;
    other.protocol = p;
    node = std::make_unique<TmlCanNode>(other, [this](const can::Frame& f, SimTime t) {
      relay->from_can(f, t);  // the relay hears the bus
      return true;
    });
    node->power_on(0);
    relay = std::make_unique<TmlRelay>(*relay_drive, p, [this](const can::Frame& f, SimTime t) {
      ++frames;
      node->on_frame(f, t);
      return true;
    }, [this](const Message& m, SimTime) { host.push_back(m); });
  }
  std::unique_ptr<TmlDrive> relay_drive;
  std::unique_ptr<TmlCanNode> node;
  std::unique_ptr<TmlRelay> relay;
  std::vector<Message> host;
  int frames = 0;
};

class TmlRelayTest : public ::testing::TestWithParam<Protocol> {};

TEST_P(TmlRelayTest, AQueryForAnotherAxisIsForwardedAndAnsweredToTheHost) {
  Rig r(GetParam());
  // The PC (axis 20 with the HOST bit) asks axis 5 for KPP.
  r.relay->from_host(give_me_data(axis_id_code(5), host_id_code(20), 0x025E, false), 0);
  EXPECT_EQ(r.frames, 1);
  ASSERT_EQ(r.host.size(), 1u);
  const Classified c = classify(r.host[0]);
  EXPECT_EQ(c.kind, Kind::take_data);
  EXPECT_EQ(c.address, 0x025E);
  EXPECT_EQ(c.value, 0x0120u);  // the power-on KPP
  EXPECT_EQ(r.relay->stats().to_host, 1u);
}

TEST_P(TmlRelayTest, TheRelaysOwnAxisIsServedLocally) {
  Rig r(GetParam());
  r.relay->from_host(*assign16(axis_id_code(20), 0x025E, 7), 0);
  EXPECT_EQ(r.frames, 0);  // not forwarded
  std::uint32_t v = 0;
  ASSERT_TRUE(r.relay_drive->read(0x025E, false, v));
  EXPECT_EQ(v, 7u);
  // An assignment to axis 5 goes onto CAN and reaches it.
  r.relay->from_host(*assign16(axis_id_code(5), 0x025E, 9), 0);
  EXPECT_EQ(r.frames, 1);
  ASSERT_TRUE(r.node->drive().read(0x025E, false, v));
  EXPECT_EQ(v, 9u);
}

TEST_P(TmlRelayTest, AnswersThroughTechCanCarryTheHostsIdCode) {
  Rig r(GetParam());
  // Host 20 (ID code 0141) asks axis 5 for KPP and for SR32; both answers go back over RS-232.
  r.relay->from_host(give_me_data(axis_id_code(5), host_id_code(20), 0x025E, false), 0);
  r.relay->from_host(give_me_data2(axis_id_code(5), host_id_code(20), 0x090E, true), 0);
  ASSERT_EQ(r.host.size(), 2u);
  auto bytes = [](const Message& m) {
    const Packet p = encode_packet(m);
    return std::vector<std::uint8_t>(p.bytes.begin(), p.bytes.begin() + p.size);
  };
  // TakeData KPP = 0x0120 from axis 5 (sender 0050) to 0141.
  EXPECT_EQ(bytes(r.host[0]),
            (std::vector<std::uint8_t>{0x0A, 0x01, 0x41, 0xB4, 0x04, 0x00, 0x50, 0x02, 0x5E, 0x01, 0x20, 0xD5}));
  // TakeData2 SR32 (SRL 0400: axis off, nothing moving; SRH 0) from axis 5 (D505) to 0141.
  EXPECT_EQ(bytes(r.host[1]),
            (std::vector<std::uint8_t>{0x0A, 0x01, 0x41, 0xD5, 0x05, 0x09, 0x0E, 0x04, 0x00, 0x00, 0x00, 0x41}));
}

INSTANTIATE_TEST_SUITE_P(Protocols, TmlRelayTest, ::testing::Values(Protocol::tmlcan, Protocol::techcan),
                         [](const auto& info) { return std::string(to_string(info.param)); });

}  // namespace
}  // namespace omnitwin::tml
