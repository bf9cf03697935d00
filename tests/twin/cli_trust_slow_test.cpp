// Slow tests (ctest -L slow) of run isolation (issue 19): eight lockstep runs at once on
// each bus, every one passing with the trajectory of a run alone. The default tier runs two
// at once (cli_trust_test.cpp); eight take about 5 s per bus on two cores.
#include <gtest/gtest.h>

#include "tests/twin/cli_support.hpp"

namespace {

using namespace omnitwin::twin::cli;

class CliTrustSlow : public CliTest {
 protected:
  void expect_eight_concurrent_runs_match_alone(const std::string& bus) {
    const std::string scenario = source_path("models/scenarios/thesis_line.yaml");
    const Finished alone = run({"run", scenario, "--bus", bus, "--no-video", "--no-report", "--out",
                                (dir_ / "alone").string(), "--no-progress"});
    ASSERT_EQ(alone.code, 0) << alone.out << alone.err;
    const std::string expected = read_bytes(dir_ / "alone/trajectory.csv");
    ASSERT_FALSE(expected.empty());
    std::vector<std::unique_ptr<Child>> runs;
    for (int i = 0; i < 8; ++i) {
      const std::string out = (dir_ / ("p" + std::to_string(i))).string();
      runs.push_back(std::make_unique<Child>(
          omnitwin_binary(),
          std::vector<std::string>{"run", scenario, "--bus", bus, "--no-video", "--no-report", "--out", out,
                                   "--no-progress"},
          work(), io(), "p" + std::to_string(i)));
    }
    for (int i = 0; i < 8; ++i) {
      Child& c = *runs[static_cast<std::size_t>(i)];
      EXPECT_EQ(c.wait(600s), 0) << "run " << i << ":\n" << c.out() << c.err();
      EXPECT_EQ(read_bytes(dir_ / ("p" + std::to_string(i)) / "trajectory.csv"), expected) << "run " << i;
    }
  }
};

TEST_F(CliTrustSlow, EightConcurrentCanLockstepRunsMatchARunAlone) { expect_eight_concurrent_runs_match_alone("can"); }

TEST_F(CliTrustSlow, EightConcurrentEthercatLockstepRunsMatchARunAlone) {
  expect_eight_concurrent_runs_match_alone("ethercat");
}

}  // namespace
