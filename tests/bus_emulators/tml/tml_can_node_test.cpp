// Tests bus_emulators/tml/tml_can_node: the IDM drive on a CAN bus — TMLCAN (29-bit) and TechCAN
// (11-bit) frames in and out against the seed's golden vectors (KPP assignment, GiveMeData2 to a
// group → TakeData2, GiveMeData → TechCAN TakeData, TakeData2 of MER after a control error,
// SETSYNC's sync and set-master-time frames), and CANopen frames on the same bus ignored.
#include "bus_emulators/tml/tml_can_node.hpp"

#include <gtest/gtest.h>

#include <vector>

namespace omnitwin::tml {
namespace {

constexpr SimTime kMs = 1'000'000;
using Bytes = std::vector<std::uint8_t>;

Bytes payload(const can::Frame& f) { return {f.data.begin(), f.data.begin() + f.payload_size()}; }

struct NodeRig {
  std::vector<can::Frame> out;
  TmlCanNode node;
  SimTime now = 0;
  NodeRig(std::uint8_t axis, Protocol p, std::uint8_t host = 3)
      : node(make_setup(axis, p, host), [this](const can::Frame& f, SimTime) {
          out.push_back(f);
          return true;
        }) {
    node.power_on(0);
  }
  static DriveSetup make_setup(std::uint8_t axis, Protocol p, std::uint8_t host) {
    DriveSetup s;
    s.axis = axis, s.protocol = p, s.host_axis = host;
    return s;
  }
  void frame(const can::Frame& f) { node.on_frame(f, now); }
  // n periods with the wheel at `counts` (a fixed feedback).
  void run(int n, double counts = 0) {
    const double k = node.drive().core().counts_per_load_rad();
    for (int i = 0; i < n; ++i, now += kMs) node.step(now, drive::Feedback{counts / k, 0, 0});
  }
  // Axis on in position mode standing at 0, then the wheel pushed to −2 counts: POSERR = 2.
  void make_poserr_2() {
    node.drive().on_message(instruction(axis_id_code(node.drive().axis()), instr::axison), now);
    run(5);
    run(2, -2);
  }
};

TEST(TmlCanNode, TmlCanKppAssignmentGolden) {
  NodeRig r(5, Protocol::tmlcan);
  r.frame(can::make_data(0x0400A05E, {0x34, 0x12}, true));
  std::uint32_t v = 0;
  ASSERT_TRUE(r.node.drive().read(reg::kpp, false, v));
  EXPECT_EQ(v, 0x1234u);
  EXPECT_EQ(r.node.stats().delivered, 1u);
  EXPECT_TRUE(r.out.empty());  // type A: no answer on CAN
}

TEST(TmlCanNode, TmlCanGroupGiveMeData2AnsweredByEachMember) {
  NodeRig a(5, Protocol::tmlcan), b(7, Protocol::tmlcan);
  a.make_poserr_2();
  b.node.drive().on_message(instruction(axis_id_code(7), instr::axison), 0);
  b.run(5);
  b.run(2, -1);  // POSERR = 1
  const can::Frame req = can::make_data(0x16602004, {0x30, 0x00, 0x2A, 0x02}, true);
  a.frame(req);
  b.frame(req);
  ASSERT_EQ(a.out.size(), 1u);
  ASSERT_EQ(b.out.size(), 1u);
  EXPECT_TRUE(a.out[0].extended);
  EXPECT_EQ(a.out[0].id, 0x1A806005u);
  EXPECT_EQ(payload(a.out[0]), (Bytes{0x2A, 0x02, 0x02, 0x00}));
  EXPECT_EQ(b.out[0].id, 0x1A806007u);
  EXPECT_EQ(payload(b.out[0]), (Bytes{0x2A, 0x02, 0x01, 0x00}));
}

TEST(TmlCanNode, TmlCanIgnoresStandardFrames) {
  NodeRig r(5, Protocol::tmlcan);
  r.frame(can::make_data(0x125, {0x5E, 0x20, 0x34, 0x12}));
  EXPECT_EQ(r.node.stats().foreign, 1u);
  EXPECT_EQ(r.node.stats().delivered, 0u);
}

TEST(TmlCanNode, TechCanKppAndGiveMeDataGolden) {
  NodeRig r(5, Protocol::techcan);
  r.frame(can::make_data(0x125, {0x5E, 0x20, 0x34, 0x12}));
  std::uint32_t v = 0;
  ASSERT_TRUE(r.node.drive().read(reg::kpp, false, v));
  EXPECT_EQ(v, 0x1234u);
  r.make_poserr_2();
  r.frame(can::make_data(0x125, {0x04, 0xB0, 0x30, 0x00, 0x2A, 0x02}));
  ASSERT_EQ(r.out.size(), 1u);
  EXPECT_FALSE(r.out[0].extended);
  EXPECT_EQ(r.out[0].id, 0x165u);
  EXPECT_EQ(payload(r.out[0]), (Bytes{0x04, 0x28, 0x2A, 0x02, 0x02, 0x00}));
}

TEST(TmlCanNode, TechCanIgnoresCanopenFramesOnTheSameBus) {
  NodeRig r(5, Protocol::techcan);
  const std::vector<can::Frame> canopen{
      can::make_data(0x000, {0x01, 0x05}),                                      // NMT start node 5
      can::make_data(0x080, {}),                                                // SYNC
      can::make_data(0x085, {0x00, 0x00, 0x00, 0, 0, 0, 0, 0}),                 // EMCY
      can::make_data(0x100, {1, 2, 3, 4, 5, 6}),                                // TIME
      can::make_data(0x185, {0x37, 0x02}),                                      // TPDO1
      can::make_data(0x605, {0x40, 0x41, 0x60, 0x00, 0, 0, 0, 0}),              // SDO request
      can::make_data(0x705, {0x05}),                                            // heartbeat
      can::make_data(0x0400A05E, {0x34, 0x12}, true),                           // 29-bit TMLCAN
  };
  for (const can::Frame& f : canopen) r.frame(f);
  EXPECT_EQ(r.node.stats().foreign, canopen.size());
  EXPECT_EQ(r.node.stats().delivered, 0u);
  EXPECT_EQ(r.node.drive().stats().handled, 0u);
  EXPECT_TRUE(r.out.empty());
  // Answers of other drives are not for it either.
  r.frame(can::make_data(0x102, {0x00, 0xFC, 0x08, 0x08, 0x00}));
  EXPECT_EQ(r.node.stats().others_answers, 1u);
}

TEST(TmlCanNode, TechCanTakeData2OfMerAfterControlError) {
  NodeRig r(2, Protocol::techcan);
  r.frame(can::make_data(0x122, {0x07, 0x21, 0x08, 0x00}));  // MER_MASK (0x0307, opcode 2107) = 0x0008
  r.frame(can::make_data(0x122, {0x02, 0x21, 0x64, 0x00}));  // ERRMAX (0x0302) = 100
  r.frame(can::make_data(0x122, {0x03, 0x21, 0x05, 0x00}));  // TERRMAX (0x0303) = 5
  r.frame(can::make_data(0x122, {0x02, 0x01}));              // AXISON
  r.run(5);
  r.frame(can::make_data(0x122, {0x9E, 0x24, 0xA0, 0x86, 0x01, 0x00}));  // CPOS (249E) = 100000
  r.frame(can::make_data(0x122, {0xA0, 0x24, 0x00, 0x00, 0x14, 0x00}));  // CSPD (24A0) = 20 IU
  r.frame(can::make_data(0x122, {0x08, 0x01}));                          // UPD
  r.run(100);  // the wheel stays at 0
  ASSERT_FALSE(r.out.empty());
  EXPECT_EQ(r.out.back().id, 0x102u);  // the seed's example 5
  EXPECT_EQ(payload(r.out.back()), (Bytes{0x00, 0xFC, 0x08, 0x08, 0x00}));
}

TEST(TmlCanNode, TechCanSetSyncSendsSyncAndMasterTime) {
  NodeRig r(1, Protocol::techcan);
  r.frame(can::make_data(0x121, {0x04, 0x14, 0x14, 0x00}));  // SETSYNC (0x1404) 20
  r.run(21);
  ASSERT_EQ(r.out.size(), 2u);
  EXPECT_EQ(r.out[0].id, 0x020u);
  EXPECT_EQ(r.out[0].dlc, 0);
  EXPECT_EQ(r.out[1].id, 0x200u);
  EXPECT_EQ(payload(r.out[1]), (Bytes{0x01, 0x14, 20, 0x00, 0x00, 0x00}));  // time 20 ms
  // A slave takes both and adopts the master's time.
  NodeRig s(2, Protocol::techcan);
  s.now = 20 * kMs + 500 * kMs;  // its own clock says 520 ms
  for (const can::Frame& f : r.out) s.frame(f);
  EXPECT_EQ(s.node.drive().drive_time_ms(s.now), 20u);
}

TEST(TmlCanNode, RefusesSerialProtocols) {
  DriveSetup s;
  s.protocol = Protocol::rs232;
  EXPECT_THROW(TmlCanNode(s, nullptr), std::invalid_argument);
}

}  // namespace
}  // namespace omnitwin::tml
