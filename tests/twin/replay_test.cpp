// Tests `omnitwin replay` through the real program: a recorded bus-direct run replayed on
// physics alone (its platform.xml, its scenario's parameters and start pose, the recorded
// wheel set-points) ends where the run ended (within 0.05 cm) and reports its real-time
// factor; a folder that is not a run directory, or a trajectory without the set-point
// columns, is bad input (exit 2) naming what is missing.
#include <gtest/gtest.h>

#include <fstream>
#include <regex>

#include "tests/twin/cli_support.hpp"

namespace omnitwin::twin::cli {
namespace {

class Replay : public CliTest {};

TEST_F(Replay, ADirectRunReplaysToTheSamePose) {
  const fs::path run_dir = dir_ / "run";
  const Finished r = run_test_scenario("run_short_line.yaml", run_dir);
  ASSERT_EQ(r.code, 0) << r.out << r.err;
  const Finished p = run({"replay", test_scenario("run_short_line.yaml"), run_dir.string()});
  ASSERT_EQ(p.code, 0) << p.out << p.err;
  EXPECT_TRUE(contains(p.out, "351 samples")) << p.out;
  std::smatch m;
  const std::string out = p.out;
  ASSERT_TRUE(std::regex_search(out, m, std::regex(R"(apart ([0-9.]+) cm)"))) << out;
  EXPECT_LT(std::stod(m[1].str()), 0.05) << out;
  EXPECT_TRUE(std::regex_search(out, std::regex(R"(\(([0-9.]+)x real time\))"))) << out;
}

TEST_F(Replay, NotARunDirectoryOrNoSetpointsIsBadInput) {
  fs::create_directories(dir_ / "empty");
  Finished p = run({"replay", test_scenario("run_short_line.yaml"), (dir_ / "empty").string()});
  EXPECT_EQ(p.code, 2);
  EXPECT_TRUE(contains(p.err, "platform.xml: no such file")) << p.err;
  const fs::path run_dir = dir_ / "run";
  ASSERT_EQ(run_test_scenario("run_short_line.yaml", run_dir).code, 0);
  std::ofstream(run_dir / "trajectory.csv") << "t,x,y\n0,0,0\n";
  p = run({"replay", test_scenario("run_short_line.yaml"), run_dir.string()});
  EXPECT_EQ(p.code, 2);
  EXPECT_TRUE(contains(p.err, "has no column w1_setpoint_rad_s")) << p.err;
}

}  // namespace
}  // namespace omnitwin::twin::cli
