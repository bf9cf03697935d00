// Tests twin/experiment_m3_cycle: the M-III cycle study in quick mode writes
// shortest_cycle.csv (the shortest cycle grows with the slave count; from a few slaves on a
// star is never slower than a cascade), verified.csv (every run agrees with the plan to the
// ns, the cycle 1 µs short is refused) and README.md; and its checks can fail: a slave
// slower than planned or a lossy line fails the trial and turns the exit code into
// kExperimentCheckFailed.
#include "twin/experiment.hpp"

#include <gtest/gtest.h>

#include <algorithm>

#include <map>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "tests/support/temp_dir.hpp"

namespace omnitwin::twin {
namespace {

using CsvRow = std::map<std::string, std::string>;  // column name → text

// A CSV file as rows of column name → text (no quoted commas in the columns read here).
std::vector<CsvRow> read_csv(const std::filesystem::path& p) {
  const std::vector<std::string> lines = omnitwin::testing::lines_of(omnitwin::testing::read_bytes(p));
  std::vector<std::string> head;
  std::vector<CsvRow> rows;
  for (const std::string& line : lines) {
    std::vector<std::string> cells;
    std::istringstream in(line);
    for (std::string c; std::getline(in, c, ',');) cells.push_back(c);
    if (head.empty()) {
      head = cells;
      continue;
    }
    CsvRow r;
    for (std::size_t k = 0; k < head.size() && k < cells.size(); ++k) r[head[k]] = cells[k];
    rows.push_back(r);
  }
  return rows;
}

long long num(const CsvRow& r, const std::string& key) { return std::stoll(r.at(key)); }

using Config = std::tuple<std::string, int, int>;  // topology, data bytes, retry slots

TEST(M3CycleExperiment, QuickRunPlansGrowingCyclesAndVerifiesThemToTheNanosecond) {
  omnitwin::testing::TempDir dir("omnitwin-m3cycle");
  ASSERT_EQ(run_experiment("m3-cycle", {dir.path().string(), true}), kExperimentOk);
  const auto plan = read_csv(dir / "shortest_cycle.csv");
  ASSERT_EQ(plan.size(), 2u * 5u * 3u * 7u) << "topologies × data lengths × retry slots × slave counts";
  std::map<Config, std::map<int, long long>> curves;  // config → slaves → min cycle
  for (const CsvRow& r : plan) {
    EXPECT_GT(num(r, "min_cycle_ns"), num(r, "int_offset_ns"));
    const Config c{r.at("topology"), static_cast<int>(num(r, "data_bytes")), static_cast<int>(num(r, "retry_slots"))};
    curves[c][static_cast<int>(num(r, "slaves"))] = num(r, "min_cycle_ns");
  }
  for (const auto& [config, curve] : curves) {
    long long before = 0;
    for (const auto& [slaves, cycle] : curve) {
      EXPECT_GT(cycle, before) << std::get<0>(config) << " " << slaves << " slaves";
      before = cycle;
      if (std::get<0>(config) != "star" || slaves < 4) continue;  // below: the hub costs more than a short cascade
      const Config cascade{"cascade", std::get<1>(config), std::get<2>(config)};
      EXPECT_LE(cycle, curves[cascade][slaves]) << slaves << " slaves";
    }
  }
  const auto verified = read_csv(dir / "verified.csv");
  ASSERT_EQ(verified.size(), 12u);  // 2 topologies × 8/32/64 bytes × 1 and 16 slaves
  EXPECT_EQ(std::count_if(verified.begin(), verified.end(), [](const CsvRow& r) { return r.at("data_bytes") == "8"; }), 4)
      << "the shortest data length the seed names is run too";
  for (const CsvRow& r : verified) {
    EXPECT_EQ(r.at("ok"), "1") << r.at("why");
    EXPECT_EQ(r.at("shorter_refused"), "1");
    EXPECT_EQ(num(r, "measured_last_rsp_max_ns"), num(r, "expected_last_rsp_ns"));
    EXPECT_EQ(num(r, "interrupt_min_ns"), num(r, "int_offset_ns"));
    EXPECT_GE(num(r, "cycles"), 200);
    EXPECT_EQ(num(r, "cycle_ns") % 1000, 0);
    EXPECT_LT(num(r, "cycle_ns") - num(r, "min_cycle_ns"), 1000);
  }
  const std::string readme = omnitwin::testing::read_bytes(dir / "README.md");
  EXPECT_NE(readme.find("## Event-driven against cyclic latency"), std::string::npos);
  EXPECT_TRUE(std::filesystem::exists(dir / "latency.csv"));
  EXPECT_NE(readme.find("Modelled, not measured"), std::string::npos);
}

TEST(M3CycleExperiment, ASlaveSlowerThanPlannedOrALossyLineFailsTheChecks) {
  const M3CycleTrial clean{.slaves = 4, .data_bytes = 64, .cycles = 50};
  EXPECT_TRUE(run_m3_cycle_trial(clean).ok()) << run_m3_cycle_trial(clean).why;
  M3CycleTrial slower = clean;
  slower.slave_slower_ns = 100;  // inside the 1 µs margin: no retry, but the timing is off
  const M3CycleVerified s = run_m3_cycle_trial(slower);
  EXPECT_FALSE(s.ok());
  EXPECT_EQ(s.retries, 0u);
  EXPECT_EQ(s.measured_max_ns - s.expected_last_ns, 4 * 100) << s.why;
  M3CycleTrial lossy = clean;
  lossy.corrupt_every = 7;
  const M3CycleVerified l = run_m3_cycle_trial(lossy);
  EXPECT_FALSE(l.ok());
  EXPECT_GT(l.retries, 0u) << l.why;
}

TEST(M3CycleExperiment, AFailingCheckGivesTheCheckFailedExitCode) {
  omnitwin::testing::TempDir dir("omnitwin-m3cycle");
  EXPECT_EQ(run_m3_cycle({dir.path().string(), true}, M3CycleTrial{.slave_slower_ns = 100}), kExperimentCheckFailed);
  const auto verified = read_csv(dir / "verified.csv");  // written before judging
  ASSERT_FALSE(verified.empty());
  for (const CsvRow& r : verified) EXPECT_EQ(r.at("ok"), "0");
}

}  // namespace
}  // namespace omnitwin::twin
