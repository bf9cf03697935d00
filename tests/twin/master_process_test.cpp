// Tests twin/master_process: log_tail(), the last words of a master's log that the twin puts
// in its error when the master exits before joining the clock.
#include "twin/master_process.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <string>

#include "tests/support/temp_dir.hpp"

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

}  // namespace
}  // namespace omnitwin::twin
