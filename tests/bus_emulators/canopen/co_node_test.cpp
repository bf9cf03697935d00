// Tests bus_emulators/canopen/co_node: one node's services working together through frames
// only — boot-up, NMT, an SDO upload of the identity, heartbeat and guarding, SYNC-driven
// PDOs, the heartbeat consumer's timeout with its EMCY and error behaviour (0x1029), reset
// communication restoring the communication objects, the TIME consumer, and a STOPPED node
// answering nothing but NMT and error control.
#include "bus_emulators/canopen/co_node.hpp"

#include <gtest/gtest.h>

#include <vector>

#include "tests/bus_emulators/canopen/co_test_od.hpp"

namespace omnitwin::canopen {
namespace {

constexpr SimTime kMs = 1'000'000;

struct NodeTest : ::testing::Test {
  ObjectDictionary od;
  std::vector<can::Frame> sent;
  std::vector<std::uint16_t> comm_errors;
  std::unique_ptr<Node> node;
  int syncs = 0;

  void SetUp() override {
    test::build_node_od(od);
    NodeHooks h;
    h.on_sync = [this](std::uint8_t, SimTime) { ++syncs; };
    h.on_comm_error = [this](std::uint16_t c, SimTime) { comm_errors.push_back(c); };
    node = std::make_unique<Node>(od, 5, [this](const can::Frame& f, SimTime) {
      sent.push_back(f);
      return true;
    }, h);
    node->power_on(0);
  }
  std::vector<can::Frame> take() { return std::exchange(sent, {}); }
  void nmt(std::uint8_t cs, SimTime t = 0) { node->on_frame(can::make_data(0, {cs, 5}), t); }
};

TEST_F(NodeTest, BootsUpAndAnswersAnExpeditedUploadOfItsIdentity) {
  ASSERT_EQ(take(), (std::vector<can::Frame>{can::make_data(0x705, {0x00})}));
  EXPECT_EQ(node->state(), NmtState::pre_operational);
  node->on_frame(can::make_data(0x605, {0x40, 0x18, 0x10, 0x01, 0, 0, 0, 0}), kMs);
  EXPECT_EQ(take(), (std::vector<can::Frame>{can::make_data(0x585, {0x43, 0x18, 0x10, 0x01, 0x4E, 0x57, 0x54, 0x4F})}));
}

TEST_F(NodeTest, OperationalNodeRunsSynchronousPdos) {
  take();
  node->on_frame(can::make_data(0x80, {}), kMs);  // pre-operational: no PDOs
  EXPECT_TRUE(take().empty());
  nmt(0x01);
  EXPECT_EQ(node->state(), NmtState::operational);
  od.entry(0x2002, 0)->set_int(0x0A0B);
  node->on_frame(can::make_data(0x205, {0x34, 0x12, 1, 0, 0, 0}), 2 * kMs);
  node->on_frame(can::make_data(0x80, {}), 3 * kMs);
  EXPECT_EQ(od.entry(0x2000, 0)->as_int(), 0x1234);  // applied at the SYNC
  EXPECT_EQ(take(), (std::vector<can::Frame>{can::make_data(0x185, {0x0B, 0x0A, 0, 0, 0, 0})}));
  EXPECT_EQ(syncs, 2);
}

TEST_F(NodeTest, HeartbeatFollowsAnSdoWriteOf1017) {
  take();
  node->on_frame(can::make_data(0x605, {0x2B, 0x17, 0x10, 0x00, 100, 0, 0, 0}), 0);  // 100 ms
  ASSERT_EQ(take().size(), 1u);  // the download response
  for (SimTime t = 0; t <= 250 * kMs; t += kMs) node->on_time(t);
  EXPECT_EQ(take(), (std::vector<can::Frame>{can::make_data(0x705, {0x7F}), can::make_data(0x705, {0x7F})}));
}

TEST_F(NodeTest, LosingTheConsumedHeartbeatRaisesEmcyAndLeavesOperational) {
  od.entry(0x1016, 1)->set_int(0x007F'0064);  // node 127, 100 ms (written directly: no hook)
  node->on_frame(can::make_data(0x605, {0x23, 0x16, 0x10, 0x01, 0x64, 0x00, 0x7F, 0x00}), 0);  // via SDO: hook
  nmt(0x01);
  take();
  node->on_frame(can::make_data(0x77F, {0x05}), 10 * kMs);
  node->on_time(110 * kMs);
  EXPECT_EQ(node->state(), NmtState::operational);
  node->on_time(111 * kMs);
  EXPECT_EQ(node->state(), NmtState::pre_operational);  // 0x1029:1 = 0
  EXPECT_EQ(take(), (std::vector<can::Frame>{can::make_data(0x85, {0x30, 0x81, 0x11, 0, 0, 0, 0, 0})}));
  EXPECT_EQ(comm_errors, (std::vector<std::uint16_t>{0x8130}));
}

TEST_F(NodeTest, ResetCommunicationRestoresTheCommunicationObjects) {
  node->on_frame(can::make_data(0x605, {0x2B, 0x17, 0x10, 0x00, 100, 0, 0, 0}), 0);
  od.entry(0x2004, 0)->set_int(77);
  ASSERT_EQ(od.entry(0x1017, 0)->as_int(), 100);
  take();
  nmt(0x82, kMs);
  EXPECT_EQ(od.entry(0x1017, 0)->as_int(), 0);
  EXPECT_EQ(od.entry(0x2004, 0)->as_int(), 77);  // application objects keep their values
  EXPECT_EQ(take(), (std::vector<can::Frame>{can::make_data(0x705, {0x00})}));
  nmt(0x81, 2 * kMs);  // reset node: everything
  EXPECT_EQ(od.entry(0x2004, 0)->as_int(), 0);
}

TEST_F(NodeTest, StoppedNodeAnswersOnlyNmtAndGuarding) {
  nmt(0x02);
  take();
  node->on_frame(can::make_data(0x605, {0x40, 0x18, 0x10, 0x01, 0, 0, 0, 0}), kMs);
  EXPECT_TRUE(take().empty());
  node->on_frame(can::make_remote(0x705, 1), kMs);
  EXPECT_EQ(take(), (std::vector<can::Frame>{can::make_data(0x705, {0x04})}));
  nmt(0x80, 2 * kMs);
  EXPECT_EQ(node->state(), NmtState::pre_operational);
}

// CiA 301: a STOPPED node sends no EMCY. The error is recorded (0x1001, 0x1003) and signalled
// when the node is back in PRE-OPERATIONAL.
TEST_F(NodeTest, StoppedNodeRecordsAnErrorWithoutEmcyAndSignalsItWhenBack) {
  nmt(0x02);
  take();
  node->raise_error(0x2310, kMs);
  EXPECT_TRUE(take().empty());
  EXPECT_EQ(od.entry(0x1001, 0)->as_int(), 0x03);  // generic + current
  EXPECT_EQ(od.entry(0x1003, 0)->as_int(), 1);
  EXPECT_EQ(od.entry(0x1003, 1)->as_int() & 0xFFFF, 0x2310);
  nmt(0x80, 2 * kMs);
  EXPECT_EQ(take(), (std::vector<can::Frame>{can::make_data(0x85, {0x10, 0x23, 0x03, 0, 0, 0, 0, 0})}));
}

// An error that came and went while STOPPED leaves the master, which saw the error before the
// stop, with the "error reset" EMCY when the node comes back.
TEST_F(NodeTest, AnErrorClearedWhileStoppedIsResetWhenBack) {
  node->raise_error(0x2310, kMs);
  nmt(0x02, 2 * kMs);
  take();
  node->clear_error(0x2310, 3 * kMs);
  EXPECT_TRUE(take().empty());
  nmt(0x01, 4 * kMs);
  EXPECT_EQ(take(), (std::vector<can::Frame>{can::make_data(0x85, {0, 0, 0, 0, 0, 0, 0, 0})}));
}

// Reset node: the application's errors are gone, but a node in INITIALISING sends nothing
// before its boot-up message — no "error reset" EMCY.
TEST_F(NodeTest, ResetNodeSendsOnlyTheBootUpMessage) {
  node->raise_error(0x2310, kMs);
  take();
  nmt(0x81, 2 * kMs);
  EXPECT_EQ(take(), (std::vector<can::Frame>{can::make_data(0x705, {0x00})}));
  EXPECT_EQ(od.entry(0x1001, 0)->as_int(), 0);
  EXPECT_EQ(node->emcy().active_count(), 0);
}

// 0x1019: 0 (no counter) or 2..240; other values are refused (0x06090030), and no value while
// the node produces SYNC with a cycle period 0x1006 ≠ 0 (0x08000022), as CiA 301 asks.
TEST_F(NodeTest, SyncCounterOverflowTakesOnly0Or2To240AndNotWhileTheCyclePeriodIsSet) {
  for (int v : {1, 241, 250, 255}) EXPECT_EQ(od.write(0x1019, 0, OdState::preop, test::le(v, 1)), SdoAbort::value_range) << v;
  for (int v : {2, 240, 0}) EXPECT_EQ(od.write(0x1019, 0, OdState::preop, test::le(v, 1)), SdoAbort::none) << v;
  ASSERT_EQ(od.write(0x1006, 0, OdState::preop, test::le(2000, 4)), SdoAbort::none);
  EXPECT_EQ(od.write(0x1019, 0, OdState::preop, test::le(3, 1)), SdoAbort::state);
  EXPECT_EQ(od.entry(0x1019, 0)->as_int(), 0);
}

TEST_F(NodeTest, ConsumesTimeStamps) {
  EXPECT_FALSE(node->last_time());
  node->on_frame(encode_time(TimeOfDay{1000, 15000}), 5 * kMs);
  ASSERT_TRUE(node->last_time());
  EXPECT_EQ(node->last_time()->days, 15000);
  EXPECT_EQ(node->last_time_at(), 5 * kMs);
}

// A wrong SYNC length is a condition: one EMCY 0x8240 when it begins, nothing for the next
// bad SYNC, the reset EMCY with the first SYNC of the right length (it was the error and its
// end for every frame; found by a protocol review).
TEST_F(NodeTest, WrongSyncLengthIsSignalledOnceUntilItEnds) {
  nmt(0x01);
  take();
  node->on_frame(can::make_data(0x80, {3}), kMs);  // no counter configured
  auto f = take();
  ASSERT_EQ(f.size(), 1u);
  EXPECT_EQ(f[0].id, 0x85u);
  EXPECT_EQ(f[0].data[0], 0x40);
  EXPECT_EQ(f[0].data[1], 0x82);
  node->on_frame(can::make_data(0x80, {4}), 2 * kMs);
  EXPECT_TRUE(take().empty()) << "the condition is still on: no second EMCY";
  EXPECT_EQ(node->stats().sync_length_errors, 2u);
  node->on_frame(can::make_data(0x80, {}), 3 * kMs);
  f = take();
  ASSERT_FALSE(f.empty());
  EXPECT_EQ(f[0].id, 0x85u);
  EXPECT_EQ(f[0].data[0], 0x00) << "error reset";
  EXPECT_EQ(f[0].data[1], 0x00);
}

// A mis-sized RPDO likewise: one EMCY 0x8210 for a run of short frames, the reset EMCY with
// the first frame of the right length.
TEST_F(NodeTest, AMisSizedRpdoIsSignalledOnceUntilOneOfTheRightLength) {
  nmt(0x01);
  take();
  for (int k = 1; k <= 100; ++k) node->on_frame(can::make_data(0x305, {0x34}), k * kMs);
  auto f = take();
  ASSERT_EQ(f.size(), 1u) << "one EMCY for 100 short frames";
  EXPECT_EQ(f[0].id, 0x85u);
  EXPECT_EQ(f[0].data[0], 0x10);
  EXPECT_EQ(f[0].data[1], 0x82);
  node->on_frame(can::make_data(0x305, {0x34, 0x12}), 101 * kMs);
  f = take();
  ASSERT_EQ(f.size(), 1u);
  EXPECT_EQ(f[0].data[0], 0x00) << "error reset";
  EXPECT_EQ(od.entry(0x2000, 0)->as_int(), 0x1234);
}

TEST_F(NodeTest, ProducesSyncWhenTheGenBitIsSet) {
  nmt(0x01);
  take();
  ASSERT_EQ(od.write(0x1019, 0, OdState::op, test::le(3, 1)), SdoAbort::none);
  ASSERT_EQ(od.write(0x1006, 0, OdState::op, test::le(2000, 4)), SdoAbort::none);  // 2 ms
  ASSERT_EQ(od.write(0x1005, 0, OdState::op, test::le(0x40000080, 4)), SdoAbort::none);
  od.entry(0x2002, 0)->set_int(0x0101);
  for (SimTime t = 0; t <= 9 * kMs; t += kMs) node->on_time(t);
  std::vector<int> counters;
  int tpdos = 0;
  for (const can::Frame& f : take()) {
    if (f.id == 0x80) counters.push_back(f.data[0]);
    if (f.id == 0x185) ++tpdos;
  }
  EXPECT_EQ(counters, (std::vector<int>{1, 2, 3, 1}));  // at 2, 4, 6, 8 ms
  EXPECT_EQ(tpdos, 4);  // its own SYNCs drive its synchronous TPDO
  EXPECT_EQ(syncs, 4);
  ASSERT_EQ(od.write(0x1005, 0, OdState::op, test::le(0x80, 4)), SdoAbort::none);  // gen off
  for (SimTime t = 10 * kMs; t <= 20 * kMs; t += kMs) node->on_time(t);
  EXPECT_TRUE(take().empty());
}

}  // namespace
}  // namespace omnitwin::canopen
