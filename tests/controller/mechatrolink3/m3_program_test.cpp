// Tests the `--bus m3` program path (run_m3_program) in process, with the twin's side of the
// line (M3Segment: four servo slaves behind the in-process transport) in a thread: on the wall
// clock served as its frames come, in lockstep behind a sim-clock server that stands in for
// the twin (each Sent answered from the segment, the slaves' timers and drives run between
// ticks). The end of a run — --duration on the wall clock, SIGINT in lockstep — leaves every
// servo off and disconnected (SV_OFF, DISCONNECT: seed 000 fig. 8's end): they were left on,
// in phase 3, until their own watchdogs raised COMM_ALM. A lost axis stops the servos, and
// --stats names the reason and the axis; a run ending as planned has none.
#include "controller/mechatrolink3/m3_program.hpp"

#include <gtest/gtest.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "bus_emulators/drive/axis_model.hpp"
#include "bus_emulators/mechatrolink3/transport/m3_segment.hpp"
#include "bus_emulators/mechatrolink3/transport/m3_transport.hpp"
#include "controller/sim_clock.hpp"
#include "tests/support/temp_dir.hpp"

#include <nlohmann/json.hpp>

namespace omnitwin::m3 {
namespace {

using namespace std::chrono_literals;
constexpr SimTime kMs = 1'000'000;
constexpr int kServos = 4;

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// The program reads SIGINT/SIGTERM from its signalfd; a thread of the test never takes them.
void block_signals() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
}

SegmentConfig segment_config() {
  SegmentConfig c;
  c.topology = Topology::cascade_of(kServos, 10.0);
  c.servo.drive.counts_per_rev = 10000;
  return c;
}

// The servos' state once the twin's side stopped.
struct ServoEnd {
  bool servo_on = false;
  Phase phase = Phase::p1;
  std::uint64_t comm_alarms = 0;
};

// The twin's side on the wall clock: every frame enters the line as it comes, the slaves'
// timers and drives run every millisecond.
class WallTwin {
 public:
  explicit WallTwin(const std::string& iface)
      : tr_(open_transport(iface, Role::slaves)), segment_(segment_config(), *tr_) {
    thread_ = std::thread([this] { serve(); });
  }
  ~WallTwin() { stop(); }
  void stop() {
    run_ = false;
    if (thread_.joinable()) thread_.join();
  }
  ServoEnd servo(int k) {
    return {segment_.servo(k).servo_on(), segment_.link(k).phase(), segment_.link(k).stats().comm_alarms};
  }

 private:
  void serve() {
    block_signals();
    const std::int64_t start = now_ns();
    SimTime next_drive = 0;
    while (run_) {
      pollfd p{tr_->fd(), POLLIN, 0};
      ::poll(&p, 1, 1);
      const SimTime t = now_ns() - start;
      segment_.poll(t);
      segment_.advance(t);
      for (; next_drive <= t; next_drive += kMs)
        for (int k = 0; k < kServos; ++k)
          axes_[static_cast<std::size_t>(k)].step(segment_.step_drive(k, next_drive, axes_[static_cast<std::size_t>(k)].feedback()), 1e-3);
    }
  }
  std::unique_ptr<M3Transport> tr_;
  M3Segment segment_;
  std::vector<drive::AxisModel> axes_ = std::vector<drive::AxisModel>(kServos);
  std::atomic<bool> run_{true};
  std::thread thread_;
};

// The twin's side in lockstep: a sim-clock server granting 1 ms ticks, each Sent answered by
// the segment, the slaves' timers and drives run between ticks. Once the master reports every
// servo on for `signal_after` ticks, SIGINT goes to the process (or, with `lose_axis` ≥ 0,
// that servo drops off the line: power lost); the twin grants on until the master closes the
// channel or `max_ticks`.
class LockstepTwin {
 public:
  LockstepTwin(const std::string& iface, const std::string& clock, int signal_after, int max_ticks, int lose_axis = -1)
      : tr_(open_transport(iface, Role::slaves)),
        segment_(segment_config(), *tr_),
        server_(clock),
        signal_after_(signal_after),
        max_ticks_(max_ticks),
        lose_axis_(lose_axis) {
    thread_ = std::thread([this] { serve(); });
  }
  ~LockstepTwin() { join(); }
  void join() {
    if (thread_.joinable()) thread_.join();
  }
  ServoEnd servo(int k) {
    return {segment_.servo(k).servo_on(), segment_.link(k).phase(), segment_.link(k).stats().comm_alarms};
  }
  std::int64_t signalled_tick = -1;  // the tick after whose Done SIGINT was sent (-1: never)
  std::int64_t last_tick = -1;       // the last tick the master answered
  bool closed = false;               // the master closed the channel (else max_ticks ended it)

 private:
  void serve() {
    block_signals();
    if (server_.accept(10s) != simclock::WaitStatus::ok) return;
    const simclock::Server::OnSent on_sent = [](void* ctx, const simclock::Sent& s) {
      const SegmentAnswer a = static_cast<M3Segment*>(ctx)->take_sent(s.frames[0], s.t_ns, 5s);
      simclock::Horizon h;
      h.tick = s.tick;
      h.arrival_ns = a.arrival_ns;
      h.frames[0] = a.to_master;
      return h;
    };
    int running = 0;
    for (std::int64_t k = 0; k < max_ticks_; ++k) {
      simclock::Grant g;
      g.tick = static_cast<std::uint64_t>(k);
      g.t_ns = k * kMs;
      g.frames[0] = segment_.to_master();
      simclock::Done d;
      if (server_.grant(g, d, 10s, on_sent, &segment_) != simclock::WaitStatus::ok) {
        closed = true;
        return;
      }
      last_tick = k;
      const SimTime end = (k + 1) * kMs;
      segment_.advance(end);
      for (int i = 0; i < kServos; ++i)
        axes_[static_cast<std::size_t>(i)].step(segment_.step_drive(i, end, axes_[static_cast<std::size_t>(i)].feedback()), 1e-3);
      running = d.report.state == simclock::MasterState::running ? running + 1 : 0;
      if (signalled_tick < 0 && running >= signal_after_) {
        signalled_tick = k;
        if (lose_axis_ >= 0)
          segment_.line().set_reachable(lose_axis_, false);
        else
          ::kill(::getpid(), SIGINT);
      }
    }
    server_.end(max_ticks_ * kMs);
  }
  std::unique_ptr<M3Transport> tr_;
  M3Segment segment_;
  simclock::Server server_;
  std::vector<drive::AxisModel> axes_ = std::vector<drive::AxisModel>(kServos);
  int signal_after_, max_ticks_, lose_axis_;
  std::thread thread_;
};

class M3Program : public ::testing::Test {
 protected:
  std::string config(const std::string& body) {
    const std::string p = (dir_ / "m3.yaml").string();
    std::ofstream(p) << body;
    return p;
  }
  omnitwin::testing::TempDir dir_{"omnitwin-m3-program"};
};

// The end of --duration on the wall clock: zero speed, SV_OFF and DISCONNECT to every servo
// before the program returns; no servo is left on for its watchdog to stop; --stats gives no
// stop reason.
TEST_F(M3Program, TheEndOfTheDurationSwitchesEveryServoOffAndDisconnectsIt) {
  WallTwin twin("mem:m3_program_end");
  ProgramOptions o;
  o.iface = "mem:m3_program_end";
  // A long cycle and a wide margin: the twin is a thread of this (loaded) test process.
  o.config = config("cycle: 0.01\nmargin_us: 1000\ndetect_timeout_ms: 20\n");
  o.duration = 1.0;
  o.stats = (dir_ / "stats.json").string();
  EXPECT_EQ(run_m3_program(o), 0);
  twin.stop();
  // A run that ends as planned has no stop reason.
  std::ifstream f(o.stats);
  ASSERT_TRUE(f) << "no stats file";
  const nlohmann::json s = nlohmann::json::parse(f);
  EXPECT_NE(s.at("state"), "stopped") << s.dump(2);
  EXPECT_EQ(s.at("stop_reason"), "") << s.dump(2);
  for (int k = 0; k < kServos; ++k) {
    const ServoEnd s = twin.servo(k);
    EXPECT_FALSE(s.servo_on) << "servo " << k + 1;
    EXPECT_EQ(s.phase, Phase::p1) << "servo " << k + 1 << ": disconnected";
    EXPECT_EQ(s.comm_alarms, 0u) << "servo " << k + 1 << ": not stopped by its watchdog";
  }
}

// SIGINT to a lockstep master while the servos run (what `kill -INT` of omni-master does while
// the twin still grants ticks): SV_OFF and DISCONNECT to every servo in the ticks it is granted,
// within 100 ms of simulated time, then exit 0 and the channel closed. It used to return at the
// signal, leaving every servo on and in phase 3.
TEST_F(M3Program, SigintInLockstepSwitchesEveryServoOffAndDisconnectsItBeforeItEnds) {
  const std::string clock = "unix:" + (dir_ / "clock").string();
  LockstepTwin twin("mem:m3_program_sigint", clock, 50, 3000);
  ProgramOptions o;
  o.iface = "mem:m3_program_sigint";
  o.config = config("cycle: 0.001\n");
  o.clock = "sim";
  o.sim_clock = clock;
  EXPECT_EQ(run_m3_program(o), 0);
  twin.join();
  ASSERT_GE(twin.signalled_tick, 0) << "the servos never all ran";
  EXPECT_TRUE(twin.closed) << "the master did not end after SIGINT";
  EXPECT_GT(twin.last_tick, twin.signalled_tick + 2) << "not at once: the servos are answered first";
  EXPECT_LE(twin.last_tick, twin.signalled_tick + 102) << "within 100 ms of simulated time";
  for (int k = 0; k < kServos; ++k) {
    const ServoEnd s = twin.servo(k);
    EXPECT_FALSE(s.servo_on) << "servo " << k + 1;
    EXPECT_EQ(s.phase, Phase::p1) << "servo " << k + 1 << ": disconnected";
    EXPECT_EQ(s.comm_alarms, 0u) << "servo " << k + 1;
  }
}

// A servo lost while the servos run (its station off the line): the master stops them all,
// and its --stats, where a master on its own clock reports its end, say why and which axis
// (the state said "stopped" and the reason nothing: found by a walkthrough of the docs).
TEST_F(M3Program, ALostAxisStopsTheServosAndTheStatsSayWhichAndWhy) {
  const std::string clock = "unix:" + (dir_ / "clock").string();
  LockstepTwin twin("mem:m3_program_lost", clock, 50, 400, 1);
  ProgramOptions o;
  o.iface = "mem:m3_program_lost";
  o.config = config("cycle: 0.001\n");
  o.clock = "sim";
  o.sim_clock = clock;
  o.stats = (dir_ / "stats.json").string();
  run_m3_program(o);
  twin.join();
  ASSERT_GE(twin.signalled_tick, 0) << "the servos never all ran";
  std::ifstream f(o.stats);
  ASSERT_TRUE(f) << "no stats file";
  const nlohmann::json s = nlohmann::json::parse(f);
  EXPECT_EQ(s.at("state"), "stopped") << s.dump(2);
  EXPECT_EQ(s.at("lost_axis"), 2) << s.dump(2);
  const std::string why = s.at("stop_reason").get<std::string>();
  EXPECT_EQ(why.rfind("feedback_missing: axis 2 lost (", 0), 0u) << why;
  EXPECT_NE(why.find("cycles without a response"), std::string::npos) << why;
}

}  // namespace
}  // namespace omnitwin::m3
