// Tests twin/experiment_thesis_platform in quick mode (250 and 1000 kbit/s, two trials, 40 cm
// in 4 s): it runs the scenario it is given, marks the fast no-sync 1000 kbit/s row as the
// fitted one and every other as held out, counts the acceptance checks, and writes the pose
// error over time without and with sync at 250 kbit/s from the runs' own trajectories; --set
// reaches every run and is named in the report, and only the thesis experiments take it; a fit
// is known by the name thesis-calibrate gives it, not by its file's name.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tests/support/temp_dir.hpp"
#include "twin/experiment.hpp"
#include "twin/experiment_thesis.hpp"

namespace omnitwin::twin {
namespace {

namespace fs = std::filesystem;

TEST(ThesisPlatform, AQuickRunOfTheFittedScenarioReportsTheFitRowAndPredictions) {
  omnitwin::testing::TempDir dir("omnitwin-tp");
  ExperimentOptions o{dir.path().string(), true};
  o.model = thesis::fitted_scenario();
  const int rc = run_experiment("thesis-platform", o);
  // 0 when every direction matches, 1 when one differs; never a runtime failure.
  ASSERT_TRUE(rc == kExperimentOk || rc == kExperimentCheckFailed) << rc;
  const std::string md = omnitwin::testing::read_bytes(dir.path() / "thesis_platform.md");
  EXPECT_NE(md.find("Scenario: `thesis_line_fitted.yaml`. Its free parameters"), std::string::npos);
  // Quick: 2 bit rates × 2 sync settings on the fast reading; one fitted, three held out.
  EXPECT_NE(md.find("| 1000 | no | **fitted** |"), std::string::npos);
  EXPECT_NE(md.find("| 250 | yes | held out |"), std::string::npos);
  EXPECT_NE(md.find(" of 3** (the acceptance asks for 6 of 7)"), std::string::npos);
  EXPECT_NE(md.find(" of 6**."), std::string::npos);  // sign checks: X, contour, axis at 250 and 1000
  EXPECT_NE(md.find("Overall axis-IAE improvement"), std::string::npos);
  // Found in review: the header named thesis_line.yaml whatever ran, and the thesis's axis rates
  // were the improvement of the mean IAE (+27.7 %, +15.7 %) where table 4-12 averages each
  // axis's rate (+25.6 %, +15.4 %), so ours were judged against numbers the thesis does not give.
  EXPECT_NE(md.find("Runs of `models/scenarios/thesis_line_fitted.yaml`"), std::string::npos);
  EXPECT_NE(md.find("/ +25.6 % | matches |"), md.find("/ +25.6 % | **differs** |")) << "table 4-12 at 250 kbit/s";
  EXPECT_TRUE(md.find("/ +25.6 % |") != std::string::npos && md.find("/ +15.4 % |") != std::string::npos);
  EXPECT_EQ(md.find("/ +27.7 % |"), std::string::npos);
  // Each axis (tables 4-4, 4-8, 4-12), the thesis's beside ours.
  EXPECT_NE(md.find("| 250 | IAE, no sync | "), std::string::npos);
  EXPECT_NE(md.find(" / 3338 |"), std::string::npos);        // axis 1, 250 kbit/s, no sync
  EXPECT_NE(md.find(" / +36.9 % |"), std::string::npos);     // axis 1's rate at 250 kbit/s
  EXPECT_NE(md.find("thesis σ x / y / contour"), std::string::npos);
  EXPECT_NE(md.find("| 250 | σ, no sync | "), std::string::npos);  // tables 4-6, 4-10, 4-14
  EXPECT_NE(md.find(" / 2.367 |"), std::string::npos);             // axis 1, 250 kbit/s, no sync
  EXPECT_NE(md.find(" / +38.3 % |"), std::string::npos);           // its rate (table 4-14)
  // The time series: both runs at 250 kbit/s, 10 ms samples over the 4 s path and its 2 s settle,
  // the contour error the hypotenuse of X and Y.
  const std::vector<std::string> lines =
      omnitwin::testing::lines_of(omnitwin::testing::read_bytes(dir.path() / "thesis_platform_time.csv"));
  ASSERT_GT(lines.size(), 1000u);
  EXPECT_EQ(lines[0], "rate_kbps,sync,t_s,ex_cm,ey_cm,ec_cm");
  int with = 0, without = 0;
  double t_max = 0, ex_max = 0;
  for (std::size_t i = 1; i < lines.size(); ++i) {
    std::vector<double> v;
    std::istringstream in(lines[i]);
    for (std::string c; std::getline(in, c, ',');) v.push_back(std::stod(c));
    ASSERT_EQ(v.size(), 6u) << lines[i];
    EXPECT_EQ(v[0], 250);
    (v[1] == 1 ? with : without)++;
    t_max = std::max(t_max, v[2]);
    ex_max = std::max(ex_max, v[3]);
    EXPECT_NEAR(v[5], std::hypot(v[3], v[4]), 1e-4) << lines[i];
  }
  EXPECT_EQ(with, without);
  EXPECT_NEAR(t_max, 6.0, 0.05);
  EXPECT_GT(ex_max, 0.5);  // the fitted P loop lags the planned pose by centimetres
}

TEST(ThesisPlatform, SetReachesEveryRunAndTheReportNamesIt) {
  omnitwin::testing::TempDir dir("omnitwin-tp-set");
  // A fit written under another name (thesis-calibrate --model my_fit.yaml) is still the fitted
  // scenario: found probing issue 15, where such a file was reported as "not the fitted scenario".
  std::string fit = omnitwin::testing::read_bytes(thesis::fitted_scenario());
  const std::string rel = "params: ../platform/";
  ASSERT_NE(fit.find(rel), std::string::npos);
  fit.replace(fit.find(rel), rel.size(), "params: " + std::string(OMNITWIN_SOURCE_DIR) + "/models/platform/");
  std::ofstream(dir.path() / "my_fit.yaml") << fit;
  ExperimentOptions o{dir.path().string(), true};
  o.model = (dir.path() / "my_fit.yaml").string();
  o.sets = {{"bus.isr_us", "2500"}};  // not the experiments' 3300
  const int rc = run_experiment("thesis-platform", o);
  ASSERT_TRUE(rc == kExperimentOk || rc == kExperimentCheckFailed) << rc;
  const std::string md = omnitwin::testing::read_bytes(dir.path() / "thesis_platform.md");
  EXPECT_NE(md.find("Every run also had `--set bus.isr_us=2500`"), std::string::npos);
  EXPECT_NE(md.find("Scenario: `my_fit.yaml`. Its free parameters"), std::string::npos);
  int runs = 0;
  for (const auto& e : fs::directory_iterator(dir.path() / "runs")) {
    const nlohmann::json m = nlohmann::json::parse(std::ifstream(e.path() / "metrics.json"));
    for (const auto& sl : m.at("slaves")) EXPECT_EQ(sl.at("isr_us").get<double>(), 2500.0) << e.path();
    ++runs;
  }
  EXPECT_GT(runs, 0);
  // A key the scenario does not have is bad input before anything runs; other experiments refuse --set.
  ExperimentOptions bad{(dir.path() / "bad").string(), true};
  bad.sets = {{"bus.no_such_key", "1"}};
  EXPECT_EQ(run_experiment("thesis-platform", bad), kExperimentUnknown);
  EXPECT_FALSE(fs::exists(dir.path() / "bad"));
  ExperimentOptions other{(dir.path() / "other").string(), true};
  other.sets = {{"bus.isr_us", "3300"}};
  EXPECT_EQ(run_experiment("can-timing", other), kExperimentUnknown);
}

}  // namespace
}  // namespace omnitwin::twin
