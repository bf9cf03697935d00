// Tests the `--bus ethercat` program path (run_ethercat_program) in process on the wall clock:
// four of B's CiA 402 drives in an EscChain behind the in-process transport (mem:NAME), served
// by a thread as the twin would serve them, and the program's exit code, --stats file and the
// slaves' states after it returned. The end of --duration takes the drives out of operation
// and the slaves to INIT; a wheel's drive lost mid-path stops the platform naming its slave; a
// bus where no slave answers fails after startup_timeout, and a run ending before OP is exit 3;
// a segment that lost a slave after OP reads "degraded", not "starting". In lockstep (a
// sim-clock server in a thread stands in for the twin), SIGINT does the same end as --duration.
#include <gtest/gtest.h>
#include <pthread.h>
#include <signal.h>

#include <nlohmann/json.hpp>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>

#include "bus_emulators/ethercat/transport/ec_transport.hpp"
#include "controller/ethercat/ec_program.hpp"
#include "controller/sim_clock.hpp"
#include "tests/controller/ethercat/ec_bench.hpp"

namespace omnitwin::controller::ethercat {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// Four of B's CiA 402 drives in one chain, each with its axis model: the slaves of both
// stand-ins for the twin below.
struct FourDrives {
  FourDrives() {
    for (int i = 0; i < 4; ++i) {
      omnitwin::ethercat::DriveSlaveConfig sc;
      sc.serial = static_cast<std::uint32_t>(100 + i);
      slaves.push_back(std::make_unique<omnitwin::ethercat::DriveSlave>(devices[0], sc));
      models.emplace_back();
    }
    for (auto& s : slaves) chain.add(&s->esc());
  }
  // Steps each powered drive's firmware and its axis model one period of `dt_ns` at `t` [ns].
  void firmware(std::int64_t t, std::int64_t dt_ns) {
    for (std::size_t i = 0; i < slaves.size(); ++i) {
      if (!chain.powered(static_cast<int>(i))) continue;
      const auto cmd = slaves[i]->axis(0).step(t, models[i].feedback());
      models[i].step(cmd, static_cast<double>(dt_ns) * 1e-9);
      slaves[i]->cycle(t);
    }
  }
  omnitwin::ethercat::AlState al_state(int i) const { return slaves[static_cast<std::size_t>(i)]->esc().al_state(); }
  omnitwin::drive::State drive_state(int i) const { return slaves[static_cast<std::size_t>(i)]->axis(0).state(); }

  std::vector<omnitwin::ethercat::DeviceDescription> devices = ecbench::drive_esi();
  std::vector<std::unique_ptr<omnitwin::ethercat::DriveSlave>> slaves;
  std::vector<omnitwin::drive::AxisModel> models;
  omnitwin::ethercat::EscChain chain;
};

// The slaves' side of `mem:NAME`: four drives, their firmware stepped every millisecond of wall
// time, each frame through the chain and back. Slave `power_off` (0-based, -1 = none) loses
// power `power_off_at` [s] after every slave first reached OP (counted from OP, not from the
// start, so a start-up slowed by a loaded machine cannot move the loss before OP), and gets it
// back `power_back_after` [s] later (0: never).
class Segment {
 public:
  Segment(const std::string& iface, int power_off = -1, double power_off_at = 0, double power_back_after = 0)
      : tr_(omnitwin::ethercat::open_transport(iface, omnitwin::ethercat::Role::slaves)),
        power_off_(power_off),
        power_off_at_ns_(static_cast<std::int64_t>(power_off_at * 1e9)),
        power_back_after_ns_(static_cast<std::int64_t>(power_back_after * 1e9)) {
    thread_ = std::thread([this] { serve(); });
  }
  ~Segment() { stop(); }
  void stop() {
    run_ = false;
    if (thread_.joinable()) thread_.join();
  }
  omnitwin::ethercat::AlState al_state(int i) const { return drives_.al_state(i); }
  omnitwin::drive::State drive_state(int i) const { return drives_.drive_state(i); }
  // When every slave was first in OP [s since the start]; negative: never. Read after stop().
  double op_at() const { return static_cast<double>(op_at_) * 1e-9; }
  bool power_lost() const { return off_at_ >= 0; }

 private:
  void serve() {
    sigset_t set;  // the program reads SIGINT/SIGTERM from its descriptor; this thread never takes them
    sigemptyset(&set);
    sigaddset(&set, SIGINT);
    sigaddset(&set, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &set, nullptr);
    const std::int64_t start = now_ns();
    std::int64_t next = 0;
    std::vector<std::uint8_t> buf(2048);
    while (run_) {
      const int n = tr_->receive(buf, 2ms);
      const std::int64_t t = now_ns() - start;
      for (; next <= t; next += kCycle) firmware(next);
      if (op_at_ < 0 && all_in_op()) op_at_ = t;
      if (power_off_ >= 0 && op_at_ >= 0 && off_at_ < 0 && t >= op_at_ + power_off_at_ns_) {
        chain_.set_powered(power_off_, false, t);
        off_at_ = t;
      }
      if (power_back_after_ns_ > 0 && off_at_ >= 0 && t >= off_at_ + power_back_after_ns_ && !chain_.powered(power_off_))
        chain_.set_powered(power_off_, true, t);
      if (n <= 0) continue;
      chain_.advance(t);
      std::span<std::uint8_t> pdu(buf.data(), static_cast<std::size_t>(n));
      if (chain_.process(pdu, t)) tr_->send(pdu);
    }
  }
  bool all_in_op() const {
    for (int i = 0; i < 4; ++i)
      if (drives_.al_state(i) != omnitwin::ethercat::AlState::op) return false;
    return true;
  }
  void firmware(std::int64_t t) { drives_.firmware(t, kCycle); }

  static constexpr std::int64_t kCycle = 1'000'000;
  std::unique_ptr<omnitwin::ethercat::EcTransport> tr_;
  FourDrives drives_;
  omnitwin::ethercat::EscChain& chain_ = drives_.chain;
  int power_off_;
  std::int64_t power_off_at_ns_;
  std::int64_t power_back_after_ns_;  // 0: the power stays off
  std::int64_t op_at_ = -1;   // when every slave was first in OP [ns since the start], -1 = not yet
  std::int64_t off_at_ = -1;  // when the power went off, -1 = not yet
  std::atomic<bool> run_{true};
  std::thread thread_;
};

// The twin's side in lockstep: the four drives of Segment, stepped in simulated time, behind a
// sim-clock server. Each tick the master's frames of the last tick go through the chain, then
// the grant counts the replies and the master's frames are taken as its Done counts them. Once
// the master reports its platform loop running for `signal_after` ticks, SIGINT goes to the
// process (the program reads it from its signalfd; every thread blocks it); the twin grants on
// until the master closes the channel or `max_ticks`.
class LockstepSegment {
 public:
  LockstepSegment(const std::string& iface, const std::string& clock, int signal_after, int max_ticks)
      : tr_(omnitwin::ethercat::open_transport(iface, omnitwin::ethercat::Role::slaves)),
        server_(clock),
        signal_after_(signal_after),
        max_ticks_(max_ticks) {
    thread_ = std::thread([this] { serve(); });
  }
  ~LockstepSegment() { join(); }
  void join() {
    if (thread_.joinable()) thread_.join();
  }
  omnitwin::ethercat::AlState al_state(int i) const { return drives_.al_state(i); }
  omnitwin::drive::State drive_state(int i) const { return drives_.drive_state(i); }
  std::int64_t signalled_tick = -1;  // the tick after whose Done SIGINT was sent (-1: never)
  std::int64_t last_tick = -1;       // the last tick the master answered
  bool closed = false;               // the master closed the channel (else max_ticks ended it)

 private:
  void serve() {
    sigset_t set;
    sigemptyset(&set);
    sigaddset(&set, SIGINT);
    sigaddset(&set, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &set, nullptr);
    if (server_.accept(10s) != simclock::WaitStatus::ok) return;
    std::vector<std::vector<std::uint8_t>> held;
    std::vector<std::uint8_t> buf(2048);
    std::uint64_t sent = 0, taken = 0;
    std::int64_t next = 0, running = 0;
    for (std::int64_t k = 0; k < max_ticks_; ++k) {
      const std::int64_t t = k * kCycle;
      for (; next <= t; next += kStep) firmware(next);
      chain_.advance(t);
      for (auto& f : held) {
        if (chain_.process(std::span<std::uint8_t>(f), t) && tr_->send(f)) ++sent;
      }
      held.clear();
      simclock::Grant g;
      g.tick = static_cast<std::uint64_t>(k);
      g.t_ns = t;
      g.frames[0] = sent;
      simclock::Done d;
      if (server_.grant(g, d, 10s) != simclock::WaitStatus::ok) {
        closed = true;
        return;
      }
      last_tick = k;
      for (const auto give_up = std::chrono::steady_clock::now() + 5s;
           taken < d.frames[0] && std::chrono::steady_clock::now() < give_up;) {
        const int n = tr_->receive(buf, 10ms);
        if (n > 0) held.emplace_back(buf.begin(), buf.begin() + n), ++taken;
      }
      running = d.report.state == simclock::MasterState::running ? running + 1 : 0;
      if (signalled_tick < 0 && running >= signal_after_) {
        signalled_tick = k;
        ::kill(::getpid(), SIGINT);
      }
    }
    server_.end(max_ticks_ * kCycle);
  }
  void firmware(std::int64_t t) { drives_.firmware(t, kStep); }

  static constexpr std::int64_t kCycle = 2'000'000, kStep = 1'000'000;
  std::unique_ptr<omnitwin::ethercat::EcTransport> tr_;
  simclock::Server server_;
  FourDrives drives_;
  omnitwin::ethercat::EscChain& chain_ = drives_.chain;
  int signal_after_, max_ticks_;
  std::thread thread_;
};

// Both configurations give the segment watch 300 ms instead of 10 cycles (20 ms): these tests run
// on the wall clock, and this machine's host can stall the whole guest for longer than 20 ms
// (docs/reliability.md, sixteenth round), which once lost the segment in the power-blip test
// below. The watch itself is tested in ec_master_test on simulated time.
constexpr const char* kWheels = R"(cycle: 0.002
expected_slaves: 4
segment_loss_ms: 300
startup:
  - {slave: all, index: 0x6060, size: 1, value: 9}
wheels: [{slave: 1}, {slave: 2}, {slave: 3}, {slave: 4}]
wheel_mode: csv
wheel_counts_per_rev: 10000
platform:
  period: 0.010
  kp: [6, 6, 6]
  ki: [6, 6, 6]
  max_speed: 0.5
  max_yaw_rate: 2.0
  geometry: {L: 0.25, r: 0.05, counts_per_rev: 10000}
  settle: 1.0
  path:
    start: {x: 0, y: 0, phi_deg: 0}
    segments:
      - line: {dx: 0.5, dy: 0, duration: 5}
)";

constexpr const char* kDrivesOnly = "cycle: 0.002\nexpected_slaves: 4\nsegment_loss_ms: 300\n";

class EcProgram : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("ec_program_test_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override {
    auto& sinks = spdlog::default_logger()->sinks();
    sinks.erase(std::remove(sinks.begin(), sinks.end(), log_sink_), sinks.end());
    fs::remove_all(dir_);
  }
  // A configuration file: the drives' ESI, then `body`.
  std::string config(const std::string& body) {
    const fs::path p = dir_ / "ec.yaml";
    std::ofstream(p) << "esi: [" OMNITWIN_SOURCE_DIR "/models/ethercat/omnitwin_drive.xml]\n" << body;
    return p.string();
  }
  int run(const std::string& iface, const std::string& cfg, double duration) {
    ProgramOptions o;
    o.iface = iface;
    o.config = cfg;
    o.duration = duration;
    o.stats = (dir_ / "stats.json").string();
    capture_log();
    return run_ethercat_program(o);
  }
  // The program's log lines from now on land in log().
  void capture_log() {
    log_.str("");
    auto& sinks = spdlog::default_logger()->sinks();
    if (std::find(sinks.begin(), sinks.end(), log_sink_) == sinks.end()) sinks.push_back(log_sink_);
  }
  // Runs a --script with the drives-only configuration; its log lines land in log().
  int run_script(const std::string& iface, const std::string& script_text, double duration = 5.0) {
    const fs::path p = dir_ / "test.fs";
    std::ofstream(p) << script_text;
    script_ = p.string();
    ProgramOptions o;
    o.iface = iface;
    o.config = config(kDrivesOnly);
    o.duration = duration;
    o.script = script_;
    capture_log();
    return run_ethercat_program(o);
  }
  std::string log() const { return log_.str(); }
  nlohmann::json stats() {
    std::ifstream in(dir_ / "stats.json");
    std::stringstream ss;
    ss << in.rdbuf();
    return nlohmann::json::parse(ss.str());
  }
  fs::path dir_;
  std::string script_;  // the last run_script's file
  std::ostringstream log_;
  std::shared_ptr<spdlog::sinks::ostream_sink_mt> log_sink_ = std::make_shared<spdlog::sinks::ostream_sink_mt>(log_);
};

TEST_F(EcProgram, TheEndOfTheDurationTakesTheDrivesOutOfOperationAndTheSlavesToInit) {
  Segment seg("mem:ec_program_end");
  EXPECT_EQ(run("mem:ec_program_end", config(kWheels), 1.5), 0);
  seg.stop();
  const nlohmann::json s = stats();
  EXPECT_EQ(s.at("state"), "running") << s.dump(2);
  for (int i = 0; i < 4; ++i) {
    EXPECT_EQ(seg.al_state(i), omnitwin::ethercat::AlState::init) << "slave " << i + 1;
    EXPECT_NE(seg.drive_state(i), omnitwin::drive::State::operation_enabled) << "slave " << i + 1;
  }
}

// SIGINT to a lockstep master mid-path (what `kill -INT` of omni-master does while the twin
// still grants ticks): it stops its drives and takes the slaves to INIT in the ticks it is
// granted, as at the end of a wall-clock run, then ends with exit 0 and closes the channel.
// It used to return at the signal, leaving every drive enabled and every slave in OP.
TEST_F(EcProgram, SigintInLockstepStopsTheDrivesAndTakesTheSlavesToInitBeforeItEnds) {
  const std::string clock = "unix:@ec_program_test_sigint_" + std::to_string(::getpid());
  LockstepSegment seg("mem:ec_program_sigint", clock, 50, 5000);
  ProgramOptions o;
  o.iface = "mem:ec_program_sigint";
  o.config = config(kWheels);
  o.clock = "sim";
  o.sim_clock = clock;
  o.stats = (dir_ / "stats.json").string();
  EXPECT_EQ(run_ethercat_program(o), 0);
  seg.join();
  ASSERT_GE(seg.signalled_tick, 0) << "the platform loop never ran";
  EXPECT_TRUE(seg.closed) << "the master did not end after SIGINT";
  // Within kShutdownNs (100 ms, 50 ticks of 2 ms) of simulated time, and not at once.
  EXPECT_GT(seg.last_tick, seg.signalled_tick + 2);
  EXPECT_LE(seg.last_tick, seg.signalled_tick + 52);
  for (int i = 0; i < 4; ++i) {
    EXPECT_EQ(seg.al_state(i), omnitwin::ethercat::AlState::init) << "slave " << i + 1;
    EXPECT_NE(seg.drive_state(i), omnitwin::drive::State::operation_enabled) << "slave " << i + 1;
  }
}

TEST_F(EcProgram, AWheelDriveLostMidPathStopsThePlatformNamingItsSlave) {
  Segment seg("mem:ec_program_lost", 3, 0.5);
  EXPECT_EQ(run("mem:ec_program_lost", config(std::string(kWheels) + "wheel_loss_timeout: 0.3\n"), 2.5), 0);
  seg.stop();
  const nlohmann::json s = stats();
  EXPECT_EQ(s.at("state"), "stopped") << s.dump(2);
  EXPECT_EQ(s.at("platform_stopped"), true);
  EXPECT_EQ(s.at("lost_slave"), 4);
  for (int i = 0; i < 3; ++i)
    EXPECT_NE(seg.drive_state(i), omnitwin::drive::State::operation_enabled) << "slave " << i + 1;
}

// A wheel's slave out of OP for less than wheel_loss_timeout does not stop the platform: a
// power blip the master recovers lets the loop pull the platform back (the regression scenario
// ethercat_power_loss; the first version of the stop broke it). On the wall clock: a timeout of
// 1.5 s leaves the recovery 1.1 s after the power returns (1 s, the default, left 0.6 s, which a
// loaded 2-core host sometimes missed), and the run lasts past OP + 0.3 + 1.5 s, so a stop
// would show.
TEST_F(EcProgram, AWheelDriveLostForLessThanTheTimeoutDoesNotStopThePlatform) {
  Segment seg("mem:ec_program_blip", 3, 0.3, 0.4);  // off from OP + 0.3 s for 0.4 s
  EXPECT_EQ(run("mem:ec_program_blip", config(std::string(kWheels) + "wheel_loss_timeout: 1.5\n"), 3.0), 0);
  seg.stop();
  ASSERT_TRUE(seg.power_lost()) << "OP at " << seg.op_at() << " s: the run ended first";
  const nlohmann::json s = stats();
  EXPECT_EQ(s.at("platform_stopped"), false) << s.dump(2);
  EXPECT_EQ(s.at("lost_slave"), 0);
}

TEST_F(EcProgram, NoSlaveAnsweringFailsAfterTheStartupTimeout) {
  const int code = run("mem:ec_program_nobody", config(std::string(kDrivesOnly) + "startup_timeout: 0.2\n"), 1.0);
  EXPECT_EQ(code, 3);
  const nlohmann::json s = stats();
  EXPECT_EQ(s.at("state"), "failed") << s.dump(2);
  EXPECT_NE(s.at("master_error").get<std::string>().find("no slave answered within 0.2 s"), std::string::npos) << s.dump(2);
}

TEST_F(EcProgram, ADurationEndingBeforeOpIsARuntimeFailure) {
  EXPECT_EQ(run("mem:ec_program_short", config(kDrivesOnly), 0.3), 3);
  EXPECT_EQ(stats().at("state"), "starting");
  // No slave was found: its shutdown says so, and nothing claims slaves taken to INIT (found by
  // a walkthrough of the docs: both lines came).
  EXPECT_NE(log().find("shutdown: no slaves"), std::string::npos) << log();
  EXPECT_EQ(log().find("slaves in INIT"), std::string::npos) << log();
}

TEST_F(EcProgram, ASlaveLostAfterOpMakesTheSegmentDegradedNotStarting) {
  Segment seg("mem:ec_program_degraded", 3, 0.3);
  EXPECT_EQ(run("mem:ec_program_degraded", config(kDrivesOnly), 1.5), 0);
  seg.stop();
  ASSERT_TRUE(seg.power_lost()) << "OP at " << seg.op_at() << " s: the run ended first";
  const nlohmann::json s = stats();
  EXPECT_EQ(s.at("state"), "degraded") << s.dump(2);
  EXPECT_EQ(s.at("slaves_lost"), 1);
}

TEST_F(EcProgram, AStartupSdoOrAWheelNamingASlaveBeyondTheCountFailsNamingTheEntry) {
  Segment seg("mem:ec_program_beyond");
  const std::string cfg = config("cycle: 0.002\nstartup:\n  - {slave: 5, index: 0x6060, size: 1, value: 9}\n");
  EXPECT_EQ(run("mem:ec_program_beyond", cfg, 1.0), 3);
  EXPECT_EQ(stats().at("master_error"), cfg + ":4: startup: start-up SDO 0x6060:0 names slave 5, but the bus has 4 slave(s)");
  std::string wheels = kWheels;
  wheels.replace(wheels.find("{slave: 4}"), 10, "{slave: 6}");
  EXPECT_EQ(run("mem:ec_program_beyond", config(wheels), 1.0), 3);
  EXPECT_EQ(stats().at("state"), "failed");
}

// Found in review: a definition or deploy body left open at the end of a --script file was
// dropped in silence (exit 0). It is bad input: exit 2, naming the file and where it began.
TEST_F(EcProgram, ADefinitionLeftOpenAtTheEndOfAScriptIsBadInputNamingTheFile) {
  Segment seg("mem:ec_program_open_def");
  EXPECT_EQ(run_script("mem:ec_program_open_def", ": move1\n    1 1 drive-on\n    1000 1 1 target-p!\n"), 2) << log();
  EXPECT_NE(log().find(script_ + ":1:1:"), std::string::npos) << log();
  EXPECT_NE(log().find("move1"), std::string::npos) << log();
  EXPECT_EQ(run_script("mem:ec_program_open_def", "deploy\n    1 1 drive-on\n    1 1 until-drive-on\n"), 2) << log();
  EXPECT_NE(log().find(script_ + ":1:1:"), std::string::npos) << log();
  EXPECT_NE(log().find(";deploy"), std::string::npos) << log();
}

// Found in review: an unknown word was exit 3 once the bus was in OP, naming neither the file
// nor the line. It is found when the script is loaded: exit 2, FILE:LINE:COLUMN and the word;
// words the script defines itself are known.
TEST_F(EcProgram, AnUnknownWordInAScriptIsBadInputNamingFileLineAndWord) {
  Segment seg("mem:ec_program_unknown");
  const std::string text = "\\ line 1 comment\n: t1 1 1 drive-on ;\nvariable v  1 1 t1 1 v !\n1 1 drvie-on\n";
  EXPECT_EQ(run_script("mem:ec_program_unknown", text), 2) << log();
  EXPECT_NE(log().find(script_ + ":4:5: `drvie-on`: unknown word"), std::string::npos) << log();
}

// A task's runtime error (here stack underflow) stays a runtime failure (exit 3) and names the
// word and where it stands in the file.
TEST_F(EcProgram, ARuntimeErrorInAScriptTaskNamesTheWordAndItsPlaceInTheFile) {
  Segment seg("mem:ec_program_task_error");
  EXPECT_EQ(run_script("mem:ec_program_task_error", "deploy\n    1 drop drop\n;deploy\n"), 3) << log();
  EXPECT_NE(log().find(script_ + ":2:12: `drop`: stack underflow"), std::string::npos) << log();
}

// Found in review: an SDO download the drive aborted (homing method 99) never reached the
// script, which ended with exit 0.
TEST_F(EcProgram, AnSdoAbortEndsTheScriptAsARuntimeFailure) {
  Segment seg("mem:ec_program_sdo_abort");
  EXPECT_EQ(run_script("mem:ec_program_sdo_abort", "deploy 99 1 1 homing-method! until-no-requests ;deploy\n"), 3)
      << log();
  EXPECT_NE(log().find("0x6098"), std::string::npos) << log();
  EXPECT_NE(log().find("0x06090030"), std::string::npos) << log();
}

// Seed 004: the software limits are read back from the drive at boot, so drive-nsl@ and
// drive-psl@ answer at their first use. Found in review: "not available", exit 3.
TEST_F(EcProgram, TheSoftwareLimitWordsAnswerAtTheirFirstUse) {
  Segment seg("mem:ec_program_limits");
  EXPECT_EQ(run_script("mem:ec_program_limits", "deploy 1 1 drive-nsl@ drop 1 2 drive-psl@ drop ;deploy\n"), 0)
      << log();
}

}  // namespace
}  // namespace omnitwin::controller::ethercat
