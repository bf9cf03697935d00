// Tests bus_emulators/canopen/co_pdo: RPDO application (at once and at SYNC), TPDO
// transmission types (every n-th SYNC with a start value, acyclic synchronous, RTR,
// event-driven with inhibit time and event timer), dynamic mapping over the dictionary with
// CiA 301's procedure and its abort codes, length errors and RPDO deadline monitoring.
#include "bus_emulators/canopen/co_pdo.hpp"

#include <gtest/gtest.h>

#include <vector>

#include "tests/bus_emulators/canopen/co_test_od.hpp"

namespace omnitwin::canopen {
namespace {

constexpr SimTime kMs = 1'000'000;
using test::le;

struct Fixture : ::testing::Test {
  ObjectDictionary od;
  std::vector<can::Frame> sent;
  std::vector<std::uint16_t> errors;
  SendFn send = [this](const can::Frame& f, SimTime) {
    sent.push_back(f);
    return true;
  };
  std::unique_ptr<PdoEngine> pdo;

  void SetUp() override {
    test::build_node_od(od);
    pdo = std::make_unique<PdoEngine>(od, 5);
    pdo->attach();
    pdo->set_error_handler([](void* ctx, std::uint16_t code, SimTime) { static_cast<Fixture*>(ctx)->errors.push_back(code); },
                           this);
  }
  std::int64_t value(std::uint16_t idx) { return od.entry(idx, 0)->as_int(); }
  SdoAbort write(std::uint16_t idx, std::uint8_t sub, std::uint64_t v, int bytes) {
    const auto d = le(v, bytes);
    return od.write(idx, sub, OdState::preop, d);
  }
};

using PdoEngineTest = Fixture;

TEST_F(PdoEngineTest, ResolvesTheDefaultMapping) {
  EXPECT_EQ(pdo->rpdo_cob_id(0), 0x205u);
  EXPECT_EQ(pdo->rpdo_bytes(0), 6);
  EXPECT_EQ(pdo->tpdo_cob_id(0), 0x185u);
  EXPECT_EQ(pdo->tpdo_cob_id(1), 0u);  // bit 31 set: does not exist
}

TEST_F(PdoEngineTest, AsynchronousRpdoAppliesAtOnceOnlyInOperational) {
  const can::Frame f = can::make_data(0x305, {0x34, 0x12});
  EXPECT_EQ(pdo->on_frame(f, 0, NmtState::pre_operational, send), RpdoStatus::not_rpdo);
  EXPECT_EQ(value(0x2000), 0);
  EXPECT_EQ(pdo->on_frame(f, 0, NmtState::operational, send), RpdoStatus::applied);
  EXPECT_EQ(value(0x2000), 0x1234);
}

TEST_F(PdoEngineTest, SynchronousRpdoWaitsForTheSync) {
  const can::Frame f = can::make_data(0x205, {0x01, 0x00, 0xFE, 0xFF, 0xFF, 0xFF});
  EXPECT_EQ(pdo->on_frame(f, 0, NmtState::operational, send), RpdoStatus::applied);
  EXPECT_EQ(value(0x2001), 0);
  pdo->on_sync(0, kMs, NmtState::operational, send);
  EXPECT_EQ(value(0x2000), 1);
  EXPECT_EQ(value(0x2001), -2);
}

TEST_F(PdoEngineTest, ShortRpdoIsDroppedWithEmcy8210AndLongOneKeptWith8220) {
  EXPECT_EQ(pdo->on_frame(can::make_data(0x305, {0x34}), 0, NmtState::operational, send), RpdoStatus::too_short);
  EXPECT_EQ(value(0x2000), 0);
  EXPECT_EQ(pdo->on_frame(can::make_data(0x305, {0x34, 0x12, 0x99}), 0, NmtState::operational, send),
            RpdoStatus::too_long);
  EXPECT_EQ(value(0x2000), 0x1234);
  EXPECT_EQ(errors, (std::vector<std::uint16_t>{0x8210, 0x8220}));
  EXPECT_EQ(pdo->stats().length_errors, 2u);
}

TEST_F(PdoEngineTest, SynchronousTpdoEveryNthSyncFromTheStartValue) {
  ASSERT_EQ(write(0x1800, 1, 0x80000185, 4), SdoAbort::none);  // destroy to change the type
  ASSERT_EQ(write(0x1800, 2, 3, 1), SdoAbort::none);
  ASSERT_EQ(write(0x1800, 6, 2, 1), SdoAbort::none);
  ASSERT_EQ(write(0x1800, 1, 0x185, 4), SdoAbort::none);
  od.entry(0x2002, 0)->set_int(0xBEEF);
  std::vector<int> at;
  for (std::uint8_t c = 1; c <= 10; ++c) {
    const std::size_t before = sent.size();
    pdo->on_sync(c, c * kMs, NmtState::operational, send);
    if (sent.size() > before) at.push_back(c);
  }
  EXPECT_EQ(at, (std::vector<int>{4, 7, 10}));  // started at counter 2, then every 3rd
  EXPECT_EQ(sent[0], can::make_data(0x185, {0xEF, 0xBE, 0, 0, 0, 0}));
}

TEST_F(PdoEngineTest, AcyclicSynchronousTpdoSendsOnlyWhenTheDataChanged) {
  write(0x1800, 1, 0x80000185, 4);
  write(0x1800, 2, 0, 1);
  write(0x1800, 1, 0x185, 4);
  pdo->on_sync(0, kMs, NmtState::operational, send);
  pdo->on_sync(0, 2 * kMs, NmtState::operational, send);
  EXPECT_EQ(sent.size(), 1u);  // the first, then nothing changed
  od.entry(0x2003, 0)->set_int(7);
  pdo->on_sync(0, 3 * kMs, NmtState::operational, send);
  EXPECT_EQ(sent.size(), 2u);
}

TEST_F(PdoEngineTest, EventDrivenTpdoHonoursInhibitTimeAndEventTimer) {
  write(0x1800, 1, 0x80000185, 4);
  write(0x1800, 2, 254, 1);
  write(0x1800, 3, 100, 2);  // 10 ms inhibit
  write(0x1800, 5, 50, 2);   // 50 ms event timer
  write(0x1800, 1, 0x185, 4);
  pdo->on_operational(0);
  pdo->on_time(0, NmtState::operational, send);
  ASSERT_EQ(sent.size(), 1u);  // first transmission after entering OPERATIONAL
  od.entry(0x2002, 0)->set_int(1);
  pdo->on_time(5 * kMs, NmtState::operational, send);
  EXPECT_EQ(sent.size(), 1u);  // inhibited
  pdo->on_time(10 * kMs, NmtState::operational, send);
  EXPECT_EQ(sent.size(), 2u);
  pdo->on_time(59 * kMs, NmtState::operational, send);
  EXPECT_EQ(sent.size(), 2u);
  pdo->on_time(60 * kMs, NmtState::operational, send);
  EXPECT_EQ(sent.size(), 3u);  // event timer, no change
}

TEST_F(PdoEngineTest, RemoteRequestedTpdo) {
  write(0x1800, 1, 0x80000185, 4);
  write(0x1800, 2, 253, 1);
  write(0x1800, 1, 0x185, 4);
  od.entry(0x2002, 0)->set_int(0x0102);
  pdo->on_frame(can::make_remote(0x185, 6), 0, NmtState::operational, send);
  ASSERT_EQ(sent.size(), 1u);
  EXPECT_EQ(sent[0], can::make_data(0x185, {0x02, 0x01, 0, 0, 0, 0}));
}

TEST_F(PdoEngineTest, DynamicMappingFollowsTheCia301Procedure) {
  // Mapping while the PDO exists: refused.
  EXPECT_EQ(write(0x1A00, 0, 0, 1), SdoAbort::state);
  ASSERT_EQ(write(0x1800, 1, 0x80000185, 4), SdoAbort::none);
  // Entries only while sub 0 is 0.
  EXPECT_EQ(write(0x1A00, 1, 0x20030020, 4), SdoAbort::subindex0_not_zero);
  ASSERT_EQ(write(0x1A00, 0, 0, 1), SdoAbort::none);
  EXPECT_EQ(write(0x1A00, 1, 0x20000010, 4), SdoAbort::not_mappable);    // RPDO-only object
  EXPECT_EQ(write(0x1A00, 1, 0x20040020, 4), SdoAbort::not_mappable);    // not mappable at all
  EXPECT_EQ(write(0x1A00, 1, 0x30000010, 4), SdoAbort::no_object);
  EXPECT_EQ(write(0x1A00, 1, 0x20020020, 4), SdoAbort::param_incompatible);  // wrong length
  ASSERT_EQ(write(0x1A00, 1, 0x20030020, 4), SdoAbort::none);
  ASSERT_EQ(write(0x1A00, 2, 0x20030020, 4), SdoAbort::none);
  ASSERT_EQ(write(0x1A00, 3, 0x20020010, 4), SdoAbort::none);
  EXPECT_EQ(write(0x1A00, 0, 3, 1), SdoAbort::pdo_length_exceeded);  // 80 bits
  ASSERT_EQ(write(0x1A00, 0, 2, 1), SdoAbort::none);
  // The identifier may not change while the PDO exists.
  ASSERT_EQ(write(0x1800, 1, 0x185, 4), SdoAbort::none);
  EXPECT_EQ(write(0x1800, 1, 0x186, 4), SdoAbort::value_range);
  EXPECT_EQ(write(0x1800, 3, 10, 2), SdoAbort::state);  // inhibit time neither
  EXPECT_EQ(write(0x1800, 2, 245, 1), SdoAbort::value_range);  // reserved type
  EXPECT_EQ(pdo->tpdo_bytes(0), 8);
  od.entry(0x2003, 0)->set_int(-1);
  pdo->on_sync(0, 0, NmtState::operational, send);
  ASSERT_EQ(sent.size(), 1u);
  EXPECT_EQ(sent[0].dlc, 8);
}

TEST_F(PdoEngineTest, DummyEntriesInRpdosSkipBytes) {
  write(0x1401, 1, 0x80000305, 4);
  write(0x1601, 0, 0, 1);
  ASSERT_EQ(write(0x1601, 1, 0x00060010, 4), SdoAbort::none);  // UNSIGNED16 dummy
  ASSERT_EQ(write(0x1601, 2, 0x20000010, 4), SdoAbort::none);
  ASSERT_EQ(write(0x1601, 0, 2, 1), SdoAbort::none);
  ASSERT_EQ(write(0x1401, 1, 0x305, 4), SdoAbort::none);
  pdo->on_frame(can::make_data(0x305, {0xAA, 0xBB, 0x22, 0x11}), 0, NmtState::operational, send);
  EXPECT_EQ(value(0x2000), 0x1122);
  write(0x1A00, 0, 0, 1);  // a TPDO cannot map dummies (PDO exists: state)
  write(0x1800, 1, 0x80000185, 4);
  write(0x1A00, 0, 0, 1);
  EXPECT_EQ(write(0x1A00, 1, 0x00060010, 4), SdoAbort::not_mappable);
}

TEST_F(PdoEngineTest, RpdoDeadlineMonitoringRaisesEmcy8250) {
  write(0x1401, 1, 0x80000305, 4);
  write(0x1401, 5, 20, 2);  // 20 ms
  write(0x1401, 1, 0x305, 4);
  pdo->on_operational(0);
  pdo->on_time(100 * kMs, NmtState::operational, send);
  EXPECT_TRUE(errors.empty());  // monitoring starts with the first RPDO
  pdo->on_frame(can::make_data(0x305, {1, 0}), 100 * kMs, NmtState::operational, send);
  pdo->on_time(120 * kMs, NmtState::operational, send);
  EXPECT_TRUE(errors.empty());
  pdo->on_time(121 * kMs, NmtState::operational, send);
  pdo->on_time(130 * kMs, NmtState::operational, send);
  EXPECT_EQ(errors, (std::vector<std::uint16_t>{0x8250}));
  EXPECT_EQ(pdo->stats().rpdo_timeouts, 1u);
}

}  // namespace
}  // namespace omnitwin::canopen
