// Tests twin/scenario's reader against bad input at scale: 1,200 mutants of the shipped
// scenario files (tests/support/scenario_mutants.hpp: truncations, wrong types, NaN/inf/huge
// numbers, missing, duplicated and unknown keys, tabs, open flow collections, binary garbage,
// empty files), a directory, a missing file and bad --set values. Every one must either load
// (some edits leave a valid scenario) or be refused with a ScenarioError whose message is one
// line naming the file (and the line, where it has one) — never another exception, a crash or
// a hang. A sample of the refused ones then goes through `omnitwin run`, which must exit 2 with
// that one line on stderr and no run directory; the whole set does so in
// cli_scenario_mutants_slow_test.cpp (label slow).
#include <gtest/gtest.h>

#include <algorithm>
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
using omnitwin::testing::ScenarioMutant;

// What loading a mutant gave: "" when it loaded, else the ScenarioError's message; any other
// exception fails the test.
std::string load_outcome(const fs::path& file, const std::vector<Override>& overrides = {}) {
  try {
    (void)load_scenario(file.string(), overrides);
    return "";
  } catch (const ScenarioError& e) {
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << file << ": not a ScenarioError: " << e.what();
    return "?";
  }
}

// A refusal names the file, says where when it can, and is one line.
void expect_one_line_naming(const std::string& message, const fs::path& file, const std::string& what) {
  EXPECT_EQ(message.rfind(file.string(), 0), 0u) << what << ": " << message;
  EXPECT_EQ(message.find('\n'), std::string::npos) << what << ": " << message;
  EXPECT_GT(message.size(), file.string().size() + 2) << what << ": says nothing: " << message;
}

class ScenarioMutants : public cli::CliTest {};

TEST_F(ScenarioMutants, EveryMutantLoadsOrIsRefusedWithOneLineNamingTheFile) {
  const std::vector<ScenarioMutant> mutants = omnitwin::testing::scenario_mutants(1200);
  ASSERT_GE(mutants.size(), 1000u);
  std::map<std::string, int> refused, loaded;
  std::vector<std::pair<fs::path, std::string>> refusals;
  for (const ScenarioMutant& m : mutants) {
    const fs::path file = work() / (m.name + ".yaml");
    omnitwin::testing::write_bytes(file, m.text);
    const std::string outcome = load_outcome(file);
    if (outcome.empty()) {
      ++loaded[m.kind];
      continue;
    }
    ++refused[m.kind];
    expect_one_line_naming(outcome, file, m.name);
    refusals.emplace_back(file, outcome);
  }
  // Most edits break a scenario; a test where they did not would prove little.
  EXPECT_GE(refusals.size(), 700u);
  for (const auto& [kind, n] : refused) std::cout << kind << ": " << n << " refused, " << loaded[kind] << " loaded\n";
  // A sample through the CLI: exit 2, the same one line on stderr, nothing on stdout, no run dir.
  const std::size_t step = std::max<std::size_t>(1, refusals.size() / 40);
  for (std::size_t i = 0; i < refusals.size(); i += step) {
    const auto& [file, message] = refusals[i];
    const fs::path out = work() / "runs" / file.stem();
    const cli::Finished r = run({"run", file.string(), "--out", out.string(), "--no-progress"});
    EXPECT_EQ(r.code, 2) << file;
    EXPECT_EQ(r.err, "omnitwin: " + message + "\n") << file;
    EXPECT_EQ(r.out, "") << file;
    EXPECT_FALSE(fs::exists(out)) << file << ": a refused scenario left a run directory";
  }
}

TEST_F(ScenarioMutants, ADirectoryOrAMissingFileIsRefusedLikeABadOne) {
  const fs::path dir = work() / "a_directory.yaml";
  fs::create_directories(dir);
  expect_one_line_naming(load_outcome(dir), dir, "directory");
  const fs::path missing = work() / "missing.yaml";
  expect_one_line_naming(load_outcome(missing), missing, "missing");
  for (const fs::path& p : {dir, missing}) {
    const cli::Finished r = run({"run", p.string(), "--out", (work() / "out").string(), "--no-progress"});
    EXPECT_EQ(r.code, 2) << p << r.err;
    EXPECT_FALSE(fs::exists(work() / "out"));
  }
}

TEST_F(ScenarioMutants, EveryBadSetValueIsRefusedBeforeAnythingRuns) {
  const std::string scenario = omnitwin::testing::source_path("models/scenarios/thesis_line.yaml");
  for (const std::string& set : omnitwin::testing::bad_overrides()) {
    std::string outcome;
    try {
      std::vector<Override> o{parse_override(set)};
      outcome = load_outcome(scenario, o);
    } catch (const ScenarioError& e) {
      outcome = e.what();  // refused while parsing KEY=VALUE itself
    }
    EXPECT_NE(outcome, "") << set << " was accepted";
    EXPECT_EQ(outcome.find('\n'), std::string::npos) << set << ": " << outcome;
    const fs::path out = work() / "set_out";
    const cli::Finished r = run({"run", scenario, "--out", out.string(), "--no-progress", "--set", set});
    EXPECT_EQ(r.code, 2) << set << ": " << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << set << ": " << r.err;
    EXPECT_FALSE(fs::exists(out)) << set;
  }
}

}  // namespace
}  // namespace omnitwin::twin
