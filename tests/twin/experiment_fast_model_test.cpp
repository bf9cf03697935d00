// Tests twin/experiment_fast_model: the twist comparison of two trajectories (identical runs
// agree exactly, a 1 % faster platform reads 1 %, bad files are refused), the fast model
// against the roller reference on the thesis line, circle and rotation (issue 17's 0.5 % bound,
// both models passing the scenarios' own expectations), a fast model whose contact line is
// moved off the reference's failing that bound, and the experiment's files.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "tests/support/mujoco_fixture.hpp"
#include "tests/support/temp_dir.hpp"
#include "twin/csv_columns.hpp"
#include "twin/experiment.hpp"

namespace omnitwin::twin {
namespace {

namespace fs = std::filesystem;

std::string scenario(const char* name) {
  return std::string(OMNITWIN_SOURCE_DIR) + "/models/scenarios/" + name + ".yaml";
}

// A trajectory.csv of 2 s at 10 ms: moving along x at `v` m/s while turning at `w` rad/s.
fs::path write_trajectory(const fs::path& dir, const std::string& name, double v, double w) {
  const fs::path p = dir / name;
  std::ofstream out(p);
  out << "t,x,y,phi,vx,vy,wz\n";
  for (int i = 0; i <= 200; ++i) {
    const double t = 0.01 * i;
    out << fmt::format("{},{},{},{},{},{},{}\n", t, v * t, 0.0, w * t, v, 0.0, w);
  }
  return p;
}

TEST(TwistAgreement, IdenticalRunsAgreeExactly) {
  omnitwin::testing::TempDir dir("omnitwin-fm");
  const CsvColumns a = read_csv_columns(write_trajectory(dir.path(), "a.csv", 0.1, 0.2).string());
  const TwistAgreement g = twist_agreement(a, a, 0.25, 1.0);
  EXPECT_EQ(g.twist_error, 0.0);
  EXPECT_EQ(g.final_pose_diff_m, 0.0);
  EXPECT_EQ(g.windows, 2);                      // 201 samples: two whole 1 s windows
  EXPECT_NEAR(g.path_m, 2 * (0.1 + 0.25 * 0.2), 1e-9);  // 2 s of 0.1 m/s and L·0.2 rad/s
}

TEST(TwistAgreement, APlatformOnePercentFasterReadsOnePercent) {
  omnitwin::testing::TempDir dir("omnitwin-fm");
  const CsvColumns ref = read_csv_columns(write_trajectory(dir.path(), "ref.csv", 0.1, 0.2).string());
  const CsvColumns fast = read_csv_columns(write_trajectory(dir.path(), "fast.csv", 0.101, 0.202).string());
  const TwistAgreement g = twist_agreement(ref, fast, 0.25, 1.0);
  EXPECT_NEAR(g.twist_error, 0.01, 1e-9);
  // At t = 2 s: 2 mm further along x and 4 mrad more heading (·L = 1 mm).
  EXPECT_NEAR(g.final_pose_diff_m, 0.002 + 0.25 * 0.004, 1e-9);
}

TEST(TwistAgreement, AFileWithoutTheTwistColumnsOrRowsIsRefused) {
  omnitwin::testing::TempDir dir("omnitwin-fm");
  const CsvColumns ok = read_csv_columns(write_trajectory(dir.path(), "ok.csv", 0.1, 0).string());
  std::ofstream(dir.path() / "bare.csv") << "t,x,y,phi\n0,0,0,0\n0.01,0,0,0\n";
  const CsvColumns bare = read_csv_columns((dir.path() / "bare.csv").string());
  EXPECT_THROW(twist_agreement(ok, bare, 0.25, 1.0), std::runtime_error);
  std::ofstream(dir.path() / "one.csv") << "t,x,y,phi,vx,vy,wz\n0,0,0,0,0,0,0\n";
  const CsvColumns one = read_csv_columns((dir.path() / "one.csv").string());
  EXPECT_THROW(twist_agreement(one, one, 0.25, 1.0), std::runtime_error);
}

class FastModel : public omnitwin::testing::MujocoTest {};

// Issue 17, item 3: within 0.5 % of the reference's twist on the thesis line, the circle and
// the rotation, at the reference's 1 ms step, and both models pass each scenario's own
// expectations (a run with a MuJoCo warning would not).
TEST_F(FastModel, FollowsTheReferenceTwistWithinHalfAPercentOnTheThreeScenarios) {
  omnitwin::testing::TempDir dir("omnitwin-fm");
  for (const char* name : {"thesis_line", "circle", "rotate"}) {
    const FastModelRow r = compare_fast_model(scenario(name), dir.path() / name, 1);
    EXPECT_LT(r.agreement.twist_error, kFastModelTwistBound) << name;
    EXPECT_LT(r.agreement.final_pose_diff_m, 0.005 * r.agreement.path_m) << name;
    EXPECT_EQ(r.exit_reference, 0) << name;
    EXPECT_EQ(r.exit_fast, 0) << name;
    RecordProperty(std::string(name) + "_twist_error_percent", fmt::format("{:.3f}", 100 * r.agreement.twist_error));
  }
}

// The bound can fail: a contact line 10 mm outward (the wheel distance the kinematics assume
// is then wrong by 4 %) turns the platform measurably slower than the reference.
TEST_F(FastModel, AContactLineOffTheReferencesFailsTheBound) {
  omnitwin::testing::TempDir dir("omnitwin-fm");
  const FastModelRow r = compare_fast_model(scenario("rotate"), dir.path() / "rotate", 1,
                                            {{"platform.capsule.contact_offset", "0.01"}});
  EXPECT_GT(r.agreement.twist_error, kFastModelTwistBound);
}

// `omnitwin experiment fast-model` (quick: one run per model): a row per scenario and step in
// the CSV, each within the bound, and the report.
TEST_F(FastModel, TheExperimentWritesARowPerScenarioAndStepAndPasses) {
  omnitwin::testing::TempDir dir("omnitwin-fm");
  ASSERT_EQ(run_experiment("fast-model", ExperimentOptions{dir.path().string(), true}), kExperimentOk);
  const CsvColumns c = read_csv_columns((dir.path() / "fast_model.csv").string());
  ASSERT_EQ(c.rows(), 6u);
  for (double e : c.column("twist_error_pct")) EXPECT_LT(e, 100 * kFastModelTwistBound);
  for (double s : c.column("speedup")) EXPECT_GT(s, 0.0);
  EXPECT_TRUE(fs::exists(dir.path() / "fast_model.md"));
}

}  // namespace
}  // namespace omnitwin::twin
