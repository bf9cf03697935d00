// Tests `omnitwin run` against every refused mutant of scenario_mutants_test.cpp (label slow:
// about a thousand CLI starts): each must exit 2 within 10 s — no crash, hang or exit 3 —
// with exactly one line on stderr, the reader's message, nothing on stdout and no run
// directory. Prints the tally by kind of edit (docs/reliability.md quotes it).
#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "tests/support/scenario_mutants.hpp"
#include "tests/twin/cli_support.hpp"
#include "twin/scenario.hpp"

namespace omnitwin::twin {
namespace {

namespace fs = std::filesystem;

class ScenarioMutantsCli : public cli::CliTest {};

TEST_F(ScenarioMutantsCli, EveryRefusedMutantExitsTwoWithOneLineAndNoRunDirectory) {
  std::map<std::string, int> tried, refused_ok;
  int loaded = 0;
  for (const auto& m : omnitwin::testing::scenario_mutants(1200)) {
    const fs::path file = work() / (m.name + ".yaml");
    omnitwin::testing::write_bytes(file, m.text);
    std::string message;
    try {
      (void)load_scenario(file.string());
      ++loaded;
      continue;  // a valid scenario: running it is not this test's business
    } catch (const ScenarioError& e) {
      message = e.what();
    }
    ++tried[m.kind];
    const fs::path out = work() / "runs" / m.name;
    cli::Child c({"run", file.string(), "--out", out.string(), "--no-progress"}, work(), io());
    const int code = c.wait(std::chrono::seconds(10));
    ASSERT_NE(code, -1) << m.name << ": no exit within 10 s";
    const bool ok = code == 2 && c.err() == "omnitwin: " + message + "\n" && c.out().empty() && !fs::exists(out);
    EXPECT_TRUE(ok) << m.name << ": exit " << code << ", stderr " << c.err() << ", stdout " << c.out();
    refused_ok[m.kind] += ok ? 1 : 0;
  }
  int total = 0;
  for (const auto& [kind, n] : tried) {
    std::cout << kind << ": " << n << " refused by the reader, " << refused_ok[kind] << " of them exit 2 cleanly\n";
    total += n;
  }
  std::cout << total << " refused mutants through the CLI, " << loaded << " mutants that still load\n";
  EXPECT_GE(total, 700);
}

}  // namespace
}  // namespace omnitwin::twin
