// Tests controller/tml/tml_master: our TML master against four emulated IDM drives
// (bus_emulators/tml/tml_can_node) on the simulated CAN wire, in process, over TMLCAN and
// TechCAN: detection by a group GiveMeData2, speed mode and AXISON, CSPD reaching the drive
// core as a velocity set-point, APOS coming back, a drive losing power stopping the platform (and one
// that comes back switched off within the answer timeout),
// and a start-up that times out when nobody answers.
#include "controller/tml/tml_master.hpp"

#include <gtest/gtest.h>

#include <functional>
#include <memory>
#include <vector>

#include "bus_emulators/can/can_bus.hpp"
#include "bus_emulators/tml/tml_can.hpp"
#include "bus_emulators/tml/tml_can_node.hpp"

namespace omnitwin::controller::tml {
namespace {

namespace t = omnitwin::tml;
constexpr SimTime kMs = 1'000'000;

struct Network {
  can::CanBus bus{can::BusConfig{.bit_rate_bps = 1'000'000, .queue_capacity = 64, .max_nodes = 5}};
  TmlProgramConfig cfg;
  std::unique_ptr<TmlMaster> master;
  std::vector<std::unique_ptr<t::TmlCanNode>> drives;
  std::vector<bool> powered = {true, true, true, true};
  // Frames to drive i (0-3) this returns true for are lost on the way (a frame_loss fault).
  std::function<bool(std::size_t, const can::Frame&)> lose;
  std::vector<std::string> events;
  SimTime now = 0;

  explicit Network(bool techcan) {
    for (int i = 0; i < 5; ++i) bus.attach();
    cfg.techcan = techcan;
    cfg.host_axis = techcan ? 31 : 120;
    cfg.wheel_counts_per_rev = 10000;
    master = std::make_unique<TmlMaster>(cfg, [this](const can::Frame& f, SimTime at) {
      return bus.submit(0, f, at) == can::SubmitStatus::queued;
    });
    master->set_event_callback([this](SimTime, const std::string& s, bool) { events.push_back(s); });
    for (int i = 0; i < 4; ++i) {
      t::DriveSetup ds;
      ds.axis = static_cast<std::uint8_t>(i + 1);
      ds.host_axis = cfg.host_axis;
      ds.protocol = techcan ? t::Protocol::techcan : t::Protocol::tmlcan;
      ds.drive.counts_per_rev = 10000;
      drives.push_back(std::make_unique<t::TmlCanNode>(ds, [this, i](const can::Frame& f, SimTime at) {
        return bus.submit(i + 1, f, at) == can::SubmitStatus::queued;
      }));
      drives.back()->power_on(0);
    }
    bus.on_deliver([this](can::BusNode r, const can::Frame& f, const can::FrameTiming& tm) {
      if (r == 0) master->on_frame(f, tm.end_ns);
      else if (powered[static_cast<std::size_t>(r - 1)] && !(lose && lose(static_cast<std::size_t>(r - 1), f)))
        drives[static_cast<std::size_t>(r - 1)]->on_frame(f, tm.end_ns);
    });
  }
  // The master every 2 ms, the drives every 1 ms.
  void run(int ms) {
    for (int k = 0; k < ms; ++k) {
      bus.advance(now);
      if (k % 2 == 0) master->on_tick(now);
      bus.advance(now + kMs / 2);
      for (std::size_t i = 0; i < 4; ++i)
        if (powered[i]) drives[i]->step(now + kMs / 2, drive::Feedback{});
      now += kMs;
    }
  }
  // Start-up, then every wheel at 5000 for 10 ms: the platform running.
  void drive_on() {
    run(40);
    ASSERT_EQ(master->phase(), TmlPhase::running);
    for (int i = 0; i < 4; ++i) master->set_speed(i, 5000);
    run(10);
  }
  // Drive i (0-3) loses its power: it neither hears nor steps.
  void power_off(std::size_t i) {
    powered[i] = false;
    drives[i]->power_off();
  }
  // The TML message in a frame from the master (false: not one).
  bool message_of(const can::Frame& f, t::Message& m) const {
    if (!cfg.techcan) return t::decode_tmlcan(f, m) == t::CanStatus::ok;
    t::TechCanMessage tm;
    if (t::decode_techcan(f, tm) != t::CanStatus::ok) return false;
    m = tm.message;
    return true;
  }
};

class TmlMasterTest : public ::testing::TestWithParam<bool> {};

TEST_P(TmlMasterTest, FindsSwitchesOnAndCommandsTheFourAxes) {
  Network n(GetParam());
  n.run(40);
  ASSERT_EQ(n.master->phase(), TmlPhase::running) << (n.events.empty() ? "" : n.events.back());
  for (int i = 0; i < 4; ++i) EXPECT_TRUE(n.master->srl(i) & t::bits::srl_axis_on);
  for (int i = 0; i < 4; ++i) n.master->set_speed(i, 1000.0 * (i + 1));
  n.run(10);
  for (int i = 0; i < 4; ++i) {
    const drive::Cia402Drive& core = n.drives[static_cast<std::size_t>(i)]->drive().core();
    EXPECT_EQ(core.state(), drive::State::operation_enabled);
    EXPECT_NEAR(core.objects().target_velocity, 1000.0 * (i + 1), 1.0) << i;
    EXPECT_EQ(n.master->position(i), core.objects().position_actual) << i;
  }
  EXPECT_GT(n.master->stats().answers, 20u);
  EXPECT_EQ(n.master->stats().not_tml, 0u);
}

TEST_P(TmlMasterTest, ADriveLosingPowerStopsThePlatform) {
  Network n(GetParam());
  ASSERT_NO_FATAL_FAILURE(n.drive_on());
  n.power_off(2);
  n.bus.detach(3, n.now);
  n.run(2 * (n.cfg.lost_ticks + 2));
  EXPECT_EQ(n.master->phase(), TmlPhase::stopped);
  EXPECT_EQ(n.master->reason(), simclock::StopReason::node_missing);
  EXPECT_EQ(n.master->reason_node(), 3);
  n.run(4);
  EXPECT_EQ(n.drives[0]->drive().core().objects().target_velocity, 0);  // CSPD 0 and UPD to everyone
}

// Found in review: a power loss shorter than lost_ticks ticks (12 ms < 20 ms) brought drive 3
// back switched off (power-on state); its APOS answers kept coming, so the master never noticed
// and the other wheels drove on without wheel 3.
TEST_P(TmlMasterTest, ADriveThatCameBackSwitchedOffStopsThePlatform) {
  Network n(GetParam());
  ASSERT_NO_FATAL_FAILURE(n.drive_on());
  n.power_off(2);
  n.run(12);
  n.drives[2]->power_on(n.now);
  n.powered[2] = true;
  n.run(40);
  EXPECT_EQ(n.master->phase(), TmlPhase::stopped);
  EXPECT_EQ(n.master->reason(), simclock::StopReason::drive_fault);
  EXPECT_EQ(n.master->reason_node(), 3);
  EXPECT_EQ(n.master->stats().axes_lost, 1u);
  EXPECT_EQ(n.drives[0]->drive().core().objects().target_velocity, 0);  // CSPD 0 and UPD to everyone
}

// Found in review: the set-up went out once; with MODE SP, CACC, CSPD and UPD to axis 4 lost
// (AXISON arrived) SRL.15 was all the start-up checked, and wheel 4 stayed in position mode at
// 0 while the path ran. Its CACC read back wrong, so the set-up goes again.
TEST_P(TmlMasterTest, ASetUpThatDidNotArriveIsSentAgainBeforeThePathStarts) {
  Network n(GetParam());
  int lost = 0;
  n.lose = [&](std::size_t d, const can::Frame& f) {
    t::Message m;
    if (d != 3 || lost == 4 || !n.message_of(f, m) || m.id_code != t::axis_id_code(4) || m.opcode == t::instr::axison)
      return false;
    return ++lost, true;  // the first four messages to axis 4 alone: MODE SP, CACC, CSPD, UPD
  };
  n.run(200);
  EXPECT_EQ(lost, 4);
  ASSERT_EQ(n.master->phase(), TmlPhase::running) << (n.events.empty() ? "" : n.events.back());
  for (int i = 0; i < 4; ++i) n.master->set_speed(i, 1000.0 * (i + 1));
  n.run(10);
  EXPECT_NEAR(n.drives[3]->drive().core().objects().target_velocity, 4000.0, 1.0);
}

// A set-up that never arrives fails the start-up after a bounded number of re-sends.
TEST_P(TmlMasterTest, ASetUpNeverConfirmedFailsTheStartUp) {
  Network n(GetParam());
  n.lose = [&](std::size_t d, const can::Frame& f) {
    t::Message m;  // every CACC assignment to axis 4
    return d == 3 && n.message_of(f, m) && m.id_code == t::axis_id_code(4) && t::classify(m).address == t::reg::cacc;
  };
  n.run(1000);
  EXPECT_EQ(n.master->phase(), TmlPhase::failed);
  EXPECT_EQ(n.master->reason(), simclock::StopReason::config_failed);
  EXPECT_EQ(n.master->reason_node(), 4);
}

TEST_P(TmlMasterTest, StartupTimesOutWithoutDrives) {
  Network n(GetParam());
  for (std::size_t i = 0; i < 4; ++i) n.powered[i] = false, n.drives[i]->power_off();
  n.run(2100);
  EXPECT_EQ(n.master->phase(), TmlPhase::failed);
  EXPECT_EQ(n.master->reason(), simclock::StopReason::startup_timeout);
}

INSTANTIATE_TEST_SUITE_P(Protocols, TmlMasterTest, ::testing::Values(false, true),
                         [](const auto& info) { return info.param ? "TechCAN" : "TMLCAN"; });

TEST(TmlMaster, SpeedsAre16Dot16CountsPerSample) {
  TmlProgramConfig c;
  TmlMaster m(c, [](const can::Frame&, SimTime) { return true; });
  EXPECT_EQ(m.speed_iu(1000.0), 65536);  // 1000 counts/s = 1 count per 1 ms sample
  EXPECT_EQ(m.speed_iu(-500.0), -32768);
}

TEST(TmlConfig, ReadsAndRefuses) {
  const TmlProgramConfig c = parse_tml_config("protocol: techcan\ncycle: 0.005\naxes: [3, 4, 5, 6]\n", "x.yaml", "");
  EXPECT_TRUE(c.techcan);
  EXPECT_EQ(c.host_axis, 31);
  EXPECT_EQ(c.axes[3], 6);
  EXPECT_THROW(parse_tml_config("protocol: techcan\naxes: [1, 2, 3, 40]\n", "x.yaml", ""), TmlConfigError);
  EXPECT_THROW(parse_tml_config("protocol: rs485\n", "x.yaml", ""), TmlConfigError);
  EXPECT_THROW(parse_tml_config("axes: [1, 1, 2, 3]\n", "x.yaml", ""), TmlConfigError);
}

}  // namespace
}  // namespace omnitwin::controller::tml
