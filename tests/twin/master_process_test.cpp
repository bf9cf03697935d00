// Tests twin/master_process: log_tail(), the last words of a master's log that the twin puts
// in its error when the master exits before joining the clock; and the omnitwin-guard started
// beside each master (it ends on its own with the master, and is reaped with the object).
#include "twin/master_process.hpp"

#include <gtest/gtest.h>

#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <optional>
#include <string>
#include <thread>

#include "tests/support/temp_dir.hpp"
#include "twin/process_tree.hpp"

namespace omnitwin::twin {
namespace {

using omnitwin::testing::TempDir;

TEST(MasterLogTail, KeepsTheLastNonEmptyLinesInOrder) {
  const TempDir dir;
  const std::string log = (dir.path() / "master.log").string();
  std::ofstream(log) << "starting\r\n\nconfig loaded\nmaster.yaml:2: period: must be in [0.0001, 1]\n\n";
  EXPECT_EQ(log_tail(log, 2), "config loaded | master.yaml:2: period: must be in [0.0001, 1]");
  EXPECT_EQ(log_tail(log, 5), "starting | config loaded | master.yaml:2: period: must be in [0.0001, 1]");
}

TEST(MasterLogTail, AnEmptyOrMissingLogSaysNothing) {
  const TempDir dir;
  const std::string log = (dir.path() / "master.log").string();
  EXPECT_EQ(log_tail(log, 3), "");
  std::ofstream(log) << "\n\n";
  EXPECT_EQ(log_tail(log, 3), "");
}

TEST(MasterLogTail, ReadsOnlyTheEndOfALongLog) {
  const TempDir dir;
  const std::string log = (dir.path() / "master.log").string();
  {
    std::ofstream out(log);
    for (int i = 0; i < 100000; ++i) out << "tick " << i << "\n";
    out << "the last line\n";
  }
  EXPECT_EQ(log_tail(log, 2), "tick 99999 | the last line");
}

// The state /proc gives `pid` ('Z' zombie), 0 when it has no entry.
char state_of(pid_t pid) {
  const std::optional<ProcessEntry> p = process_entry(pid);
  return p ? p->state : 0;
}

// Waits up to `timeout` for `pid` to be a zombie or gone.
bool ends_within(pid_t pid, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (state_of(pid) != 0 && state_of(pid) != 'Z') {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return true;
}

TEST(MasterGuard, WatchesWhileTheMasterRunsEndsWithItAndIsReapedWithTheObject) {
  const TempDir dir;
  pid_t guard = -1;
  {
    MasterProcess m("sh", {"-c", "sleep 0.5"}, (dir.path() / "master.log").string());
    guard = m.guard_pid();
    ASSERT_GT(guard, 0) << "no omnitwin-guard was started";
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    EXPECT_NE(state_of(guard), 'Z') << "the guard ended while its master ran";
    EXPECT_NE(state_of(guard), 0);
    ASSERT_TRUE(m.wait(std::chrono::milliseconds(5000)));
    // The master reaped: the guard sees it gone and ends by itself (it polls every 50 ms).
    EXPECT_TRUE(ends_within(guard, std::chrono::milliseconds(1000)));
  }
  EXPECT_EQ(state_of(guard), 0) << "the guard was not reaped";
}

TEST(MasterGuard, AMasterStoppedByTheTwinTakesItsGuardAlong) {
  const TempDir dir;
  pid_t guard = -1;
  {
    MasterProcess m("sh", {"-c", "sleep 30; :"}, (dir.path() / "master.log").string());
    guard = m.guard_pid();
    ASSERT_GT(guard, 0);
    m.stop(std::chrono::milliseconds(2000));
    EXPECT_EQ(m.exit_code(), 128 + SIGTERM);
  }
  EXPECT_EQ(state_of(guard), 0);
}

}  // namespace
}  // namespace omnitwin::twin
