// Tests twin/m3_network.cpp: the twin's MECHATROLINK-III line, in one process, against our C1
// master core and four servo axes (controller/mechatrolink3) over an in-process transport,
// stepped by the twin's own scheduler as a lockstep run steps it: each master tick the core
// runs through its transmission cycle, and every frame it sends is met inside the tick
// (on_sent) and its answer handed back at the arrival the Horizon names. The wheels are a
// shaft per servo that follows the amplifier setpoint. Checked: the driver sequence measures
// the line and the four servos start and turn their wheels; frames in and out are counted
// and captured; a power loss in the cascade drops the station and every one behind it, and
// the station reconnects; a cable break cuts off the stations behind it (communication
// alarms there, none before it); corruption is an FCS error at the slave; a late station's
// responses are late at the master; stations beyond the wheels are on the line with shafts
// of their own; the metrics name every slave's phase and alarms.
#include <gtest/gtest.h>

#include <array>
#include <filesystem>
#include <memory>
#include <vector>

#include "bus_emulators/mechatrolink3/transport/m3_transport.hpp"
#include "controller/mechatrolink3/m3_master.hpp"
#include "controller/mechatrolink3/m3_servo_axis.hpp"
#include "tests/support/mujoco_fixture.hpp"
#include "tests/support/temp_dir.hpp"
#include "twin/clock.hpp"
#include "twin/m3_network.hpp"
#include "twin/scenario.hpp"

namespace omnitwin::twin {
namespace {

using omnitwin::testing::source_path;
constexpr SimTime kCycle = 1'000'000;  // 1 ms transmission cycle

class M3NetworkTest : public ::testing::Test {
 protected:
  void build(const std::string& name, std::vector<Override> extra = {}, int stations = 4) {
    std::vector<Override> o{{"bus.transport", "mem:" + name}, {"bus.stations", std::to_string(stations)}};
    o.insert(o.end(), extra.begin(), extra.end());
    scenario_ = load_scenario(source_path("tests/data/scenarios/m3_short.yaml"), o);
    BusNetwork::Hooks h;
    h.wheel_angle = [this](int i) { return angle_[static_cast<std::size_t>(i)]; };
    h.wheel_speed = [this](int i) { return speed_[static_cast<std::size_t>(i)]; };
    h.set_setpoint = [this](int i, double w) { speed_[static_cast<std::size_t>(i)] = w; };
    h.axis_sample = [](int, double) {};
    h.log = [this](SimTime, std::string_view, const std::string& text) { log_.push_back(text); };
    net_ = std::make_unique<M3Network>(scenario_, sched_, std::move(h));
    net_->open_pcap((dir_ / "bus-m3.pcap").string());
    link_ = m3::open_transport("mem:" + name, m3::Role::master);
    m3::MasterConfig mc;
    for (int k = 0; k < stations; ++k) mc.slaves.push_back(m3::MasterSlave{.address = static_cast<std::uint8_t>(0x03 + k)});
    for (int k = 0; k < stations; ++k) axes_.emplace_back("axis", m3::ServoAxisConfig{});
    master_ = std::make_unique<m3::C1Master>(
        mc, [this](std::span<const std::uint8_t> f, SimTime t) { emit(f, t); },
        [this](std::uint64_t, SimTime t) {
          for (int k = 0; k < static_cast<int>(axes_.size()); ++k)
            axes_[static_cast<std::size_t>(k)].on_interrupt(master_->response(k), master_->fresh(k), master_->command(k), t);
        });
    sched_.add_periodic("master", Phase::master, 0, kCycle, [this](SimTime t) { tick(t); });
    sched_.add_periodic("physics", Phase::physics, 0, kCycle, [this](SimTime t) {
      net_->advance(t);
      for (std::size_t i = 0; i < 4; ++i) angle_[i] += speed_[i] * 1e-3;
    });
  }

  // The master's frame: onto the transport, reported, the twin's answer taken into the inbox.
  void emit(std::span<const std::uint8_t> f, SimTime t) {
    ASSERT_TRUE(link_->send(f));
    simclock::Sent s;
    s.t_ns = t;
    s.frames[0] = ++sent_;
    const simclock::Horizon h = net_->on_sent(s, std::chrono::milliseconds(1000));
    ASSERT_GE(h.arrival_ns, -1);
    std::array<std::uint8_t, 2 * m3::kMaxFrame> buf{};
    while (received_ < h.frames[0]) {
      const int n = link_->receive(buf, std::chrono::milliseconds(1000));
      ASSERT_GT(n, 0);
      ++received_;
      inbox_.push_back({h.arrival_ns, std::vector<std::uint8_t>(buf.begin(), buf.begin() + n)});
    }
  }
  // One tick: the master's events up to the next tick, the inbox handed over in between.
  void tick(SimTime t) {
    if (!started_) master_->start(t), started_ = true;
    master_->advance(t);
    for (;;) {
      while (!inbox_.empty()) {
        const auto [at, bytes] = inbox_.front();
        inbox_.erase(inbox_.begin());
        master_->advance(at);
        master_->on_frame(bytes, at);
      }
      const SimTime next = master_->next_wakeup();
      if (next < 0 || next >= t + kCycle) return;
      master_->advance(next);
    }
  }

  void run_until(double seconds) { sched_.run_until(static_cast<SimTime>(seconds * 1e9) + 1, pacer_); }
  void set_velocity(std::int32_t v) {
    for (auto& a : axes_) a.set_velocity(v);
  }
  bool running(int k) const { return axes_[static_cast<std::size_t>(k)].step() == m3::AxisStep::running; }

  omnitwin::testing::TempDir dir_{"omnitwin-m3net"};
  Scenario scenario_;
  Scheduler sched_;
  LockstepPacer pacer_;
  std::array<double, 4> angle_{}, speed_{};
  std::vector<std::string> log_;
  std::unique_ptr<M3Network> net_;
  std::unique_ptr<m3::M3Transport> link_;
  std::vector<m3::ServoAxis> axes_;
  std::unique_ptr<m3::C1Master> master_;
  std::vector<std::pair<SimTime, std::vector<std::uint8_t>>> inbox_;
  std::uint64_t sent_ = 0, received_ = 0;
  bool started_ = false;
};

TEST_F(M3NetworkTest, TheFourServosStartAndTurnTheirWheels) {
  build("m3net-start");
  set_velocity(131072);  // one wheel revolution per second
  run_until(0.5);
  EXPECT_EQ(master_->state(), m3::DriverState::cyclic) << master_->why();
  const m3::Topology line = m3::Topology::cascade_of(4, 1.0);
  for (int k = 0; k < 4; ++k) {
    EXPECT_TRUE(running(k)) << k;
    EXPECT_EQ(master_->tr_dly_ns(k), m3::tr_dly_ns(line, k)) << "measured in simulated time";
    EXPECT_EQ(master_->counters(k).missed, 0u);
    EXPECT_EQ(net_->drive_state(k), DriveStateCode::running);
    EXPECT_EQ(net_->wheel_record(k).node, 0x03 + k);
    EXPECT_NEAR(speed_[static_cast<std::size_t>(k)], 2 * M_PI, 0.1) << "the wheel turns at 1 rev/s";
  }
  const BusSample b = net_->bus_sample();
  EXPECT_EQ(b.frames_rx, sent_);
  EXPECT_EQ(b.frames_tx, received_);
  EXPECT_EQ(b.dropouts, 0u);
  EXPECT_GT(net_->wire_busy_ns(), 0);
  EXPECT_GE(net_->master_start_ns(), 0) << "the instant all four servos were on";
  ASSERT_EQ(net_->close_pcap(), "");
  net_->flush_pcap();  // the held records
  EXPECT_EQ(net_->segment().pcap()->written(m3::Direction::out), sent_);
  EXPECT_EQ(net_->segment().pcap()->written(m3::Direction::back), received_);
}

// Station 2 of the cascade loses power: nothing passes a dead station, so 3 and 4 drop off
// too; station 1 carries on. Power back: all are reachable and the axes reconnect.
TEST_F(M3NetworkTest, APowerLossInACascadeDropsTheStationAndEveryOneBehindIt) {
  build("m3net-power");
  run_until(0.1);
  ASSERT_TRUE(running(1));
  FaultSpec f;
  f.kind = FaultSpec::Kind::power_loss;
  f.wheel = 1;
  net_->apply_fault(f, true, sched_.now());
  const auto missed0 = master_->counters(0).missed, missed3 = master_->counters(3).missed;
  run_until(0.2);
  EXPECT_EQ(net_->drive_state(1), DriveStateCode::off);
  EXPECT_EQ(master_->counters(0).missed, missed0) << "before the dead station: unaffected";
  EXPECT_GT(master_->counters(3).missed, missed3 + 50) << "behind it: off the line";
  net_->apply_fault(f, false, sched_.now());
  run_until(0.4);
  for (int k = 0; k < 4; ++k) EXPECT_TRUE(running(k)) << k;
  EXPECT_GE(axes_[1].recoveries(), 1) << "reconnected after its power-on";
}

TEST_F(M3NetworkTest, ACableBreakCutsOffTheStationsBehindIt) {
  build("m3net-cable");
  run_until(0.1);
  FaultSpec f;
  f.kind = FaultSpec::Kind::link_break;
  f.wheel = 2;  // after slave 2
  net_->apply_fault(f, true, sched_.now());
  run_until(0.15);
  const nlohmann::json s = net_->slave_metrics();
  EXPECT_EQ(s[0]["comm_alarms"], 0);
  EXPECT_EQ(s[1]["comm_alarms"], 0);
  EXPECT_GE(s[2]["comm_alarms"].get<int>(), 1) << s[2].dump();
  EXPECT_GE(s[3]["comm_alarms"].get<int>(), 1);
  EXPECT_EQ(s[3]["phase"], 2) << "a communication alarm drops phase 3 to 2 and stops the servo";
  net_->apply_fault(f, false, sched_.now());
  run_until(0.4);
  for (int k = 0; k < 4; ++k) EXPECT_TRUE(running(k)) << k;
}

TEST_F(M3NetworkTest, CorruptionIsAnFcsErrorAtTheSlaveAndARetryAtTheMaster) {
  build("m3net-corrupt", {{"bus.seed", "3"}});
  run_until(0.1);
  FaultSpec f;
  f.kind = FaultSpec::Kind::corruption;
  f.wheel = 0;
  f.rate = 0.05;
  net_->apply_fault(f, true, sched_.now());
  run_until(1.1);
  EXPECT_GT(net_->slave_metrics()[0]["fcs_errors"].get<int>(), 0);
  EXPECT_GT(master_->counters(0).retries, 0u);
  EXPECT_EQ(master_->counters(1).retries, 0u) << "only slave 1's frames";
  EXPECT_GT(net_->bus_metrics(sched_.now())["corrupted_frames"].get<int>(), 0);
}

// Corruption on node master corrupts the master's commands only, as frame_loss on the master
// loses them: the slaves count FCS errors and no response reaches the master bad (it acted as
// `all`, corrupting the responses too; found in review).
TEST_F(M3NetworkTest, CorruptionOnTheMasterCorruptsItsCommandsOnly) {
  build("m3net-corrupt-master", {{"bus.seed", "3"}});
  run_until(0.1);
  FaultSpec f;
  f.kind = FaultSpec::Kind::corruption;
  f.wheel = FaultSpec::kMaster;
  f.rate = 0.05;
  net_->apply_fault(f, true, sched_.now());
  run_until(1.1);
  for (int k = 0; k < 4; ++k) {
    EXPECT_GT(net_->slave_metrics()[static_cast<std::size_t>(k)]["fcs_errors"].get<int>(), 0) << k;
    EXPECT_EQ(master_->counters(k).bad, 0u) << k;
  }
}

TEST_F(M3NetworkTest, ALateStationsResponsesAreLateAtTheMaster) {
  build("m3net-late");
  run_until(0.1);
  FaultSpec f;
  f.kind = FaultSpec::Kind::delay;
  f.wheel = 2;
  f.extra_ms = 0.005;  // 5 µs: beyond this station's T_RSP margin
  net_->apply_fault(f, true, sched_.now());
  run_until(0.11);
  EXPECT_GE(master_->counters(2).late, 10u);
  EXPECT_EQ(master_->counters(1).late, 0u);
  net_->apply_fault(f, false, sched_.now());
  const auto late = master_->counters(2).late;
  run_until(0.12);
  EXPECT_EQ(master_->counters(2).late, late) << "on time again";
}

// Found in review: the delay fault's jitter was drawn once per fault; it is drawn per response,
// so with a jitter about the station's T_RSP margin some responses are late and some are not.
TEST_F(M3NetworkTest, DelayJitterIsDrawnPerResponse) {
  build("m3net-jitter");
  run_until(0.1);
  FaultSpec f;
  f.kind = FaultSpec::Kind::delay;
  f.wheel = 2;
  f.jitter_ms = 0.01;  // 0 … 10 µs, across the margin the 5 µs test above exceeds
  const m3::SlaveCounters before = master_->counters(2);
  net_->apply_fault(f, true, sched_.now());
  run_until(0.2);
  const std::uint64_t late = master_->counters(2).late - before.late;
  // One delay for all would make every retry late too (or none): a retry that recovers is a
  // late response followed by an on-time one.
  const std::uint64_t recovered = master_->counters(2).retry_recovered - before.retry_recovered;
  EXPECT_GT(late, 5u);
  EXPECT_GT(recovered, 5u) << "late " << late;
  EXPECT_EQ(master_->counters(1).late, 0u);
}

// Stations beyond the four wheels: on the line at the next addresses, started like the
// wheels, their servos turning shafts of their own; the wheels are unaffected.
TEST_F(M3NetworkTest, StationsBeyondTheWheelsAreOnTheLineWithShaftsOfTheirOwn) {
  build("m3net-stations", {}, 6);
  axes_[5].set_velocity(131072);
  run_until(0.5);
  ASSERT_EQ(master_->state(), m3::DriverState::cyclic) << master_->why();
  for (int k = 0; k < 6; ++k) EXPECT_TRUE(running(k)) << k;
  const nlohmann::json s = net_->slave_metrics();
  ASSERT_EQ(s.size(), 6u);
  EXPECT_EQ(s[5]["address"], 0x08);
  EXPECT_EQ(s[5]["servo"], "operation enabled");
  EXPECT_GT(net_->segment().servo(5).drive().objects().velocity_actual, 100000) << "its own shaft turns";
  for (std::size_t i = 0; i < 4; ++i) EXPECT_EQ(speed_[i], 0.0) << "no wheel was asked to move";
}

TEST_F(M3NetworkTest, TheMetricsNameEverySlavesPhaseAndAlarms) {
  build("m3net-metrics");
  run_until(0.1);
  const nlohmann::json b = net_->bus_metrics(sched_.now()), s = net_->slave_metrics();
  EXPECT_EQ(b["name"], "m3");
  EXPECT_EQ(b["topology"], "cascade");
  EXPECT_EQ(b["cycle_ns"], 1'000'000);
  ASSERT_EQ(s.size(), 4u);
  for (int k = 0; k < 4; ++k) {
    EXPECT_EQ(s[k]["address"], 0x03 + k);
    EXPECT_EQ(s[k]["phase"], 3);
    EXPECT_EQ(s[k]["comm_alarm"], "normal");
    EXPECT_EQ(s[k]["servo"], "operation enabled");
  }
}

}  // namespace
}  // namespace omnitwin::twin
