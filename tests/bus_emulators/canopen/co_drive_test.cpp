// Tests bus_emulators/canopen/co_drive: the CiA 402 drive node built from the shipped EDS —
// every entry of the EDS readable over SDO with its size (and refused with the right abort
// code where its access forbids it), the power-up through RPDO controlwords and SYNC with the
// statusword in TPDO1, the velocity set-point reaching the drive core, a drive fault raising
// EMCY with 0x603F's code and its reset clearing it, and the master's heartbeat lost while
// enabled faulting the drive.
#include "bus_emulators/canopen/co_drive.hpp"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>

#include <vector>

namespace omnitwin::canopen {
namespace {

constexpr SimTime kMs = 1'000'000;

const EdsDevice& shipped_eds() {
  static const EdsDevice eds = load_eds(std::string(OMNITWIN_SOURCE_DIR) + "/models/canopen/omnitwin_drive.eds");
  return eds;
}

struct DriveNodeTest : ::testing::Test {
  std::vector<can::Frame> sent;
  std::unique_ptr<DriveNode> d;
  SimTime now = 0;

  void SetUp() override {
    drive::DriveConfig c;
    c.counts_per_rev = 10000;
    d = std::make_unique<DriveNode>(shipped_eds(), 3, c, [this](const can::Frame& f, SimTime) {
      sent.push_back(f);
      return true;
    });
    d->power_on(0);
  }
  std::vector<can::Frame> take() { return std::exchange(sent, {}); }
  can::Frame sdo(std::initializer_list<std::uint8_t> b) {
    take();
    d->on_frame(can::make_data(0x603, b), now);
    const auto f = take();
    EXPECT_EQ(f.size(), 1u);
    return f.empty() ? can::Frame{} : f.back();
  }
  // One period: a SYNC, then the drive's step.
  void period(std::uint16_t cw, std::int32_t v) {
    const auto u = static_cast<std::uint32_t>(v);
    d->on_frame(can::make_data(0x203, {static_cast<std::uint8_t>(cw), static_cast<std::uint8_t>(cw >> 8),
                                       static_cast<std::uint8_t>(u), static_cast<std::uint8_t>(u >> 8),
                                       static_cast<std::uint8_t>(u >> 16), static_cast<std::uint8_t>(u >> 24)}),
                 now);
    now += kMs;
    d->on_frame(can::make_data(0x80, {}), now);
    d->step(now, drive::Feedback{});
  }
  std::uint16_t statusword() const { return d->drive().objects().statusword; }
};

TEST_F(DriveNodeTest, EveryEdsEntryIsReadableOverSdoWithItsSizeAndAccess) {
  int checked = 0;
  for (const EdsObject& o : shipped_eds().objects) {
    for (const EdsEntry& e : o.entries) {
      const can::Frame r = sdo({0x40, static_cast<std::uint8_t>(o.index), static_cast<std::uint8_t>(o.index >> 8), e.subindex, 0, 0, 0, 0});
      const std::string what = fmt::format("0x{:04X}:{} {}", o.index, e.subindex, e.name);
      if (e.access == EdsAccess::wo) {
        EXPECT_EQ(r.data[0], 0x80) << what;
        EXPECT_EQ(get_u32(r.data.data() + 4), 0x06010001u) << what;
        continue;
      }
      ASSERT_EQ(r.data[0] & 0xE0, 0x40) << what << ": " << can::to_string(r);
      const std::size_t bytes = (e.bits + 7) / 8;
      if (r.data[0] & 0x02) {  // expedited, size indicated
        ASSERT_TRUE(r.data[0] & 0x01) << what;
        EXPECT_EQ(4u - ((r.data[0] >> 2) & 3u), bytes) << what;
      } else {                 // segmented: the size in the initiate
        EXPECT_EQ(get_u32(r.data.data() + 4), bytes) << what;
        d->on_frame(can::make_data(0x603, {0x80, r.data[1], r.data[2], r.data[3], 0, 0, 0, 0}), now);  // abort it
      }
      ++checked;
    }
  }
  EXPECT_GT(checked, 150);
}

TEST_F(DriveNodeTest, ReadOnlyEntriesRefuseWrites) {
  for (const EdsObject& o : shipped_eds().objects)
    for (const EdsEntry& e : o.entries) {
      if (e.access != EdsAccess::ro && e.access != EdsAccess::const_) continue;
      if (e.bits > 32 || e.bits == 0) continue;
      const can::Frame r = sdo({0x23, static_cast<std::uint8_t>(o.index), static_cast<std::uint8_t>(o.index >> 8), e.subindex, 0, 0, 0, 0});
      EXPECT_EQ(r.data[0], 0x80) << fmt::format("0x{:04X}:{}", o.index, e.subindex);
      // A 4-byte write to a shorter entry may be refused for its length first; both are right.
      const std::uint32_t code = get_u32(r.data.data() + 4);
      EXPECT_TRUE(code == 0x06010002u || (e.bits < 32 && (code == 0x06070010u || code == 0x06070012u)))
          << fmt::format("0x{:04X}:{} abort 0x{:08X}", o.index, e.subindex, code);
    }
}

TEST_F(DriveNodeTest, PowersUpThroughPdosAndFollowsTheVelocity) {
  ASSERT_EQ(sdo({0x2F, 0x60, 0x60, 0x00, 9, 0, 0, 0}).data[0], 0x60);  // CSV
  d->on_frame(can::make_data(0, {0x01, 3}), now);
  ASSERT_EQ(d->node().state(), NmtState::operational);
  for (std::uint16_t cw : {0x06, 0x07, 0x0F}) {
    period(cw, 0);
    period(cw, 0);
  }
  EXPECT_EQ(d->drive().state(), drive::State::operation_enabled);
  EXPECT_EQ(statusword() & 0x6F, 0x27);
  // TPDO1 after the last SYNC carries the statusword.
  take();
  period(0x0F, 5000);
  period(0x0F, 5000);
  const auto f = take();
  ASSERT_FALSE(f.empty());
  EXPECT_EQ(f[0].id, 0x183u);
  EXPECT_EQ(get_u16(f[0].data.data()) & 0x6F, 0x27);
  EXPECT_EQ(d->drive().objects().target_velocity, 5000);
  const drive::Command c = d->step(now + kMs / 2, drive::Feedback{});
  EXPECT_TRUE(c.power);
  EXPECT_NEAR(c.velocity_rad_s, 5000.0 / 10000 * 2 * 3.141592653589793, 1e-6);
}

TEST_F(DriveNodeTest, DriveFaultRaisesEmcyAndTheResetClearsIt) {
  d->on_frame(can::make_data(0, {0x01, 3}), now);
  for (std::uint16_t cw : {0x06, 0x07, 0x0F}) period(cw, 0), period(cw, 0);
  take();
  d->drive().raise_fault(0x8611);
  period(0x0F, 0);
  period(0x0F, 0);
  auto f = take();
  const auto emcy = std::find_if(f.begin(), f.end(), [](const can::Frame& x) { return x.id == 0x83; });
  ASSERT_NE(emcy, f.end());
  EXPECT_EQ(get_u16(emcy->data.data()), 0x8611);
  EXPECT_EQ(emcy->data[2] & 0x21, 0x21);  // generic + device profile
  period(0x00, 0);
  period(0x80, 0);  // fault reset edge
  period(0x80, 0);
  f = take();
  const auto reset = std::find_if(f.begin(), f.end(), [](const can::Frame& x) { return x.id == 0x83; });
  ASSERT_NE(reset, f.end());
  EXPECT_EQ(get_u16(reset->data.data()), 0x0000);
  EXPECT_EQ(d->drive().state(), drive::State::switch_on_disabled);
}

// A real following error: in CSP the target position runs away from a shaft that does not
// move; the core's supervision (0x6065 window, 0x6066 time) faults the drive, and the node
// signals EMCY 0x8611 with the device-profile bit in the error register.
TEST_F(DriveNodeTest, AFollowingErrorRaisesEmcy8611) {
  ASSERT_EQ(sdo({0x2F, 0x60, 0x60, 0x00, 8, 0, 0, 0}).data[0], 0x60);  // CSP
  d->on_frame(can::make_data(0, {0x01, 3}), now);
  for (std::uint16_t cw : {0x06, 0x07, 0x0F}) period(cw, 0), period(cw, 0);
  ASSERT_EQ(d->drive().state(), drive::State::operation_enabled);
  bool emcy = false;
  for (int k = 1; k <= 60 && !emcy; ++k) {
    const auto target = static_cast<std::uint32_t>(k * 2000);  // 2000 counts per ms; the shaft stays at 0
    sdo({0x23, 0x7A, 0x60, 0x00, static_cast<std::uint8_t>(target), static_cast<std::uint8_t>(target >> 8),
         static_cast<std::uint8_t>(target >> 16), static_cast<std::uint8_t>(target >> 24)});
    period(0x0F, 0);
    for (const can::Frame& f : take())
      if (f.id == 0x83 && get_u16(f.data.data()) == 0x8611) emcy = (f.data[2] & 0x21) == 0x21;
  }
  EXPECT_TRUE(emcy);
  EXPECT_EQ(d->drive().objects().error_code, 0x8611);
  EXPECT_EQ(d->stats().faults, 1u);
}

TEST_F(DriveNodeTest, LosingTheMastersHeartbeatWhileEnabledFaultsTheDrive) {
  sdo({0x23, 0x16, 0x10, 0x01, 0x96, 0x00, 0x7F, 0x00});  // consume node 127, 150 ms
  d->on_frame(can::make_data(0, {0x01, 3}), now);
  d->on_frame(can::make_data(0x77F, {0x05}), now);
  for (std::uint16_t cw : {0x06, 0x07, 0x0F}) period(cw, 0), period(cw, 0);
  ASSERT_EQ(d->drive().state(), drive::State::operation_enabled);
  for (int i = 0; i < 200; ++i) period(0x0F, 0);
  EXPECT_TRUE(d->drive().state() == drive::State::fault || d->drive().state() == drive::State::fault_reaction_active);
  EXPECT_EQ(d->node().state(), NmtState::pre_operational);
  EXPECT_EQ(d->stats().comm_faults, 1u);
}

// NMT stop while enabled faults the drive (0x6007 = 1), but a STOPPED node sends no EMCY: the
// fault's EMCY 0x8100 follows when the master takes the node back to PRE-OPERATIONAL.
TEST_F(DriveNodeTest, StoppingTheNodeWhileEnabledSignalsTheFaultOnlyWhenItIsBack) {
  d->on_frame(can::make_data(0, {0x01, 3}), now);
  for (std::uint16_t cw : {0x06, 0x07, 0x0F}) period(cw, 0), period(cw, 0);
  ASSERT_EQ(d->drive().state(), drive::State::operation_enabled);
  take();
  d->on_frame(can::make_data(0, {0x02, 3}), now);
  for (int i = 0; i < 20; ++i) now += kMs, d->step(now, drive::Feedback{});
  EXPECT_EQ(d->drive().state(), drive::State::fault);
  for (const can::Frame& f : take()) EXPECT_NE(f.id, 0x83u) << can::to_string(f);
  d->on_frame(can::make_data(0, {0x80, 3}), now);
  const auto f = take();
  ASSERT_EQ(f.size(), 1u);
  EXPECT_EQ(f[0].id, 0x83u);
  EXPECT_EQ(get_u16(f[0].data.data()), 0x8100);
}

}  // namespace
}  // namespace omnitwin::canopen
