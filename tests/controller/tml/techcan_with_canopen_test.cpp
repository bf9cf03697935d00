// Tests TechCAN and CANopen sharing one CAN bus (seed 003 chapter 5: TechCAN's COB-IDs lie
// outside CANopen's): four TechCAN IDM drives (axes 1..4) driven by our TML master and two
// CANopen CiA 402 drive nodes (node IDs 5 and 6, built from the shipped EDS) talked to by an SDO
// client, NMT and SYNC, all on the simulated wire in process. Each side works as if alone:
// the TML master runs the four axes, the CANopen nodes answer SDO, go OPERATIONAL and send
// their TPDOs on SYNC; each ignores the other's frames without counting them as errors.
#include <gtest/gtest.h>

#include <memory>
#include <vector>

#include "bus_emulators/can/can_bus.hpp"
#include "bus_emulators/canopen/co_drive.hpp"
#include "bus_emulators/canopen/co_eds.hpp"
#include "bus_emulators/tml/tml_can_node.hpp"
#include "controller/canopen/co_sdo_client.hpp"
#include "controller/tml/tml_master.hpp"

namespace omnitwin::controller::tml {
namespace {

namespace t = omnitwin::tml;
namespace co = omnitwin::canopen;
constexpr SimTime kMs = 1'000'000;

TEST(TechcanWithCanopen, BothProtocolsRunOnOneBus) {
  const co::EdsDevice eds = co::load_eds(std::string(OMNITWIN_SOURCE_DIR) + "/models/canopen/omnitwin_drive.eds");
  can::CanBus bus(can::BusConfig{.bit_rate_bps = 1'000'000, .queue_capacity = 64, .max_nodes = 7});
  for (int i = 0; i < 7; ++i) bus.attach();
  // Node 0: the host, with our TML master and an SDO client.
  TmlProgramConfig cfg;
  cfg.techcan = true;
  cfg.host_axis = 31;
  TmlMaster master(cfg, [&](const can::Frame& f, SimTime at) { return bus.submit(0, f, at) == can::SubmitStatus::queued; });
  canopen::SdoClient sdo([&](const can::Frame& f, SimTime at) { return bus.submit(0, f, at) == can::SubmitStatus::queued; });
  std::vector<std::unique_ptr<t::TmlCanNode>> tml;
  for (int i = 0; i < 4; ++i) {
    t::DriveSetup ds;
    ds.axis = static_cast<std::uint8_t>(i + 1);
    ds.host_axis = 31;
    ds.protocol = t::Protocol::techcan;
    tml.push_back(std::make_unique<t::TmlCanNode>(ds, [&bus, i](const can::Frame& f, SimTime at) {
      return bus.submit(i + 1, f, at) == can::SubmitStatus::queued;
    }));
    tml.back()->power_on(0);
  }
  std::vector<std::unique_ptr<co::DriveNode>> cop;
  for (int i = 0; i < 2; ++i)
    cop.push_back(std::make_unique<co::DriveNode>(eds, static_cast<std::uint8_t>(5 + i), drive::DriveConfig{},
                                                  [&bus, i](const can::Frame& f, SimTime at) {
                                                    return bus.submit(5 + i, f, at) == can::SubmitStatus::queued;
                                                  }));
  for (auto& d : cop) d->power_on(0);
  bus.on_deliver([&](can::BusNode r, const can::Frame& f, const can::FrameTiming& tm) {
    if (r == 0) {
      master.on_frame(f, tm.end_ns);
      sdo.on_frame(f, tm.end_ns);
    } else if (r <= 4) {
      tml[static_cast<std::size_t>(r - 1)]->on_frame(f, tm.end_ns);
    } else {
      cop[static_cast<std::size_t>(r - 5)]->on_frame(f, tm.end_ns);
    }
  });
  auto run = [&](SimTime& now, int ms, bool sync) {
    for (int k = 0; k < ms; ++k) {
      bus.advance(now);
      if (k % 2 == 0) master.on_tick(now);
      if (sync) bus.submit(0, co::frame11(co::cob::sync, 0), now);
      sdo.on_time(now);
      bus.advance(now + kMs / 2);
      for (auto& d : tml) d->step(now + kMs / 2, drive::Feedback{});
      for (auto& d : cop) d->step(now + kMs / 2, drive::Feedback{});
      now += kMs;
    }
  };
  SimTime now = 0;
  // CANopen: the identity of node 5 by SDO while the TML master starts its axes.
  sdo.upload(5, 0x1018, 1, now);
  run(now, 20, false);
  const canopen::SdoResult* r = sdo.result(5);
  ASSERT_NE(r, nullptr);
  ASSERT_EQ(r->status, canopen::SdoStatus::done);
  EXPECT_EQ(co::get_u32(r->data.data()), 0x4F54574Eu);
  // NMT start of the two CANopen nodes, then SYNCs: their TPDO1s flow.
  bus.submit(0, can::make_data(0, {0x01, 0x00}), now);
  for (int i = 0; i < 4; ++i) master.set_speed(i, 1000);
  run(now, 40, true);
  EXPECT_EQ(master.phase(), TmlPhase::running);
  EXPECT_EQ(master.stats().axes_lost, 0u);
  EXPECT_GT(master.stats().not_tml, 0u);  // it saw the CANopen traffic, and left it alone
  for (auto& d : tml) {
    EXPECT_EQ(d->drive().core().state(), drive::State::operation_enabled);
    EXPECT_NEAR(d->drive().core().objects().target_velocity, 1000, 1);
    EXPECT_GT(d->stats().foreign, 0u);
    EXPECT_EQ(d->stats().malformed, 0u);
  }
  for (auto& d : cop) {
    EXPECT_EQ(d->node().state(), co::NmtState::operational);
    EXPECT_GT(d->node().pdo().stats().tpdo_tx, 30u);
    EXPECT_EQ(d->node().emcy().sent(), 0u);
    EXPECT_EQ(d->node().sdo().stats().aborts_sent, 0u);
    EXPECT_EQ(d->node().pdo().stats().length_errors, 0u);
  }
  EXPECT_EQ(bus.stats().error_frames, 0u);
}

}  // namespace
}  // namespace omnitwin::controller::tml
