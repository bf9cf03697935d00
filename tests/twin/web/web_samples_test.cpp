// Tests twin/web/web_samples: the view's one format for live and recorded runs — a state
// sample and an event as JSON (unknown values as null), and a recorded run directory read
// back: decimated by simulated time like the live stream, bus.csv paired with trajectory.csv
// by time, drive states by name, events.log parsed, the video found, a missing record named.
#include "twin/web/web_samples.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <limits>

#include "tests/support/temp_dir.hpp"

namespace omnitwin::twin {
namespace {

using nlohmann::json;

TEST(WebSamples, StateSampleAsJsonWithUnknownsAsNull) {
  StateSample s;
  s.t_ns = 1'250'000'000;
  s.seq = 125;
  s.x = 0.5, s.y = -0.25, s.phi = 0.1;
  s.cmd_vx = std::numeric_limits<double>::quiet_NaN();
  s.wheel_angle = {1, 2, 3, 4};
  s.wheel_torque[2] = 0.75;
  s.drives[3].node = 4;
  s.drives[3].state = DriveStateCode::fault;
  s.drives[3].comm_state = "SAFE-OP";
  s.drives[3].device_state = "fault";
  s.bus.has_frames = true;
  s.bus.frames_tx = 1000;
  s.bus.load = 0.07;
  s.bus.wkc = 12;
  s.active_faults = 2;
  const json j = sample_json(s);
  EXPECT_DOUBLE_EQ(j["t"].get<double>(), 1.25);
  EXPECT_EQ(j["seq"], 125);
  EXPECT_DOUBLE_EQ(j["y"].get<double>(), -0.25);
  EXPECT_TRUE(j["cmd_vx"].is_null());
  EXPECT_DOUBLE_EQ(j["wheels"][3]["angle"].get<double>(), 4);
  EXPECT_DOUBLE_EQ(j["wheels"][2]["torque"].get<double>(), 0.75);
  EXPECT_EQ(j["drives"][3]["state"], "fault");
  EXPECT_EQ(j["drives"][3]["node"], 4);
  EXPECT_EQ(j["drives"][3]["comm"], "SAFE-OP");  // the protocol's own words
  EXPECT_EQ(j["drives"][3]["device"], "fault");
  EXPECT_EQ(j["drives"][0]["comm"], "");
  EXPECT_EQ(j["bus"]["tx"], 1000);
  EXPECT_DOUBLE_EQ(j["bus"]["load"].get<double>(), 0.07);
  EXPECT_EQ(j["bus"]["wkc"], 12);
  EXPECT_TRUE(sample_json(StateSample{})["bus"]["wkc"].is_null());  // a bus without a WKC
  EXPECT_EQ(j["faults"], 2);
  EXPECT_EQ(j.dump().find("NaN"), std::string::npos);
}

TEST(WebSamples, EventsAndTheEndMessage) {
  const json e = event_json(RunEvent{2'500'000, RunEventKind::fault, "fault", "node 2 power loss"});
  EXPECT_DOUBLE_EQ(e["t"].get<double>(), 0.0025);
  EXPECT_EQ(e["kind"], "fault");
  EXPECT_EQ(e["text"], "node 2 power loss");
  const json end = end_json({{"expectations", {{"passed", false}}}}, 1);
  EXPECT_EQ(end["passed"], false);
  EXPECT_EQ(end["exit_code"], 1);
  EXPECT_TRUE(end_json(json::object(), std::nullopt)["passed"].is_null());
}

// A recorded run's exit code from its metrics.json: an interruption during its outputs left
// expectations.passed true, and the view said "passed" (found in review).
TEST(WebSamples, ARecordedRunsExitCodeFollowsItsMetrics) {
  EXPECT_EQ(recorded_exit_code({{"expectations", {{"passed", true}}}}), 0);
  EXPECT_EQ(recorded_exit_code({{"expectations", {{"passed", false}}}}), 1);
  EXPECT_EQ(recorded_exit_code({{"expectations", {{"passed", true}}}, {"interrupted", true},
                                {"interrupted_phase", "outputs"}}),
            3);
  EXPECT_EQ(recorded_exit_code({{"expectations", {{"passed", true}}}, {"error", "disk full"}}), 3);
  EXPECT_FALSE(recorded_exit_code(json::object()).has_value());
}

// A run directory of 1 s at a 10 ms control period (101 rows), the platform moving 0.1 m/s.
void write_run(const std::filesystem::path& d, bool with_video) {
  std::ofstream(d / "run.json") << R"({"scenario": "s", "bus": "can", "clock": "lockstep", "control_period_s": 0.01,
                                       "duration_s": 1.0})";
  std::ofstream tr(d / "trajectory.csv");
  tr << "t,ref_x,ref_y,ref_phi,x,y,phi,vx,vy,wz,cmd_vx,cmd_vy,cmd_wz";
  for (int i = 1; i <= 4; ++i)
    tr << ",w" << i << "_cmd_rad_s,w" << i << "_speed_rad_s,w" << i << "_angle_rad,w" << i << "_setpoint_rad_s,w" << i
       << "_torque_nm";
  tr << "\n";
  std::ofstream bus(d / "bus.csv");
  bus << "t,frames_tx,frames_rx,dropouts,errors,load,active_faults,s1_state,s2_state,s3_state,s4_state\n";
  for (int r = 0; r <= 100; ++r) {
    const double t = r * 0.01;
    tr << t << "," << 0.1 * t << ",0,0," << 0.1 * t << ",0,0,0.1,0,0,nan,nan,nan";
    for (int i = 1; i <= 4; ++i) tr << "," << i << "," << i << "," << i * t << ",0,0";
    tr << "\n";
    bus << t << "," << 10 * r << "," << 10 * r << ",0,0,0.05,0," << (r < 50 ? 1 : 2) << ",2,2," << (r > 90 ? 4 : 2)
        << "\n";
  }
  std::ofstream(d / "events.log") << "    0.000000  start       scenario s bus can\n"
                                     "    0.500000  fault       node 4 power loss\n";
  std::ofstream(d / "metrics.json") << R"({"expectations": {"passed": true, "failures": []}})";
  if (with_video) std::ofstream(d / "video.mp4") << "x";
}

TEST(WebSamples, RecordedRunDecimatedPairedAndNamed) {
  omnitwin::testing::TempDir dir("websamples");
  write_run(dir.path(), true);
  const json run = recorded_run_json(dir.path().string(), 20.0);
  EXPECT_EQ(run["info"]["mode"], "recorded");
  EXPECT_EQ(run["info"]["bus"], "can");
  EXPECT_EQ(run["info"]["video"], "/run/video.mp4");
  const json& s = run["samples"];
  ASSERT_EQ(s.size(), 21u);  // every 50 ms of 1 s, both ends included
  EXPECT_NEAR(s[10]["t"].get<double>(), 0.5, 1e-9);
  EXPECT_NEAR(s[10]["x"].get<double>(), 0.05, 1e-9);
  EXPECT_TRUE(s[10]["cmd_vx"].is_null());
  EXPECT_NEAR(s[10]["wheels"][2]["angle"].get<double>(), 1.5, 1e-9);
  EXPECT_EQ(s[9]["drives"][0]["state"], "waiting");
  EXPECT_EQ(s[10]["drives"][0]["state"], "running");
  EXPECT_EQ(s[20]["drives"][3]["state"], "fault");
  EXPECT_EQ(s[10]["bus"]["tx"].get<double>(), 500);  // the bus row of the same time
  EXPECT_EQ(s[10]["drives"][1]["node"], 2);
  ASSERT_EQ(run["events"].size(), 2u);
  EXPECT_EQ(run["events"][1]["kind"], "fault");
  EXPECT_EQ(run["events"][1]["text"], "node 4 power loss");
  EXPECT_EQ(run["end"]["passed"], true);
  EXPECT_EQ(run["end"]["exit_code"], 0);  // as `omnitwin run` ended it
}

TEST(WebSamples, RecordedRunWithoutVideoAndWithAMissingRecord) {
  omnitwin::testing::TempDir dir("websamples");
  write_run(dir.path(), false);
  EXPECT_TRUE(recorded_run_json(dir.path().string(), 20.0)["info"]["video"].is_null());
  std::filesystem::remove(dir.path() / "bus.csv");
  try {
    (void)recorded_run_json(dir.path().string(), 20.0);
    FAIL() << "a run directory without bus.csv was read";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("bus.csv"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace omnitwin::twin
