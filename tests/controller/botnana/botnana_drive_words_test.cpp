// Tests controller/botnana/botnana_drive_words: every drive word of seed 004 against real
// CiA 402 drive cores (drive::Cia402Drive) behind DriveHarness (drive_harness.hpp), which
// plays the master's part each cycle. Seed 004's PP-TEST program, run verbatim as the seed
// writes it (Chinese comments included) as a background task: the axis switches to PP,
// leaves a fault, is enabled, moves to 1000 counts and the task ends only once target
// reached is seen. Also: the mode and goal constants; each store word lands in the object
// the seed names (SDO ones only after the request queue drains, PDO ones the next cycle);
// each fetch word returns the latched object; PDS goals switch the drive's state;
// reset-fault leaves Fault (and does nothing otherwise); the controlword bit words and `go`
// (cleared by the master on set-point acknowledge); digital inputs and their flags; the
// homing record; user PDOs (CSV through drive-wpdo1!); homing method 35 through the words;
// until-drive-on waits across cycles; errors name the word (absent axis, bad goal, underflow).
#include "controller/botnana/botnana_interpreter.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "tests/controller/botnana/drive_harness.hpp"

namespace omnitwin::botnana {
namespace {

using drive::State;
using testing::DriveHarness;

// Seed 004, "PP-TEST 範例", verbatim.
constexpr const char* kPpTest = R"(: pp-test
    pp 1 1 op-mode!          \ 切換到 PP Mode
    until-no-requests        \ 等待 op-mode! 命令實際設定到驅動器
    1 1 reset-fault          \ 解除驅動器異警
    1 1 until-no-fault       \ 等待解除驅動器異警完成
    1 1 drive-on             \ Drive On
    1 1 until-drive-on       \ 等待 Drive on 程序完成
    1000 1 1 target-p!       \ Set target position to 1000
    1 1 go                   \ New set-point
    1 1 until-target-reached \ 等待到達目標點
;

deploy pp-test ;deploy       \ 在 Background Task 執行 pp-test
)";

class BotnanaDrive : public ::testing::Test {
 protected:
  BotnanaDrive() : in(h, [this](std::string_view s) { out += s; }) {
    h.add_axis(1, 1);
    h.add_axis(1, 2);
    h.add_axis(2, 1);
    h.run(3);  // power-on: not ready → switch on disabled
  }
  // A master cycle: the tasks run, then the frame exchange and the drives' period.
  void cycle(int n = 1) {
    for (int k = 0; k < n; ++k) {
      in.step_tasks();
      h.cycle();
    }
  }
  void ok(std::string_view line) {
    const Status s = in.evaluate(line);
    ASSERT_TRUE(s.ok) << line << " -> " << s.to_string();
  }
  std::int64_t value(std::string_view line) {
    const Status s = in.evaluate(line);
    EXPECT_TRUE(s.ok) << line << " -> " << s.to_string();
    EXPECT_EQ(in.stack().size(), 1u) << line;
    const std::int64_t v = in.stack().empty() ? 0 : in.stack().back();
    in.evaluate("( clear ) nosuchword");  // errors empty the stack
    return v;
  }
  void evaluate_source(std::string_view src) {
    std::size_t begin = 0;
    while (begin < src.size()) {
      std::size_t end = src.find('\n', begin);
      if (end == std::string_view::npos) end = src.size();
      ok(src.substr(begin, end - begin));
      begin = end + 1;
    }
  }
  // Runs cycles until no SDO request is left (at most `limit`).
  void drain(int limit = 200) {
    for (int k = 0; k < limit && (h.requests_pending(1) || h.requests_pending(2)); ++k) cycle();
    cycle();
  }
  void enable(int slave = 1, int ch = 1) {
    ok(fmt::format("{} {} drive-on", ch, slave));
    for (int k = 0; k < 50 && h.drive(slave, ch).state() != State::operation_enabled; ++k) cycle();
    ASSERT_EQ(h.drive(slave, ch).state(), State::operation_enabled);
  }

  DriveHarness h;
  std::string out;
  Interpreter in;
};

TEST_F(BotnanaDrive, PpTestFromTheSeedReachesTheTarget) {
  evaluate_source(kPpTest);
  ASSERT_EQ(in.tasks_running(), 1u);
  const drive::Objects& o = h.drive(1, 1).objects();
  int cycles = 0;
  bool moved = false, reached_seen = false;
  std::int32_t max_pos = 0;
  while (in.tasks_running() > 0 && cycles < 5000) {
    cycle();
    ++cycles;
    if (o.position_actual > 0) moved = true;
    max_pos = std::max(max_pos, o.position_actual);
    if (moved && (o.statusword & drive::sw::target_reached) != 0) reached_seen = true;
  }
  ASSERT_EQ(in.tasks_running(), 0u) << "PP-TEST did not finish in 5000 cycles";
  EXPECT_TRUE(in.last_task_error().ok) << in.last_task_error().to_string();
  EXPECT_GT(cycles, 10);  // it really waited: SDO latency, enable, motion
  EXPECT_TRUE(moved);
  EXPECT_TRUE(reached_seen);
  EXPECT_EQ(h.drive(1, 1).state(), State::operation_enabled);
  EXPECT_EQ(h.drive(1, 1).mode(), drive::Mode::pp);
  EXPECT_EQ(o.mode_display, 1);
  EXPECT_EQ(o.target_position, 1000);
  EXPECT_LE(std::abs(o.position_actual - 1000), static_cast<int>(o.position_window));
  EXPECT_NE(o.statusword & drive::sw::target_reached, 0);
  EXPECT_LT(max_pos, 1100);  // a profile move, not an overshoot
  // `go` was taken back by the master after the acknowledge.
  EXPECT_EQ(h.user_controlword(1, 1) & drive::cw::new_set_point, 0);
  // The other axes were not touched.
  EXPECT_EQ(h.drive(1, 2).state(), State::switch_on_disabled);
  EXPECT_EQ(h.drive(2, 1).objects().position_actual, 0);
}

TEST_F(BotnanaDrive, PpTestLeavesAFaultFirst) {
  h.drive(1, 1).raise_fault();
  h.run(5);
  ASSERT_EQ(h.drive(1, 1).state(), State::fault);
  EXPECT_EQ(value("1 1 drive-fault?"), -1);
  evaluate_source(kPpTest);
  for (int k = 0; k < 5000 && in.tasks_running() > 0; ++k) cycle();
  ASSERT_EQ(in.tasks_running(), 0u);
  EXPECT_TRUE(in.last_task_error().ok) << in.last_task_error().to_string();
  EXPECT_EQ(h.drive(1, 1).state(), State::operation_enabled);
  EXPECT_LE(std::abs(h.drive(1, 1).objects().position_actual - 1000), 10);
  EXPECT_EQ(value("1 1 drive-fault?"), 0);
}

TEST_F(BotnanaDrive, ModeAndGoalConstants) {
  ok("pp . pv . tq . hm . csp . csv . cst .");
  ok("switch-on-disabled . ready-to-switch-on . switched-on . operation-enabled . quick-stop-active .");
  EXPECT_EQ(out, "1 3 4 6 8 9 10 1 2 3 4 5 ");
}

TEST_F(BotnanaDrive, OpModeIsAnSdoRequest) {
  ok("csv 1 1 op-mode!");
  EXPECT_TRUE(h.requests_pending(1));
  EXPECT_FALSE(h.requests_pending(2));
  cycle();
  EXPECT_EQ(h.drive(1, 1).objects().mode, 0);  // not before the download completes
  drain();
  EXPECT_EQ(h.drive(1, 1).objects().mode, 9);
  EXPECT_EQ(h.drive(1, 1).objects().mode_display, 9);
  EXPECT_EQ(value("1 1 drive-sw@") & 0x6F, 0x40);  // still switch on disabled
}

struct StoreCase {
  const char* word;
  std::int64_t value;
  std::uint16_t index;
  std::uint8_t sub;
};

TEST_F(BotnanaDrive, StoreWordsReachTheirObjects) {
  const StoreCase cases[] = {
      {"target-p!", 4321, 0x607A, 0},          {"target-v!", -1234, 0x60FF, 0},
      {"v-ofs!", 77, 0x60B1, 0},               {"drive-douts!", 0x5, 0x60FE, 1},
      {"drive-douts-mask!", 0x7, 0x60FE, 2},   {"drive-nsl!", -50000, 0x607D, 1},
      {"drive-psl!", 60000, 0x607D, 2},        {"drive-polarity!", 0x80, 0x607E, 0},
      {"drive-vmax!", 150000, 0x6080, 0},      {"profile-a1!", 500000, 0x6083, 0},
      {"profile-a2!", 400000, 0x6084, 0},      {"profile-v!", 30000, 0x6081, 0},
      {"tq-slope!", 2000, 0x6087, 0},          {"homing-method!", 19, 0x6098, 0},
      {"homing-v1!", 11000, 0x6099, 1},        {"homing-v2!", 1100, 0x6099, 2},
      {"homing-a!", 90000, 0x609A, 0},         {"drive-wpdo1!", 2500, 0x60FF, 0},
      {"drive-wpdo2!", 150, 0x6071, 0},        {"drive-cw!", 0x0006, 0x6040, 0},
  };
  for (const StoreCase& c : cases) {
    ok(fmt::format("{} 2 1 {}", c.value, c.word));  // slave 1, channel 2
    drain();
    const auto v = DriveHarness::get_object(h.drive(1, 2).objects(), c.index, c.sub);
    ASSERT_TRUE(v) << c.word;
    EXPECT_EQ(*v, c.value) << c.word;
    // nothing leaked to channel 1
    const auto other = DriveHarness::get_object(h.drive(1, 1).objects(), c.index, c.sub);
    EXPECT_NE(*other, c.value) << c.word;
  }
  // drive-cw! 6 (shutdown) with no goal set: the drive followed the raw controlword.
  cycle(2);
  EXPECT_EQ(h.drive(1, 2).state(), State::ready_to_switch_on);
}

// Seed 004: drive-cw! sets the controlword directly. Found in review: after drive-on the goal
// kept bits 0-3 and 7, so 6 drive-cw! (shutdown) was silently ignored. It ends the goal.
TEST_F(BotnanaDrive, DriveCwAfterAGoalWordSetsTheStateBitsToo) {
  enable();
  ASSERT_EQ(h.drive(1, 1).state(), State::operation_enabled);
  ok("6 1 1 drive-cw!");
  EXPECT_FALSE(h.goal(1, 1).has_value());
  cycle(2);
  EXPECT_EQ(h.drive(1, 1).state(), State::ready_to_switch_on);
  enable();  // a goal word takes the controlword back
  EXPECT_EQ(h.drive(1, 1).state(), State::operation_enabled);
}

TEST_F(BotnanaDrive, PdoOutputsNeedNoRequest) {
  ok("4321 1 1 target-p!");
  EXPECT_FALSE(h.requests_pending(1));
  EXPECT_EQ(value("1 1 target-p@"), 4321);
  cycle();
  EXPECT_EQ(h.drive(1, 1).objects().target_position, 4321);
}

TEST_F(BotnanaDrive, FetchWordsReadTheLatchedObjects) {
  ok("pv 1 1 op-mode! 20000 1 1 target-v! 150 1 1 v-ofs!");
  drain();
  enable();
  cycle(300);
  const drive::Objects& o = h.find(1, 1)->inputs;
  ASSERT_GT(o.position_actual, 0);  // it moves
  ASSERT_GT(o.velocity_actual, 10000);
  const struct {
    const char* word;
    std::int64_t expected;
  } cases[] = {
      {"real-p@", o.position_actual},    {"real-v@", o.velocity_actual}, {"real-tq@", o.torque_actual},
      {"demand-p@", o.position_demand},  {"demand-v@", o.velocity_demand}, {"drive-sw@", o.statusword},
      {"v-ofs@", 150},                   {"drive-dins@", o.digital_inputs}, {"drive-nsl@", o.sw_limit_min},
      {"drive-psl@", o.sw_limit_max},    {"drive-rpdo1@", o.following_error_actual},
      {"drive-rpdo2@", o.torque_demand}, {"drive-wpdo1@", 20000},          {"target-p@", o.target_position},
  };
  for (const auto& c : cases) EXPECT_EQ(value(fmt::format("1 1 {}", c.word)), c.expected) << c.word;
  EXPECT_NE(value("1 1 demand-v@"), 0);
}

TEST_F(BotnanaDrive, PdsGoalsSwitchTheDrive) {
  EXPECT_EQ(value("1 1 drive-on?"), 0);
  enable();
  EXPECT_EQ(value("1 1 drive-on?"), -1);
  EXPECT_EQ(h.goal(1, 1), PdsGoal::operation_enabled);
  ok("3 1 1 pds-goal!");
  cycle(3);
  EXPECT_EQ(h.drive(1, 1).state(), State::switched_on);
  EXPECT_EQ(value("1 1 drive-on?"), 0);
  ok("2 1 1 pds-goal!");
  cycle(3);
  EXPECT_EQ(h.drive(1, 1).state(), State::ready_to_switch_on);
  enable();
  ok("1 1 drive-stop");
  EXPECT_EQ(h.goal(1, 1), PdsGoal::quick_stop_active);
  bool quick_stop_seen = false;
  for (int k = 0; k < 50; ++k) {
    cycle();
    if (h.drive(1, 1).state() == State::quick_stop_active) quick_stop_seen = true;
  }
  EXPECT_TRUE(quick_stop_seen);
  ok("1 1 drive-off");
  cycle(3);
  EXPECT_EQ(h.drive(1, 1).state(), State::switch_on_disabled);
  EXPECT_EQ(h.goal(1, 1), PdsGoal::switch_on_disabled);
}

TEST_F(BotnanaDrive, ResetFault) {
  enable();
  ok("1 1 reset-fault");  // not in fault: nothing changes
  cycle(3);
  EXPECT_EQ(h.drive(1, 1).state(), State::operation_enabled);
  h.drive(1, 1).raise_fault();
  cycle(20);
  ASSERT_EQ(h.drive(1, 1).state(), State::fault);
  EXPECT_EQ(value("1 1 drive-fault?"), -1);
  ok("1 1 reset-fault");
  cycle(5);
  EXPECT_EQ(h.drive(1, 1).state(), State::switch_on_disabled);
  EXPECT_EQ(value("1 1 drive-fault?"), 0);
}

TEST_F(BotnanaDrive, ControlwordBitWords) {
  enable();
  ok("1 1 +pp-imt 1 1 +pp-rel 1 1 +pp-cosp 1 1 +drive-halt");
  cycle();
  EXPECT_EQ(h.drive(1, 1).objects().controlword, 0x0020 | 0x0040 | 0x0200 | 0x0100 | 0x000F);
  ok("1 1 -pp-imt 1 1 -drive-halt");
  cycle();
  EXPECT_EQ(h.drive(1, 1).objects().controlword, 0x0040 | 0x0200 | 0x000F);
  ok("1 1 -pp-rel 1 1 -pp-cosp");
  cycle();
  EXPECT_EQ(h.drive(1, 1).objects().controlword, 0x000F);
  EXPECT_EQ(h.drive(1, 1).state(), State::operation_enabled);  // the goal bits stayed the master's
}

TEST_F(BotnanaDrive, GoIsTakenBackOnAcknowledge) {
  ok("pp 1 1 op-mode!");
  drain();
  enable();
  ok("500 1 1 target-p! 1 1 go");
  EXPECT_NE(h.user_controlword(1, 1) & 0x10, 0);
  cycle();
  EXPECT_NE(h.drive(1, 1).objects().controlword & 0x10, 0);  // new set-point went out
  cycle(3);
  EXPECT_EQ(h.user_controlword(1, 1) & 0x10, 0);  // acknowledged and taken back
  cycle(300);
  EXPECT_LE(std::abs(h.drive(1, 1).objects().position_actual - 500), 10);
  EXPECT_EQ(value("1 1 target-reached?"), -1);
}

TEST_F(BotnanaDrive, HaltStopsAProfileVelocityMove) {
  ok("pv 1 1 op-mode! 30000 1 1 target-v!");
  drain();
  enable();
  cycle(200);
  ASSERT_GT(value("1 1 real-v@"), 20000);
  ok("1 1 +drive-halt");
  cycle(300);
  EXPECT_EQ(value("1 1 real-v@"), 0);
  ok("1 1 -drive-halt");
  cycle(300);
  EXPECT_GT(value("1 1 real-v@"), 20000);
}

TEST_F(BotnanaDrive, DigitalInputs) {
  h.drive(1, 1).set_external_inputs(0b101);
  cycle();
  EXPECT_EQ(value("1 1 drive-dins@") & 0x7, 0b101);
  EXPECT_EQ(value("1 1 drive-nl?"), -1);
  EXPECT_EQ(value("1 1 drive-pl?"), 0);
  EXPECT_EQ(value("1 1 drive-org?"), -1);
  h.drive(1, 1).set_external_inputs(0b010);
  cycle();
  EXPECT_EQ(value("1 1 drive-nl?"), 0);
  EXPECT_EQ(value("1 1 drive-pl?"), -1);
  EXPECT_EQ(value("1 1 drive-org?"), 0);
}

TEST_F(BotnanaDrive, HomedRecord) {
  EXPECT_EQ(value("1 1 drive-homed?"), 0);
  ok("1 1 +drive-homed");
  EXPECT_EQ(value("1 1 drive-homed?"), -1);
  EXPECT_EQ(value("2 1 drive-homed?"), 0);  // per axis
  EXPECT_TRUE(in.homed(1, 1));
  ok("1 1 -drive-homed");
  EXPECT_EQ(value("1 1 drive-homed?"), 0);
}

TEST_F(BotnanaDrive, CsvThroughUserPdo) {
  ok("csv 1 1 op-mode!");
  drain();
  enable();
  ok("20000 1 1 drive-wpdo1!");
  EXPECT_FALSE(h.requests_pending(1));  // a process-image output
  cycle(200);
  EXPECT_NEAR(static_cast<double>(value("1 1 real-v@")), 20000.0, 200.0);
}

TEST_F(BotnanaDrive, HomingMethod35ThroughTheWords) {
  ok(": home-test 35 1 1 homing-method! hm 1 1 op-mode! until-no-requests");
  ok("  1 1 reset-fault 1 1 until-no-fault 1 1 drive-on 1 1 until-drive-on");
  ok("  1 1 go 1 1 until-target-reached 1 1 +drive-homed ;");
  ok("deploy home-test ;deploy");
  for (int k = 0; k < 3000 && in.tasks_running() > 0; ++k) cycle();
  ASSERT_EQ(in.tasks_running(), 0u);
  EXPECT_TRUE(in.last_task_error().ok) << in.last_task_error().to_string();
  EXPECT_TRUE(h.drive(1, 1).homed());
  EXPECT_EQ(value("1 1 drive-homed?"), -1);
}

TEST_F(BotnanaDrive, UntilDriveOnWaitsAcrossCycles) {
  ok("variable on-at variable cycles");
  ok(": count begin 1 cycles +! pause again ;");
  ok("deploy count ;deploy");
  ok("deploy 1 1 drive-on 1 1 until-drive-on cycles @ on-at ! ;deploy");
  int k = 0;
  for (; k < 100 && in.tasks_running() > 1; ++k) cycle();
  ASSERT_EQ(in.tasks_running(), 1u);  // the waiter ended, the counter goes on
  EXPECT_EQ(h.drive(1, 1).state(), State::operation_enabled);
  const std::int64_t on_at = value("on-at @");
  EXPECT_GE(on_at, 2);  // it waited for the drive over several cycles
  EXPECT_LE(on_at, 10);
  in.kill_tasks();
}

TEST_F(BotnanaDrive, UntilTargetReachedWaitsForTheMove) {
  ok("pp 1 1 op-mode!");
  drain();
  enable();
  ok("variable done");
  ok("deploy 20000 1 1 target-p! 1 1 go 1 1 until-target-reached -1 done ! ;deploy");
  int k = 0;
  for (; k < 5000 && in.tasks_running() > 0; ++k) cycle();
  ASSERT_EQ(in.tasks_running(), 0u);
  EXPECT_GT(k, 100);  // a 20000-count profile move takes well over 100 ms
  EXPECT_LE(std::abs(h.drive(1, 1).objects().position_actual - 20000), 10);
  EXPECT_EQ(value("done @"), -1);
}

TEST_F(BotnanaDrive, ErrorsNameTheWord) {
  Status s = in.evaluate("1 3 drive-on");
  EXPECT_FALSE(s.ok);
  EXPECT_EQ(s.word, "drive-on");
  EXPECT_EQ(s.position, 4u);
  EXPECT_EQ(s.message, "no drive at slave 3 channel 1");
  s = in.evaluate("0 1 real-p@");
  EXPECT_EQ(s.word, "real-p@");
  EXPECT_NE(s.message.find("count from 1"), std::string::npos);
  s = in.evaluate("9 1 1 pds-goal!");
  EXPECT_EQ(s.word, "pds-goal!");
  EXPECT_EQ(s.message, "PDS goal 9 is not one of 1..5");
  s = in.evaluate("1 target-p!");
  EXPECT_EQ(s.word, "target-p!");
  EXPECT_EQ(s.message, "stack underflow");
  // A failing drive word in a task ends that task with the error.
  ok("deploy pause 1 7 go ;deploy");
  cycle(2);
  EXPECT_EQ(in.tasks_running(), 0u);
  EXPECT_EQ(in.last_task_error().word, "go");
  EXPECT_EQ(in.last_task_error().message.rfind("no drive at slave 7 channel 1", 0), 0u);
  // still usable
  EXPECT_EQ(value("1 1 drive-homed?"), 0);
}

}  // namespace
}  // namespace omnitwin::botnana
