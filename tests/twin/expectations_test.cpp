// Tests expectations (twin/expectations.cpp): the known-metric list the loader validates
// against, dotted-path lookup into metrics.json (objects and arrays), and the pass/fail
// verdict with its failure sentences.
#include <gtest/gtest.h>

#include "twin/expectations.hpp"

namespace omnitwin::twin {
namespace {

Expectation bound(const std::string& metric, std::optional<double> min, std::optional<double> max) {
  Expectation e;
  e.metric = metric;
  e.min = min;
  e.max = max;
  return e;
}

nlohmann::json sample_metrics() {
  return nlohmann::json::parse(R"({
    "scenario": "thesis_line", "sim_time_s": 22, "wall_time_s": 1.5,
    "platform": {"final_error_cm": 0.73, "iae_x_cm": 120.5},
    "axes": [{"iae_velocity_pulse": 400, "std_velocity_pulse": 2.5},
             {"iae_velocity_pulse": 510, "std_velocity_pulse": 3.0}],
    "bus": {"errors": "many"}
  })");
}

TEST(KnownMetrics, AcceptsTheDocumentedPaths) {
  for (const char* m : {"sim_time_s", "wall_time_s", "real_time_factor", "platform.iae_x_cm",
                        "platform.std_contour_cm", "platform.final_error_cm", "platform.max_phi_error_deg",
                        "platform_odometry.iae_contour_cm", "platform_odometry.final_phi_error_deg",
                        "axes.0.iae_velocity_pulse", "axes.3.std_velocity_pulse", "bus.frames_tx",
                        "bus.dropout_rate", "bus.errors", "realtime.overruns", "realtime.jitter_p99_us",
                        // issue 18 (what the master did) and issue 20 (emergencies)
                        "platform.final_x_m", "platform.final_phi_deg", "drives.all_running_at_s",
                        "drives.stopped_at_s", "drives.faults", "drives.running_at_end", "master.emergencies",
                        "drives.running_at_duration", "bus.master_changes", "master.wakes_late",
                        // whether the plan reached the path's end within the run
                        "platform.path_done_s"}) {
    EXPECT_TRUE(is_known_metric(m)) << m;
  }
}

TEST(KnownMetrics, RejectsEverythingElse) {
  for (const char* m : {"", "platform", "platform.final_errr_cm", "axes.4.iae_velocity_pulse",
                        "axes.x.iae_velocity_pulse", "axes.-1.iae_velocity_pulse", "axes.0",
                        "axes.00x.iae_velocity_pulse", "bus.frames_tx.more", "realtime.jitter",
                        "scenario", "expectations.passed", "platform..iae_x_cm",
                        "platform_odometry.final_x_m", "platform_odometry.path_done_s", "drives.faultz", "drives"}) {
    EXPECT_FALSE(is_known_metric(m)) << m;
  }
}

TEST(Expectations, FindMetricWalksObjectsAndArrays) {
  const auto m = sample_metrics();
  ASSERT_NE(find_metric(m, "axes.1.iae_velocity_pulse"), nullptr);
  EXPECT_EQ(*find_metric(m, "axes.1.iae_velocity_pulse"), 510);
  EXPECT_EQ(*find_metric(m, "platform.final_error_cm"), 0.73);
  EXPECT_EQ(find_metric(m, "axes.2.iae_velocity_pulse"), nullptr);
  EXPECT_EQ(find_metric(m, "axes.first.iae_velocity_pulse"), nullptr);
  EXPECT_EQ(find_metric(m, "sim_time_s.x"), nullptr);
}

TEST(Expectations, AllMetPasses) {
  const auto r = evaluate_expectations({bound("platform.final_error_cm", std::nullopt, 1.0),
                                        bound("axes.0.iae_velocity_pulse", 100.0, 500.0),
                                        bound("sim_time_s", 22.0, 22.0)},
                                       sample_metrics());
  EXPECT_TRUE(r.passed);
  EXPECT_TRUE(r.failures.empty());
  EXPECT_EQ(r.to_json(), nlohmann::json::parse(R"({"passed": true, "failures": []})"));
}

TEST(Expectations, FailureSentences) {
  const auto r = evaluate_expectations({bound("platform.final_error_cm", std::nullopt, 0.5),
                                        bound("axes.1.iae_velocity_pulse", std::nullopt, 500.0),
                                        bound("sim_time_s", 30.0, std::nullopt),
                                        bound("bus.frames_tx", 1.0, std::nullopt),
                                        bound("bus.errors", std::nullopt, 0.0)},
                                       sample_metrics());
  EXPECT_FALSE(r.passed);
  ASSERT_EQ(r.failures.size(), 5u);
  EXPECT_EQ(r.failures[0], "platform.final_error_cm = 0.73 > max 0.5");
  EXPECT_EQ(r.failures[1], "axes.1.iae_velocity_pulse = 510 > max 500");
  EXPECT_EQ(r.failures[2], "sim_time_s = 22 < min 30");
  EXPECT_EQ(r.failures[3], "bus.frames_tx: missing from metrics");
  EXPECT_EQ(r.failures[4], "bus.errors: not a number (\"many\")");
  const auto j = r.to_json();
  EXPECT_EQ(j["passed"], false);
  EXPECT_EQ(j["failures"].size(), 5u);
  EXPECT_EQ(j["failures"][0], "platform.final_error_cm = 0.73 > max 0.5");
}

// A master on its own clock reports no stop: its metrics are null, and a bound on one fails
// saying so (they were 0 and -1, "never stopped", and passed; found by a walkthrough).
TEST(Expectations, ABoundOnAMetricTheRunDoesNotKnowFails) {
  nlohmann::json m = sample_metrics();
  m["master"] = {{"state", "unreported"}, {"stop_reason_code", nullptr}, {"stopped_at_s", nullptr}};
  const auto r = evaluate_expectations({bound("master.stop_reason_code", std::nullopt, 0.0),
                                        bound("master.stopped_at_s", std::nullopt, -1.0)},
                                       m);
  EXPECT_FALSE(r.passed);
  ASSERT_EQ(r.failures.size(), 2u);
  EXPECT_EQ(r.failures[0], "master.stop_reason_code: not known in this run (a master on its own clock reports no "
                           "state; judge it in lockstep)");
}

TEST(Expectations, NoExpectationsPass) {
  EXPECT_TRUE(evaluate_expectations({}, nlohmann::json::object()).passed);
}

}  // namespace
}  // namespace omnitwin::twin
