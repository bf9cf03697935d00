// Tests `omnitwin replay` through the real program: a recorded bus-direct run replayed on
// physics alone (its platform.xml, its scenario's parameters and start pose, the recorded
// wheel set-points) ends where the run ended (within 0.05 cm) and reports its real-time
// factor; a folder that is not a run directory, or a trajectory without the set-point
// columns, or a torn run.json, is bad input (exit 2) naming what is missing or where.
#include <gtest/gtest.h>

#include <csignal>
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
  // A torn run.json: the file and the place, without the JSON library's exception tag.
  const std::string run_json = read_bytes(run_dir / "run.json");
  std::ofstream(run_dir / "run.json", std::ios::trunc) << run_json.substr(0, run_json.size() / 2);
  p = run({"replay", test_scenario("run_short_line.yaml"), run_dir.string()});
  EXPECT_EQ(p.code, 2);
  EXPECT_TRUE(contains(p.err, (run_dir / "run.json").string() + ": parse error at line")) << p.err;
  EXPECT_FALSE(contains(p.err, "json.exception")) << p.err;
}

// The "apart X cm" figure of a replay's output (-1 when absent).
double apart_cm(const std::string& out) {
  std::smatch m;
  return std::regex_search(out, m, std::regex(R"(apart ([0-9.]+) cm)")) ? std::stod(m[1].str()) : -1;
}

// Found in review: run.json was never read, so a run made with --set (another start, another
// driver) replayed with the scenario file's physics and still exited 0; another scenario too.
TEST_F(Replay, TheRunsOverridesAndStartPoseApplyAndAnotherScenarioIsRefused) {
  const fs::path run_dir = dir_ / "run";
  const Finished r = run_test_scenario("run_short_line.yaml", run_dir,
                                       {"path.start.x=0.5", "platform.driver.gain_error=[0.05,0,0,0]"});
  ASSERT_EQ(r.code, 0) << r.out << r.err;
  const Finished p = run({"replay", test_scenario("run_short_line.yaml"), run_dir.string()});
  ASSERT_EQ(p.code, 0) << p.out << p.err;
  const double apart = apart_cm(p.out);
  EXPECT_GE(apart, 0) << p.out;
  EXPECT_LT(apart, 0.05) << p.out;
  // The same file under another name is another scenario: bad input, naming both.
  std::string yaml = read_bytes(test_scenario("run_short_line.yaml"));
  yaml.replace(yaml.find("name: run_short_line"), 20, "name: other_line");
  std::ofstream(dir_ / "other_line.yaml") << yaml;
  const Finished q = run({"replay", (dir_ / "other_line.yaml").string(), run_dir.string()});
  EXPECT_EQ(q.code, 2) << q.out << q.err;
  EXPECT_TRUE(contains(q.err, "'other_line'") && contains(q.err, "'run_short_line'")) << q.err;
}

// Found in review: replay ran one control period past the last sample, so it compared the
// recorded pose with a later instant. It ends at the last sample's t (3.5 s here).
TEST_F(Replay, EndsAtTheLastSamplesTime) {
  const fs::path run_dir = dir_ / "run";
  ASSERT_EQ(run_test_scenario("run_short_line.yaml", run_dir).code, 0);
  const Finished p = run({"replay", test_scenario("run_short_line.yaml"), run_dir.string()});
  ASSERT_EQ(p.code, 0) << p.err;
  EXPECT_TRUE(contains(p.out, " 3.50 s simulated")) << p.out;
  EXPECT_TRUE(contains(p.out, " 3500 physics steps")) << p.out;
}

// Found in review: a header-only trajectory.csv (an interrupted twin can leave one) crashed
// replay (SIGSEGV), and a torn row replayed to "apart nan cm" with exit 0.
TEST_F(Replay, NoSamplesOrATornRowIsBadInputNamingTheFileAndLine) {
  const fs::path run_dir = dir_ / "run";
  ASSERT_EQ(run_test_scenario("run_short_line.yaml", run_dir).code, 0);
  const fs::path csv = run_dir / "trajectory.csv";
  const std::string whole = read_bytes(csv);
  const std::string header = whole.substr(0, whole.find('\n') + 1);
  std::ofstream(csv, std::ios::trunc) << header;
  Finished p = run({"replay", test_scenario("run_short_line.yaml"), run_dir.string()});
  EXPECT_EQ(p.code, 2) << p.out << p.err;
  EXPECT_TRUE(contains(p.err, "trajectory.csv holds no samples")) << p.err;
  // A last row torn after its first cell: t = "3." (not after 3.49); then an empty t.
  std::string body = whole.substr(0, whole.rfind('\n', whole.size() - 2) + 1);
  std::ofstream(csv, std::ios::trunc) << body << "3.\n";
  p = run({"replay", test_scenario("run_short_line.yaml"), run_dir.string()});
  EXPECT_EQ(p.code, 2) << p.out << p.err;
  EXPECT_TRUE(contains(p.err, "trajectory.csv:352: t 3 does not increase")) << p.err;
  std::ofstream(csv, std::ios::trunc) << body << ",1,2\n";
  p = run({"replay", test_scenario("run_short_line.yaml"), run_dir.string()});
  EXPECT_EQ(p.code, 2) << p.out << p.err;
  EXPECT_TRUE(contains(p.err, "trajectory.csv:352: t is not a finite number")) << p.err;
}

// Found in review: replay ignored Ctrl-C and SIGTERM and exited 0 once done. A long (made-up)
// trajectory: the signal ends it at once with exit 3.
TEST_F(Replay, ASignalEndsItWithExitThree) {
  const fs::path run_dir = dir_ / "run";
  ASSERT_EQ(run_test_scenario("run_short_line.yaml", run_dir).code, 0);
  {
    std::ofstream f(run_dir / "trajectory.csv", std::ios::trunc);
    f << "t,x,y,w1_setpoint_rad_s,w2_setpoint_rad_s,w3_setpoint_rad_s,w4_setpoint_rad_s\n";
    for (int k = 0; k < 100000; ++k) f << k * 0.01 << ",0,0,0,0,0,0\n";  // 1000 s simulated
  }
  for (const int sig : {SIGINT, SIGTERM}) {
    Child c({"replay", test_scenario("run_short_line.yaml"), run_dir.string()}, work(), io());
    std::this_thread::sleep_for(std::chrono::milliseconds(700));
    c.signal(sig);
    EXPECT_EQ(c.wait(std::chrono::seconds(5)), 3) << c.out() << c.err();
    EXPECT_TRUE(contains(c.err(), "interrupted")) << c.err();
  }
}

}  // namespace
}  // namespace omnitwin::twin::cli
