// Tests controller/mechatrolink3/m3_master (with m3_servo_axis as its application): our C1
// master over the in-process line (m3_line) to emulated slaves (m3_link + m3_servo on the
// shared drive core, closed over axis models). The driver sequence of seed 000 figs. 9-11
// appears in the log in order, measures every slave's TR_DLY exactly, computes T_RSP and
// INT_OFFSET as m3_wire plans them, and refuses a missing slave or a cycle too short (naming
// the shortest that fits); the servo start-up of fig. 8 brings four servos on and they turn
// at the commanded speed; lost commands and corrupted responses are retried inside the same
// cycle and never reach the slaves as missed commands; a slave off the line is counted
// missed without disturbing the others; a slave that loses power and returns, and a servo
// stopped by a communication alarm, are brought back by the application; a master that stops
// trips every slave's watchdog; event-driven, each slave's requests carry their own sequence
// numbers, so a lost command's retry is run, not taken for a retry of the one before.
#include "controller/mechatrolink3/m3_master.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "bus_emulators/drive/axis_model.hpp"
#include "bus_emulators/mechatrolink3/m3_line.hpp"
#include "bus_emulators/mechatrolink3/m3_link.hpp"
#include "bus_emulators/mechatrolink3/m3_servo.hpp"
#include "controller/mechatrolink3/m3_servo_axis.hpp"

namespace omnitwin::m3 {
namespace {

constexpr SimTime kMs = 1'000'000;
constexpr double kCpr = 10000;

ServoConfig servo_config() {
  ServoConfig c;
  c.drive.counts_per_rev = kCpr;
  c.drive.max_speed_rad_s = 200;
  return c;
}

// A C1 master, the line and n servo slaves with their axes, stepped on one timeline.
struct Rig {
  Topology topology;
  Line line;
  std::vector<std::unique_ptr<ServoProfile>> servos;
  std::vector<std::unique_ptr<SlaveLink>> links;
  std::vector<drive::AxisModel> axes;
  std::vector<ServoAxis> apps;
  std::vector<std::string> log;
  std::unique_ptr<C1Master> master;
  SimTime now = 0, next_drive = 0;
  bool master_alive = true;

  explicit Rig(int n, MasterConfig cfg = {}, int attached = -1,
               std::vector<std::pair<std::uint16_t, std::int32_t>> params = {})
      : topology(Topology::cascade_of(n, 10.0)), line(topology) {
    const std::size_t bytes = cfg.event_driven ? 64 : 32;
    if (cfg.slaves.empty())
      for (int k = 0; k < n; ++k)
        cfg.slaves.push_back(MasterSlave{.address = static_cast<std::uint8_t>(kFirstSlave + k), .data_bytes = bytes});
    for (int k = 0; k < n; ++k) {
      servos.push_back(std::make_unique<ServoProfile>(servo_config()));
      links.push_back(std::make_unique<SlaveLink>(
          LinkConfig{.address = static_cast<std::uint8_t>(kFirstSlave + k)}, *servos.back(),
          [this, k](std::span<const std::uint8_t> f, SimTime t) { line.from_slave(k, f, t); }));
      line.attach_slave(k, [this, k](std::span<const std::uint8_t> f, SimTime t) { links[static_cast<std::size_t>(k)]->on_frame(f, t); });
      axes.emplace_back();
      apps.emplace_back(fmt_name(k), ServoAxisConfig{.com_tim = 1, .synchronous = !cfg.event_driven, .position_mode = false, .params = params},
                        [this](SimTime, const std::string& s) { log.push_back(s); });
      if (attached < 0 || k < attached) links.back()->power_on(0);
      else line.set_reachable(k, false);
    }
    master = std::make_unique<C1Master>(
        cfg, [this](std::span<const std::uint8_t> f, SimTime t) { line.from_master(f, t); },
        [this](std::uint64_t, SimTime t) {
          for (int k = 0; k < master->slaves(); ++k)
            apps[static_cast<std::size_t>(k)].on_interrupt(master->response(k), master->fresh(k), master->command(k), t);
        },
        [this](SimTime, const std::string& s) { log.push_back(s); });
    line.attach_master([this](std::span<const std::uint8_t> f, SimTime t) {
      if (master_alive) master->on_frame(f, t);
    });
  }
  static std::string fmt_name(int k) { return "axis " + std::to_string(k + 1); }

  void run_until(SimTime end) {
    for (;;) {
      SimTime t = end + 1;
      for (SimTime c : {master_alive ? master->next_wakeup() : SimTime{-1}, line.next_due(), next_drive})
        if (c >= 0 && c < t) t = c;
      if (t > end) break;
      now = t;
      line.advance(t);
      if (master_alive) master->advance(t);
      for (auto& l : links) l->advance(t);
      if (t == next_drive) {
        for (std::size_t k = 0; k < axes.size(); ++k) axes[k].step(servos[k]->step(t, axes[k].feedback()), 1e-3);
        next_drive += kMs;
      }
    }
    now = end;
  }
  std::size_t find(const std::string& text, std::size_t from = 0) const {
    for (std::size_t i = from; i < log.size(); ++i)
      if (log[i].find(text) != std::string::npos) return i;
    return log.size();
  }
};

TEST(M3Master, TheDriverSequenceMeasuresTrDlyAndPlansTheCycle) {
  Rig rig(4);
  rig.master->start(0);
  rig.run_until(5 * kMs);
  ASSERT_EQ(rig.master->state(), DriverState::cyclic) << rig.master->why();
  CycleInputs in;
  in.topology = rig.topology;
  in.stations.assign(4, StationTiming{.data_bytes = 32, .response_ns = 2'000});
  const CyclePlan plan = plan_cycle(in);
  for (int k = 0; k < 4; ++k) {
    EXPECT_EQ(rig.master->tr_dly_ns(k), tr_dly_ns(rig.topology, k)) << k;
    EXPECT_EQ(rig.master->t_rsp_ns(k), plan.t_rsp_ns[static_cast<std::size_t>(k)]) << k;
  }
  EXPECT_EQ(rig.master->int_offset_ns(), plan.int_offset_ns);
  // Figs. 9-11 in order.
  std::size_t at = 0;
  for (const char* step : {"initialisation request", "SRAM test", "connected-station detection", "station 03h detected",
                           "station 06h detected", "delay-time measurement", "station 06h TR_DLY",
                           "communication parameters", "station 03h T_RSP", "transmission-cycle notification",
                           "communication start"}) {
    at = rig.find(step, at);
    ASSERT_LT(at, rig.log.size()) << "missing or out of order: " << step;
  }
  EXPECT_GE(rig.master->cycles(), 3u);
}

TEST(M3Master, AMissingSlaveFailsDetectionNamingItsAddress) {
  Rig rig(4, {}, 3);
  rig.master->start(0);
  rig.run_until(5 * kMs);
  EXPECT_EQ(rig.master->state(), DriverState::failed);
  EXPECT_NE(rig.master->why().find("06h"), std::string::npos) << rig.master->why();
}

TEST(M3Master, ACycleTooShortIsRefusedNamingTheShortestThatFits) {
  MasterConfig cfg;
  for (int k = 0; k < 4; ++k) cfg.slaves.push_back(MasterSlave{.address = static_cast<std::uint8_t>(kFirstSlave + k)});
  cfg.cycle_ns = 50'000;
  Rig rig(4, cfg);
  rig.master->start(0);
  rig.run_until(5 * kMs);
  EXPECT_EQ(rig.master->state(), DriverState::failed);
  EXPECT_NE(rig.master->why().find("shortest cycle that fits is"), std::string::npos) << rig.master->why();
  EXPECT_EQ(rig.master->why().find("shortest cycle that fits is " +
                                   std::to_string((rig.master->min_cycle_ns() + 999) / 1000) + " µs") == std::string::npos,
            false);
}

TEST(M3Master, FourServosStartAsFigure8SaysAndTurnAtTheCommandedSpeed) {
  Rig rig(4);
  for (auto& a : rig.apps) a.set_velocity(static_cast<std::int32_t>(kCpr));  // 1 rev/s
  rig.master->start(0);
  rig.run_until(1500 * kMs);
  for (int k = 0; k < 4; ++k) {
    const auto& app = rig.apps[static_cast<std::size_t>(k)];
    ASSERT_EQ(app.step(), AxisStep::running) << k << " " << app.why();
    EXPECT_EQ(app.device(), "OMNITWIN M3-SERV") << "ID_RD, 16 characters";
    EXPECT_NEAR(rig.axes[static_cast<std::size_t>(k)].velocity_rad_s(), 2 * M_PI, 0.1);
    EXPECT_NEAR(app.velocity(), kCpr, 0.05 * kCpr) << "FSPD";
    EXPECT_EQ(rig.links[static_cast<std::size_t>(k)]->phase(), Phase::p3);
    EXPECT_EQ(rig.links[static_cast<std::size_t>(k)]->comm_alarm(), CommAlarm::normal);
    const SlaveCounters& c = rig.master->counters(k);
    EXPECT_EQ(c.retries, 0u);
    EXPECT_EQ(c.bad, 0u);
    EXPECT_EQ(c.late, 0u);
    EXPECT_LE(c.exchanges - rig.master->cycles(), 1u) << "one exchange per slave per cycle (the last one's interrupt may be ahead)";
    EXPECT_EQ(c.missed, 0u);
  }
  std::size_t at = 0;
  for (const char* step : {"axis 2: CONNECT", "axis 2: SYNC_SET", "axis 2: ID_RD", "axis 2: device", "axis 2: SENS_ON",
                           "axis 2: SV_ON", "axis 2: running"}) {
    at = rig.find(step, at);
    ASSERT_LT(at, rig.log.size()) << "missing or out of order: " << step;
  }
  // Shut-down: zero speed, SV_OFF, then DISCONNECT.
  for (auto& a : rig.apps) a.shutdown(rig.now);
  rig.run_until(1600 * kMs);
  for (int k = 0; k < 4; ++k) {
    EXPECT_EQ(rig.apps[static_cast<std::size_t>(k)].step(), AxisStep::released);
    EXPECT_EQ(rig.links[static_cast<std::size_t>(k)]->phase(), Phase::p1);
    EXPECT_FALSE(rig.servos[static_cast<std::size_t>(k)]->servo_on());
  }
}

TEST(M3Master, LostCommandsAndCorruptedResponsesAreRetriedInsideTheCycle) {
  MasterConfig cfg;
  for (int k = 0; k < 4; ++k) cfg.slaves.push_back(MasterSlave{.address = static_cast<std::uint8_t>(kFirstSlave + k)});
  cfg.retry_slots = 2;
  Rig rig(4, cfg);
  int commands = 0, responses = 0;
  rig.line.set_fault_hook([&](bool from_master, int, std::span<const std::uint8_t> f) {
    if (from_master && f[3] == static_cast<std::uint8_t>(FrameType::cyclic_command))
      return ++commands % 29 == 0 ? Fate::drop : Fate::deliver;
    if (!from_master && f[3] == static_cast<std::uint8_t>(FrameType::cyclic_response))
      return ++responses % 31 == 0 ? Fate::corrupt : Fate::deliver;
    return Fate::deliver;
  });
  for (auto& a : rig.apps) a.set_velocity(5000);
  rig.master->start(0);
  rig.run_until(1000 * kMs);
  std::uint64_t retries = 0, recovered = 0, bad = 0, missed = 0;
  for (int k = 0; k < 4; ++k) {
    const SlaveCounters& c = rig.master->counters(k);
    retries += c.retries;
    recovered += c.retry_recovered;
    bad += c.bad;
    missed += c.missed;
    EXPECT_EQ(rig.apps[static_cast<std::size_t>(k)].step(), AxisStep::running) << rig.apps[static_cast<std::size_t>(k)].why();
  }
  EXPECT_GT(retries, 200u);
  EXPECT_GT(bad, 80u) << "corrupted responses";
  // About 7 % of exchanges fail; a retry fails as often, so about 93 % come back in the cycle
  // and a slave misses its exchange only when its retry failed too (two slots: always room).
  EXPECT_GE(recovered, retries * 85 / 100);
  EXPECT_EQ(missed, retries - recovered);
  EXPECT_GT(rig.line.dropped(), 100u);
  EXPECT_GT(rig.line.corrupted(), 80u);
}

TEST(M3Master, ASlaveOffTheLineIsMissedWithoutDisturbingTheOthers) {
  Rig rig(4);
  rig.master->start(0);
  rig.run_until(100 * kMs);
  const std::uint64_t before = rig.master->counters(1).missed;
  rig.line.set_reachable(1, false);
  rig.run_until(120 * kMs);
  EXPECT_GE(rig.master->counters(1).missed - before, 19u);
  EXPECT_GE(rig.master->counters(1).retries, 19u) << "each cycle's retry slot went to it";
  for (int k : {0, 2, 3}) EXPECT_EQ(rig.master->counters(k).missed, 0u) << k;
}

// Item 6: a slave that loses power and comes back is connected again by the master.
TEST(M3Master, ASlaveThatLosesPowerAndReturnsIsConnectedAgain) {
  Rig rig(4);
  for (auto& a : rig.apps) a.set_velocity(static_cast<std::int32_t>(kCpr));
  rig.master->start(0);
  rig.run_until(400 * kMs);
  ASSERT_EQ(rig.apps[2].step(), AxisStep::running);
  rig.line.set_reachable(2, false);
  rig.links[2]->power_off(rig.now);
  rig.servos[2]->power_cycle();
  rig.run_until(450 * kMs);
  EXPECT_GE(rig.master->counters(2).missed, 45u);
  rig.links[2]->power_on(rig.now);
  rig.line.set_reachable(2, true);
  rig.run_until(900 * kMs);
  EXPECT_EQ(rig.apps[2].step(), AxisStep::running) << rig.apps[2].why();
  EXPECT_EQ(rig.apps[2].recoveries(), 1);
  EXPECT_TRUE(rig.servos[2]->servo_on());
  EXPECT_EQ(rig.links[2]->phase(), Phase::p3);
  EXPECT_NEAR(rig.axes[2].velocity_rad_s(), 2 * M_PI, 0.2);
  EXPECT_LT(rig.find("axis 3: ", 0), rig.log.size());
  EXPECT_LT(rig.find("recovering"), rig.log.size());
  for (int k : {0, 1, 3}) EXPECT_EQ(rig.apps[static_cast<std::size_t>(k)].recoveries(), 0) << k;
}

// A communication alarm (commands lost two cycles in a row, retries included) stops a servo;
// the master clears the alarm and switches it on again.
TEST(M3Master, AServoStoppedByACommunicationAlarmIsClearedAndSwitchedOnAgain) {
  Rig rig(2);
  for (auto& a : rig.apps) a.set_velocity(5000);
  rig.master->start(0);
  rig.run_until(300 * kMs);
  ASSERT_TRUE(rig.servos[1]->servo_on());
  bool cut = true;
  rig.line.set_fault_hook([&](bool from_master, int k, std::span<const std::uint8_t> f) {
    const bool command = from_master && f[3] == static_cast<std::uint8_t>(FrameType::cyclic_command);
    return cut && command && k == 1 ? Fate::drop : Fate::deliver;
  });
  rig.run_until(305 * kMs);
  EXPECT_EQ(rig.links[1]->comm_alarm(), CommAlarm::no_command);
  cut = false;
  rig.run_until(400 * kMs);
  EXPECT_EQ(rig.apps[1].step(), AxisStep::running) << rig.apps[1].why();
  EXPECT_EQ(rig.apps[1].recoveries(), 1);
  EXPECT_TRUE(rig.servos[1]->servo_on());
  EXPECT_EQ(rig.links[1]->comm_alarm(), CommAlarm::normal);
  EXPECT_LT(rig.find("ALM_CLR"), rig.log.size());
}

// Event-driven communication: no SYNC, one exchange at a time on request, 64-byte data,
// each slave's own response time (T_RSP, at most 50 ms) with the driver's retries.
TEST(M3Master, EventDrivenExchangesAnswerOnRequestWithinTheirOwnResponseTime) {
  MasterConfig cfg;
  cfg.event_driven = true;
  Rig rig(3, cfg);
  std::vector<SimTime> latency(3, -1);
  std::vector<int> failures(3, 0);
  rig.master->on_event([&](int k, bool ok, SimTime lat) {
    latency[static_cast<std::size_t>(k)] = lat;
    failures[static_cast<std::size_t>(k)] += ok ? 0 : 1;
    auto& app = rig.apps[static_cast<std::size_t>(k)];
    app.on_interrupt(rig.master->response(k), ok, rig.master->command(k), rig.now);
    rig.master->request(k, rig.now);  // the next exchange at once
  });
  for (auto& a : rig.apps) a.set_velocity(5000);
  rig.master->start(0);
  rig.run_until(1 * kMs);
  ASSERT_EQ(rig.master->state(), DriverState::event) << rig.master->why();
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(rig.master->request(k, rig.now));
  rig.run_until(300 * kMs);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(rig.apps[static_cast<std::size_t>(k)].step(), AxisStep::running) << rig.apps[static_cast<std::size_t>(k)].why();
    EXPECT_EQ(rig.links[static_cast<std::size_t>(k)]->phase(), Phase::p2) << "event-driven never enters phase 3";
    EXPECT_TRUE(rig.servos[static_cast<std::size_t>(k)]->servo_on());
  }
  EXPECT_GT(rig.axes[0].velocity_rad_s(), 2.5);
  // With the others queued ahead, a request waits for them; the exchange itself is TR_DLY +
  // two 64-byte frames + the slave's 2 µs response time, exactly.
  const SimTime own = tr_dly_ns(rig.topology, 2) + 2 * frame_time_ns(64) + 2'000;
  EXPECT_GE(latency[2], own);
  EXPECT_LE(latency[2], 3 * (own + 2 * 960) + 3 * tr_dly_ns(rig.topology, 2));
  EXPECT_EQ(failures, (std::vector<int>{0, 0, 0}));
  // A slave that stops answering: its T_RSP, the driver's two retries, then a failure.
  rig.line.set_reachable(1, false);
  rig.run_until(600 * kMs);
  EXPECT_GE(failures[1], 1);
  EXPECT_GE(latency[1], 3 * rig.master->t_rsp_ns(1));
  EXPECT_GE(rig.master->counters(1).retries, 2u);
  EXPECT_EQ(failures[0], 0) << "the others still answer";
}

// Event-driven, the program's way: one request per slave every 1 ms cycle, and one slave
// silent (its power lost). An exchange waits for the slave's own response time (seed 000 fig. 6:
// each slave answers within its own; 50 ms is the most any may take): T_RSP from the measured
// TR_DLY, as in cyclic communication, so the driver's two retries to the silent slave hold the
// line for microseconds and the others are still served every cycle. With 50 ms per attempt
// they were served once every 150 ms.
TEST(M3Master, EventDrivenASilentSlaveHoldsTheLineOnlyForItsOwnResponseTime) {
  MasterConfig cfg;
  cfg.event_driven = true;
  Rig rig(4, cfg);
  std::vector<int> answered(4, 0), failed(4, 0);
  std::vector<SimTime> latency(4, -1);
  rig.master->on_event([&](int k, bool ok, SimTime lat) {
    const auto i = static_cast<std::size_t>(k);
    (ok ? answered : failed)[i] += 1;
    latency[i] = lat;
    rig.apps[i].on_interrupt(rig.master->response(k), ok, rig.master->command(k), rig.now);
  });
  auto cycles = [&](int from_ms, int to_ms) {
    for (int ms = from_ms; ms < to_ms; ++ms) {
      for (int k = 0; k < 4; ++k) rig.master->request(k, rig.now);
      rig.run_until((ms + 1) * kMs);
    }
  };
  rig.master->start(0);
  rig.run_until(1 * kMs);
  ASSERT_EQ(rig.master->state(), DriverState::event) << rig.master->why();
  cycles(1, 100);
  for (const auto& a : rig.apps) ASSERT_EQ(a.step(), AxisStep::running) << a.why();
  for (int k = 0; k < 4; ++k) {
    EXPECT_EQ(rig.master->t_rsp_ns(k), t_rsp_ns(CycleInputs{.topology = rig.topology, .stations = std::vector<StationTiming>(4, StationTiming{.data_bytes = 64})}, k))
        << "T_RSP as in cyclic communication, for 64-byte data";
  }
  rig.line.set_reachable(3, false);
  answered.assign(4, 0);
  cycles(100, 200);
  for (int k = 0; k < 3; ++k) EXPECT_GE(answered[static_cast<std::size_t>(k)], 99) << "slave " << k + 1 << ": served every cycle";
  EXPECT_EQ(answered[3], 0);
  EXPECT_GE(failed[3], 99) << "a failed exchange with the silent slave every cycle";
  // Requested after the others: their exchanges, then three attempts of T_RSP each.
  SimTime bound = 3 * (rig.master->t_rsp_ns(3) + kInterFrameGapNs);
  for (int k = 0; k < 3; ++k) bound += rig.master->t_rsp_ns(k) + kInterFrameGapNs;
  EXPECT_LE(latency[3], bound);
  EXPECT_GE(latency[3], 3 * rig.master->t_rsp_ns(3));
  EXPECT_EQ(rig.master->counters(3).retries, 2u * static_cast<std::uint64_t>(failed[3]));
}

// A slave configured with a response time beyond seed 000's 50 ms is waited for 50 ms only.
TEST(M3Master, EventDrivenExchangesWaitAtMostTheFiftyMillisecondLimit) {
  MasterConfig cfg;
  cfg.event_driven = true;
  for (int k = 0; k < 2; ++k)
    cfg.slaves.push_back(MasterSlave{.address = static_cast<std::uint8_t>(kFirstSlave + k), .data_bytes = 64,
                                     .response_ns = k == 1 ? 80 * kMs : 2'000});
  Rig rig(2, cfg);
  rig.master->start(0);
  rig.run_until(1 * kMs);
  ASSERT_EQ(rig.master->state(), DriverState::event) << rig.master->why();
  EXPECT_LT(rig.master->t_rsp_ns(0), 1 * kMs);
  EXPECT_EQ(rig.master->t_rsp_ns(1), cfg.event_timeout_ns);
}

// Event-driven with 16 slaves requested round-robin: every slave's new commands carry a
// sequence number of its own that advances by one, so the retry of a lost command is never
// mistaken for a retry of the slave's previous command (with one counter for all requests,
// each of the 16 slaves saw the same number every time, and the slave answered the retried
// SVPRM_WR 0103h from the stored response of SVPRM_WR 0102h: "done", never written).
TEST(M3Master, EventDrivenRetriesOfALostCommandRunItWithEachSlavesOwnSequenceNumber) {
  MasterConfig cfg;
  cfg.event_driven = true;
  const int n = 16;
  Rig rig(n, cfg, -1, {{0x0102, 111111}, {0x0103, 222222}});
  constexpr int kVictim = 5;  // station 08h
  int dropped = 0;
  std::vector<int> sequences;  // of the first attempts to the victim
  rig.line.set_fault_hook([&](bool from_master, int k, std::span<const std::uint8_t> f) {
    FrameView v;
    if (!from_master || k != kVictim || decode(f, v) != FrameStatus::ok || v.type != FrameType::event_command ||
        v.dst != kFirstSlave + kVictim)
      return Fate::deliver;
    if (!v.retry()) sequences.push_back(v.sequence());
    const bool wr_0103 = v.data[0] == static_cast<std::uint8_t>(Command::svprm_wr) && get_u16(v.data, 12) == 0x0103;
    if (wr_0103 && !v.retry() && dropped++ == 0) return Fate::drop;
    return Fate::deliver;
  });
  rig.master->on_event([&](int k, bool ok, SimTime) {
    rig.apps[static_cast<std::size_t>(k)].on_interrupt(rig.master->response(k), ok, rig.master->command(k), rig.now);
    rig.master->request(k, rig.now);
  });
  rig.master->start(0);
  rig.run_until(1 * kMs);
  ASSERT_EQ(rig.master->state(), DriverState::event) << rig.master->why();
  for (int k = 0; k < n; ++k) ASSERT_TRUE(rig.master->request(k, rig.now));
  rig.run_until(400 * kMs);
  ASSERT_EQ(dropped, 1);
  EXPECT_GE(rig.master->counters(kVictim).retries, 1u);
  for (int k = 0; k < n; ++k) {
    const auto& o = rig.servos[static_cast<std::size_t>(k)]->drive().objects();
    EXPECT_EQ(o.profile_acceleration, 111111u) << "station " << k;
    EXPECT_EQ(o.profile_deceleration, 222222u) << "station " << k << ": SVPRM_WR 0103h carried out";
    EXPECT_EQ(rig.apps[static_cast<std::size_t>(k)].step(), AxisStep::running) << rig.apps[static_cast<std::size_t>(k)].why();
  }
  ASSERT_GE(sequences.size(), 4u);
  for (std::size_t i = 1; i < sequences.size(); ++i)
    EXPECT_EQ(sequences[i], (sequences[i - 1] + 1) % 16) << "exchange " << i << " with station 08h";
}

TEST(M3Master, ACutCableDropsEveryStationBehindItAndTheOthersRunOn) {
  Rig rig(4);
  for (auto& a : rig.apps) a.set_velocity(5000);
  rig.master->start(0);
  rig.run_until(300 * kMs);
  rig.line.cut_cable(1);  // behind the second station
  rig.run_until(320 * kMs);
  for (int k : {2, 3}) {
    EXPECT_GE(rig.master->counters(k).missed, 19u) << k;
    EXPECT_EQ(rig.links[static_cast<std::size_t>(k)]->comm_alarm(), CommAlarm::no_sync) << k;
    EXPECT_FALSE(rig.servos[static_cast<std::size_t>(k)]->servo_on()) << k;
  }
  for (int k : {0, 1}) {
    EXPECT_EQ(rig.master->counters(k).missed, 0u) << k;
    EXPECT_TRUE(rig.servos[static_cast<std::size_t>(k)]->servo_on()) << k;
  }
  rig.line.mend_cable();
  rig.run_until(500 * kMs);
  for (int k : {2, 3}) {
    EXPECT_EQ(rig.apps[static_cast<std::size_t>(k)].step(), AxisStep::running) << rig.apps[static_cast<std::size_t>(k)].why();
    EXPECT_TRUE(rig.servos[static_cast<std::size_t>(k)]->servo_on()) << "alarm cleared, switched on again";
  }
}

// A slave slower than the master allows for answers after T_RSP: late, retried, missed.
TEST(M3Master, ResponsesLaterThanTrspAreLateAndMissed) {
  Rig rig(2);
  rig.master->start(0);
  rig.run_until(50 * kMs);
  ASSERT_EQ(rig.master->state(), DriverState::cyclic);
  auto& link = rig.links[1];
  link = std::make_unique<SlaveLink>(LinkConfig{.address = 0x04, .response_ns = 30'000}, *rig.servos[1],
                                     [&rig](std::span<const std::uint8_t> f, SimTime t) { rig.line.from_slave(1, f, t); });
  link->power_on(rig.now);
  rig.run_until(80 * kMs);
  EXPECT_GE(rig.master->counters(1).late, 20u);
  EXPECT_GE(rig.master->counters(1).missed, 20u);
  EXPECT_EQ(rig.master->counters(0).missed, 0u);
}

// Malformed input on the master's side and a second C1 master: counted, never acted on.
TEST(M3Master, GarbageAndASecondC1MasterAreCountedAndIgnored) {
  Rig rig(2);
  rig.master->start(0);
  rig.run_until(20 * kMs);
  ASSERT_EQ(rig.master->state(), DriverState::cyclic);
  const std::uint64_t cycles = rig.master->cycles();
  std::vector<std::uint8_t> other(kMaxFrame);
  other.resize(encode(FrameSpec{.dst = kBroadcast, .src = kC1Master, .type = FrameType::sync,
                                .data = std::vector<std::uint8_t>(8, 0)}, other));
  for (int i = 0; i < 5; ++i) rig.master->on_frame(other, rig.now);
  rig.master->on_frame(std::vector<std::uint8_t>{1, 2, 3}, rig.now);
  rig.master->on_frame(std::vector<std::uint8_t>(200, 0xFF), rig.now);
  rig.run_until(40 * kMs);
  EXPECT_EQ(rig.master->foreign_master_frames(), 5u);
  EXPECT_EQ(std::count_if(rig.log.begin(), rig.log.end(),
                          [](const std::string& l) { return l.find("another C1 master") != std::string::npos; }),
            1) << "logged once";
  EXPECT_EQ(rig.master->state(), DriverState::cyclic);
  EXPECT_GE(rig.master->cycles(), cycles + 19);
  for (int k = 0; k < 2; ++k) EXPECT_EQ(rig.master->counters(k).missed, 0u);
}

TEST(M3Master, AMasterThatStopsTripsEverySlavesWatchdogAndTheServosGoOff) {
  Rig rig(4);
  for (auto& a : rig.apps) a.set_velocity(static_cast<std::int32_t>(kCpr));
  rig.master->start(0);
  rig.run_until(500 * kMs);
  ASSERT_TRUE(rig.servos[0]->servo_on());
  rig.master_alive = false;
  rig.run_until(520 * kMs);
  for (int k = 0; k < 4; ++k) {
    EXPECT_EQ(rig.links[static_cast<std::size_t>(k)]->comm_alarm(), CommAlarm::no_sync) << k;
    EXPECT_EQ(rig.links[static_cast<std::size_t>(k)]->phase(), Phase::p2);
    EXPECT_FALSE(rig.servos[static_cast<std::size_t>(k)]->servo_on());
  }
}

}  // namespace
}  // namespace omnitwin::m3
