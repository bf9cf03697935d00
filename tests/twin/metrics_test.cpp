// Tests the thesis's tracking indices (twin/metrics.cpp): IAE = Σ|e| (seed 002 eq. 4-14)
// and σ = sqrt(Σe²/N) (eq. 4-15) over samples, in cm/deg/pulses, against numbers worked
// out by hand, including the contour error, final/max values, NaN samples and the empty case.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "twin/expectations.hpp"
#include "twin/metrics.hpp"

namespace omnitwin::twin {
namespace {

constexpr double kTol = 1e-9;
constexpr double kDegPerRad = 180.0 / std::numbers::pi;

TEST(PoseErrorStats, TwoSamplesByHand) {
  PoseErrorStats s;
  s.add(-0.06, 0.08, -0.02);  // contour 0.10 m
  s.add(0.03, 0.04, 0.01);    // contour 0.05 m
  const auto j = s.to_json();
  EXPECT_EQ(j["samples"], 2);
  // IAE: sums of |e| in cm, no dt.
  EXPECT_NEAR(j["iae_x_cm"].get<double>(), 9.0, kTol);
  EXPECT_NEAR(j["iae_y_cm"].get<double>(), 12.0, kTol);
  EXPECT_NEAR(j["iae_contour_cm"].get<double>(), 15.0, kTol);
  // σ: sqrt((0.0036 + 0.0009)/2) m etc.
  EXPECT_NEAR(j["std_x_cm"].get<double>(), 100 * std::sqrt(0.00225), kTol);
  EXPECT_NEAR(j["std_y_cm"].get<double>(), 100 * std::sqrt(0.004), kTol);
  EXPECT_NEAR(j["std_contour_cm"].get<double>(), 100 * std::sqrt(0.00625), kTol);
  // Last sample and worst sample.
  EXPECT_NEAR(j["final_error_cm"].get<double>(), 5.0, kTol);
  EXPECT_NEAR(j["max_error_cm"].get<double>(), 10.0, kTol);
  // Heading in degrees.
  EXPECT_NEAR(j["iae_phi_deg"].get<double>(), 0.03 * kDegPerRad, kTol);
  EXPECT_NEAR(j["std_phi_deg"].get<double>(), std::sqrt(0.00025) * kDegPerRad, kTol);
  EXPECT_NEAR(j["final_phi_error_deg"].get<double>(), 0.01 * kDegPerRad, kTol);
  EXPECT_NEAR(j["max_phi_error_deg"].get<double>(), 0.02 * kDegPerRad, kTol);
}

// No sample, no figure: every figure null (was 0, which passed any max bound on odometry
// a realtime run never sampled; found in review), and a bound on one fails.
TEST(PoseErrorStats, EmptyIsNullAndFailsItsBounds) {
  const auto j = PoseErrorStats{}.to_json();
  EXPECT_EQ(j["samples"], 0);
  EXPECT_EQ(j.size(), 13u);
  for (const auto& [key, value] : j.items()) {
    if (key != "samples") {
      EXPECT_TRUE(value.is_null()) << key;
    }
  }
  const nlohmann::json metrics = {{"platform_odometry", j}};
  const ExpectationResult r = evaluate_expectations({Expectation{.metric = "platform_odometry.max_error_cm", .min = {}, .max = 1e-4}}, metrics);
  EXPECT_FALSE(r.passed);
  ASSERT_EQ(r.failures.size(), 1u);
  EXPECT_EQ(r.failures[0], "platform_odometry.max_error_cm: not known in this run (null)");
}

// A NaN error (a master's odometry can report one) makes the worst case NaN for good: the
// max figures skipped NaN samples and passed their bounds (found in review).
TEST(PoseErrorStats, ANanSampleMakesTheMaxFiguresNan) {
  PoseErrorStats s;
  s.add(0.01, 0, 0);
  s.add(std::nan(""), 0, std::nan(""));
  s.add(0.02, 0, 0.01);
  const auto j = s.to_json();
  EXPECT_TRUE(std::isnan(j["max_error_cm"].get<double>()));
  EXPECT_TRUE(std::isnan(j["max_phi_error_deg"].get<double>()));
  EXPECT_NEAR(j["final_error_cm"].get<double>(), 2.0, kTol);
  const ExpectationResult r = evaluate_expectations({Expectation{.metric = "platform.max_error_cm", .min = {}, .max = 10.0}},
                                                    nlohmann::json{{"platform", j}});
  EXPECT_FALSE(r.passed);
}

TEST(PoseErrorStats, IaeGrowsWithSampleCountNotTime) {
  // Same constant error, twice the samples: IAE doubles, σ stays (eq. 4-14 is a sum).
  PoseErrorStats a, b;
  for (int i = 0; i < 10; ++i) a.add(0.01, 0, 0);
  for (int i = 0; i < 20; ++i) b.add(0.01, 0, 0);
  EXPECT_NEAR(b.to_json()["iae_x_cm"].get<double>(), 2 * a.to_json()["iae_x_cm"].get<double>(), kTol);
  EXPECT_NEAR(a.to_json()["std_x_cm"].get<double>(), 1.0, kTol);
  EXPECT_NEAR(b.to_json()["std_x_cm"].get<double>(), 1.0, kTol);
}

TEST(VelocityErrorStats, ThreeSamplesByHand) {
  VelocityErrorStats v;
  v.add(3);
  v.add(-4);
  v.add(0);
  const auto j = v.to_json();
  EXPECT_EQ(j["samples"], 3);
  EXPECT_NEAR(j["iae_velocity_pulse"].get<double>(), 7.0, kTol);
  EXPECT_NEAR(j["std_velocity_pulse"].get<double>(), std::sqrt(25.0 / 3.0), kTol);
}

TEST(VelocityErrorStats, ASuffixNamesTheSameFigures) {
  VelocityErrorStats v;
  v.add(-2);
  const auto j = v.to_json("_at_master");
  EXPECT_EQ(j["samples_at_master"], 1);
  EXPECT_NEAR(j["iae_velocity_pulse_at_master"].get<double>(), 2.0, kTol);
  EXPECT_FALSE(j.contains("iae_velocity_pulse"));
  const auto e = VelocityErrorStats{}.to_json("_at_master");
  EXPECT_TRUE(e["iae_velocity_pulse_at_master"].is_null());
  EXPECT_EQ(e["samples_at_master"], 0);
  EXPECT_FALSE(e.contains("samples"));
}

TEST(VelocityErrorStats, EmptyIsNull) {
  const auto j = VelocityErrorStats{}.to_json();
  EXPECT_TRUE(j["iae_velocity_pulse"].is_null());
  EXPECT_TRUE(j["std_velocity_pulse"].is_null());
  EXPECT_EQ(j["samples"], 0);
}

// Issue 18: what the drives did. All four running from 0.2 s, drive 3 faults at 0.5 s and
// again at 0.7 s (two transitions), none running from 0.9 s; two running at the end.
TEST(DriveHistory, FirstAllRunningStopsAndFaults) {
  using D = DriveStateCode;
  DriveHistory h;
  EXPECT_EQ(h.to_json().at("all_running_at_s"), -1.0);
  h.add(0.1, {D::waiting, D::running, D::running, D::running});
  h.add(0.2, {D::running, D::syncing, D::running, D::running});
  h.add(0.5, {D::running, D::running, D::fault, D::running});
  h.add(0.6, {D::running, D::running, D::running, D::running});
  h.add(0.7, {D::running, D::running, D::fault, D::running});
  h.add(0.9, {D::waiting, D::waiting, D::fault, D::off});
  h.add(1.0, {D::running, D::running, D::waiting, D::waiting});
  const auto j = h.to_json();
  EXPECT_DOUBLE_EQ(j.at("all_running_at_s").get<double>(), 0.2);
  EXPECT_DOUBLE_EQ(j.at("stopped_at_s").get<double>(), 0.9);
  EXPECT_EQ(j.at("faults"), 2);
  EXPECT_EQ(j.at("running_at_end"), 2);
  EXPECT_EQ(j.at("running_at_duration"), 2) << "every sample was in the run";
}

// The master's shutdown after the run's end: running_at_end is what it left, running_at_duration
// what the run left before it.
TEST(DriveHistory, TheShutdownAfterTheRunsEndIsKeptApart) {
  using D = DriveStateCode;
  DriveHistory h;
  h.add(0.1, {D::running, D::running, D::running, D::running});
  h.add(0.2, {D::running, D::running, D::running, D::waiting});
  h.add(0.3, {D::waiting, D::waiting, D::waiting, D::waiting}, false);
  const auto j = h.to_json();
  EXPECT_EQ(j.at("running_at_end"), 0);
  EXPECT_EQ(j.at("running_at_duration"), 3);
  EXPECT_DOUBLE_EQ(j.at("stopped_at_s").get<double>(), 0.3);
}

}  // namespace
}  // namespace omnitwin::twin
