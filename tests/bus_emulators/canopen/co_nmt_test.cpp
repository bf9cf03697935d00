// Tests bus_emulators/canopen/co_nmt: the NMT slave's transitions and boot-up message, the
// heartbeat producer's timing, node guarding with its toggle bit and life guarding, and the
// heartbeat consumer's timeout, resume and boot-up events.
#include "bus_emulators/canopen/co_nmt.hpp"

#include <gtest/gtest.h>

#include <vector>

namespace omnitwin::canopen {
namespace {

constexpr SimTime kMs = 1'000'000;

struct Sent {
  can::Frame f;
  SimTime t;
};

struct Wire {
  std::vector<Sent> sent;
  SendFn fn() {
    return [this](const can::Frame& f, SimTime t) {
      sent.push_back({f, t});
      return true;
    };
  }
};

can::Frame nmt(std::uint8_t cs, std::uint8_t node) { return can::make_data(0, {cs, node}); }

TEST(NmtSlave, BootsUpIntoPreOperationalWithTheBootUpMessage) {
  Wire w;
  NmtSlave n(5);
  EXPECT_EQ(n.state(), NmtState::initialising);
  EXPECT_FALSE(n.apply(NmtTransition::start, 0, w.fn()));  // not legal while initialising
  ASSERT_TRUE(n.apply(NmtTransition::boot_up, 10, w.fn()));
  EXPECT_EQ(n.state(), NmtState::pre_operational);
  ASSERT_EQ(w.sent.size(), 1u);
  EXPECT_EQ(w.sent[0].f, can::make_data(0x705, {0x00}));
  EXPECT_EQ(w.sent[0].t, 10);
  EXPECT_FALSE(n.apply(NmtTransition::boot_up, 20, w.fn()));
}

TEST(NmtSlave, DecodesCommandsForItselfAndForAllOnly) {
  NmtSlave n(5);
  NmtTransition t{};
  EXPECT_TRUE(n.decode(nmt(0x01, 5), t));
  EXPECT_EQ(t, NmtTransition::start);
  EXPECT_TRUE(n.decode(nmt(0x81, 0), t));
  EXPECT_EQ(t, NmtTransition::reset_node);
  EXPECT_FALSE(n.decode(nmt(0x01, 6), t));              // another node
  EXPECT_FALSE(n.decode(nmt(0x03, 5), t));              // no such command
  EXPECT_FALSE(n.decode(can::make_data(0, {0x01}), t)); // wrong length
}

TEST(NmtSlave, FollowsTheStateDiagram) {
  Wire w;
  NmtSlave n(1);
  n.apply(NmtTransition::boot_up, 0, w.fn());
  EXPECT_TRUE(n.apply(NmtTransition::start, 0, w.fn()));
  EXPECT_EQ(n.state(), NmtState::operational);
  EXPECT_TRUE(n.apply(NmtTransition::stop, 0, w.fn()));
  EXPECT_EQ(n.state(), NmtState::stopped);
  EXPECT_TRUE(n.apply(NmtTransition::enter_pre_operational, 0, w.fn()));
  EXPECT_EQ(n.state(), NmtState::pre_operational);
  EXPECT_TRUE(n.apply(NmtTransition::reset_communication, 0, w.fn()));
  EXPECT_EQ(n.state(), NmtState::initialising);
  EXPECT_EQ(w.sent.size(), 1u);  // only the first boot-up so far
}

TEST(ErrorControlProducer, HeartbeatsAtTheConfiguredPeriodWithTheState) {
  Wire w;
  ErrorControlProducer p(3);
  p.restart(0);
  ErrorControlParams par;
  par.heartbeat_ms = 100;
  for (SimTime t = 0; t <= 350 * kMs; t += kMs) p.on_time(t, par, NmtState::operational, w.fn());
  ASSERT_EQ(w.sent.size(), 3u);
  EXPECT_EQ(w.sent[0].t, 100 * kMs);
  EXPECT_EQ(w.sent[2].t, 300 * kMs);
  EXPECT_EQ(w.sent[1].f, can::make_data(0x703, {0x05}));
  EXPECT_EQ(p.heartbeats_sent(), 3u);
}

// 0x1017 written long after boot-up: the first heartbeat one period after the write, then one
// per period — no burst catching up from the boot-up time.
TEST(ErrorControlProducer, AHeartbeatTimeWrittenLongAfterBootUpStartsOnePeriodLater) {
  Wire w;
  ErrorControlProducer p(3);
  p.restart(0);
  ErrorControlParams par;  // 0x1017 = 0: no heartbeat
  for (SimTime t = kMs; t <= 10'000 * kMs; t += kMs) p.on_time(t, par, NmtState::operational, w.fn());
  EXPECT_TRUE(w.sent.empty());
  par.heartbeat_ms = 100;
  for (SimTime t = 10'001 * kMs; t <= 10'301 * kMs; t += kMs) p.on_time(t, par, NmtState::operational, w.fn());
  ASSERT_EQ(w.sent.size(), 3u);
  EXPECT_EQ(w.sent[0].t, 10'101 * kMs);
  EXPECT_EQ(w.sent[1].t, 10'201 * kMs);
  EXPECT_EQ(w.sent[2].t, 10'301 * kMs);
}

// A caller that comes late (several periods overdue) gets one heartbeat, and the next one a
// period after it.
TEST(ErrorControlProducer, SendsAtMostOneHeartbeatPerCall) {
  Wire w;
  ErrorControlProducer p(3);
  p.restart(0);
  ErrorControlParams par;
  par.heartbeat_ms = 100;
  p.on_time(0, par, NmtState::operational, w.fn());
  p.on_time(1'000 * kMs, par, NmtState::operational, w.fn());
  ASSERT_EQ(w.sent.size(), 1u);
  p.on_time(1'099 * kMs, par, NmtState::operational, w.fn());
  EXPECT_EQ(w.sent.size(), 1u);
  p.on_time(1'100 * kMs, par, NmtState::operational, w.fn());
  EXPECT_EQ(w.sent.size(), 2u);
}

TEST(ErrorControlProducer, AnswersGuardingWithAToggleAndDetectsLifeGuarding) {
  Wire w;
  ErrorControlProducer p(3);
  p.reset(0);
  ErrorControlParams par;
  par.guard_time_ms = 100;
  par.life_factor = 3;
  EXPECT_EQ(p.on_guard_request(0, par, NmtState::pre_operational, w.fn()), LifeGuardEvent::none);
  EXPECT_EQ(p.on_guard_request(100 * kMs, par, NmtState::pre_operational, w.fn()), LifeGuardEvent::none);
  ASSERT_EQ(w.sent.size(), 2u);
  EXPECT_EQ(w.sent[0].f.data[0], 0x7F);
  EXPECT_EQ(w.sent[1].f.data[0], 0xFF);  // toggle bit set on the second answer
  EXPECT_EQ(p.on_time(400 * kMs, par, NmtState::pre_operational, w.fn()), LifeGuardEvent::none);  // 300 ms
  EXPECT_EQ(p.on_time(401 * kMs, par, NmtState::pre_operational, w.fn()), LifeGuardEvent::lost);
  EXPECT_EQ(p.on_time(500 * kMs, par, NmtState::pre_operational, w.fn()), LifeGuardEvent::none);  // once
  EXPECT_EQ(p.on_guard_request(600 * kMs, par, NmtState::pre_operational, w.fn()), LifeGuardEvent::resumed);
}

TEST(ErrorControlProducer, IgnoresGuardingWhileTheHeartbeatRuns) {
  Wire w;
  ErrorControlProducer p(3);
  ErrorControlParams par;
  par.heartbeat_ms = 50;
  EXPECT_EQ(p.on_guard_request(0, par, NmtState::operational, w.fn()), LifeGuardEvent::none);
  EXPECT_TRUE(w.sent.empty());
}

TEST(HeartbeatConsumer, TimesOutResumesAndSeesBootUp) {
  std::vector<HeartbeatEvent> ev;
  HeartbeatConsumer c([&](const HeartbeatEvent& e) { ev.push_back(e); });
  c.set(7, 150);
  c.on_time(1000 * kMs);  // never heard: not monitored yet
  EXPECT_TRUE(ev.empty());
  c.on_frame(can::make_data(0x707, {0x05}), 0);
  EXPECT_TRUE(c.alive(7));
  ASSERT_EQ(ev.size(), 1u);  // state changed initialising → operational
  c.on_time(150 * kMs);
  EXPECT_EQ(ev.size(), 1u);
  c.on_time(151 * kMs);
  ASSERT_EQ(ev.size(), 2u);
  EXPECT_EQ(ev[1].kind, HeartbeatEvent::timeout);
  EXPECT_EQ(ev[1].node, 7);
  EXPECT_FALSE(c.alive(7));
  c.on_frame(can::make_data(0x707, {0x00}), 200 * kMs);  // it rebooted
  ASSERT_EQ(ev.size(), 3u);
  EXPECT_EQ(ev[2].kind, HeartbeatEvent::boot_up);
  c.on_frame(can::make_data(0x707, {0x7F}), 210 * kMs);
  EXPECT_EQ(ev.back().kind, HeartbeatEvent::state_changed);
  EXPECT_EQ(c.state(7), NmtState::pre_operational);
  EXPECT_EQ(c.timeouts(), 1u);
}

TEST(HeartbeatConsumer, ReadsTheObject1016Format) {
  HeartbeatConsumer c(nullptr);
  EXPECT_TRUE(c.set_from_entry(0x0001'00C8));  // node 1, 200 ms
  EXPECT_TRUE(c.set_from_entry(0));            // unused
  EXPECT_FALSE(c.set_from_entry(0x0080'0064)); // node 128
  c.on_frame(can::make_data(0x701, {0x05}), 0);
  c.on_time(200 * kMs);
  EXPECT_TRUE(c.alive(1));
  c.on_time(201 * kMs);
  EXPECT_FALSE(c.alive(1));
}

}  // namespace
}  // namespace omnitwin::canopen
