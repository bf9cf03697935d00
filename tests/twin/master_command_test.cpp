// Tests twin/master_command: a master command line splits into words as a shell would, and a
// program that cannot be started is named with the reason (not on PATH, no such file, not
// executable) while one that can gives none.
#include "twin/master_command.hpp"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "tests/support/temp_dir.hpp"

namespace omnitwin::twin {
namespace {

TEST(MasterCommand, SplitsAsAShellWould) {
  EXPECT_EQ(split_command("a b  'c d' \"e \\\"f\\\"\" g\\ h"),
            (std::vector<std::string>{"a", "b", "c d", "e \"f\"", "g h"}));
  EXPECT_THROW(split_command("a 'b"), std::invalid_argument);
  EXPECT_TRUE(split_command("   ").empty());
}

TEST(MasterCommand, AProgramThatCannotStartIsNamedWithWhy) {
  const testing::TempDir dir("omnitwin-mcmd");
  EXPECT_EQ(program_problem("true"), "") << "on PATH";
  EXPECT_EQ(program_problem("/bin/sh"), "");
  EXPECT_EQ(program_problem("no-such-program-anywhere"), "not found on PATH");
  EXPECT_EQ(program_problem((dir.path() / "missing").string()), "no such file");
  const auto plain = dir.path() / "plain.sh";
  std::ofstream(plain) << "#!/bin/sh\n";
  ::chmod(plain.c_str(), 0644);
  if (::geteuid() != 0) {
    EXPECT_EQ(program_problem(plain.string()), "not an executable file");
  }
  EXPECT_EQ(program_problem(dir.path().string()), "not an executable file") << "a folder";
  EXPECT_EQ(program_path("sh").empty(), false);
  EXPECT_EQ(program_path("./x"), "./x") << "a path is taken as it is";
}

}  // namespace
}  // namespace omnitwin::twin
