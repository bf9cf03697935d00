// Tests twin/nelder_mead: the bounded minimiser thesis-calibrate fits with. It finds the
// minimum of a smooth bowl inside the box, stops at the box's edge when the minimum lies
// outside (never evaluating outside), keeps to its budget, records every evaluation, and
// refuses inputs it cannot work with.
#include "twin/nelder_mead.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

namespace omnitwin::twin {
namespace {

// A stretched, tilted bowl with its minimum at `m`.
double bowl(const std::vector<double>& x, const std::vector<double>& m) {
  double s = 0;
  for (std::size_t i = 0; i < x.size(); ++i) s += (i + 1.0) * (x[i] - m[i]) * (x[i] - m[i]);
  return s + 0.5 * (x[0] - m[0]) * (x[1] - m[1]);
}

TEST(NelderMeadTest, FindsTheMinimumOfABowlInsideTheBox) {
  const std::vector<double> m{0.3, 0.7, 0.55};
  const NelderMeadResult r =
      nelder_mead([&](const auto& x) { return bowl(x, m); }, {0.9, 0.1, 0.1}, NelderMeadOptions{400, 0.25, 1e-10});
  ASSERT_EQ(r.x.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_NEAR(r.x[i], m[i], 2e-3) << i;
  EXPECT_LT(r.value, 1e-5);
  EXPECT_TRUE(r.converged);
}

TEST(NelderMeadTest, AMinimumOutsideTheBoxEndsOnItsEdgeAndNothingOutsideIsEvaluated) {
  const std::vector<double> m{1.4, -0.2};
  const NelderMeadResult r =
      nelder_mead([&](const auto& x) { return bowl(x, m); }, {0.5, 0.5}, NelderMeadOptions{300, 0.25, 1e-12});
  EXPECT_NEAR(r.x[0], 1.0, 1e-3);
  EXPECT_NEAR(r.x[1], 0.0, 0.2);  // the tilt pulls the constrained optimum a little inside
  for (const NelderMeadEvaluation& e : r.trace)
    for (double v : e.x) EXPECT_TRUE(v >= 0.0 && v <= 1.0) << v;
}

TEST(NelderMeadTest, KeepsToItsBudgetAndRecordsEveryCall) {
  int calls = 0;
  const NelderMeadResult r = nelder_mead(
      [&](const auto& x) {
        ++calls;
        return std::sin(7 * x[0]) + x[1];
      },
      {0.5, 0.5}, NelderMeadOptions{9, 0.25, 0.0});
  EXPECT_EQ(calls, 9);
  EXPECT_EQ(r.evaluations, 9);
  EXPECT_EQ(r.trace.size(), 9u);
  EXPECT_FALSE(r.converged);
  // The result is the best point it evaluated.
  for (const NelderMeadEvaluation& e : r.trace) EXPECT_GE(e.value, r.value);
}

TEST(NelderMeadTest, AStartOutsideTheBoxIsClampedIntoIt) {
  const NelderMeadResult r = nelder_mead([](const auto& x) { return x[0]; }, {3.0}, NelderMeadOptions{2, 0.25, 0.0});
  EXPECT_DOUBLE_EQ(r.trace.front().x[0], 1.0);
  EXPECT_DOUBLE_EQ(r.trace[1].x[0], 0.75);  // the first step goes backwards from the edge
}

TEST(NelderMeadTest, RefusesNoParametersAndABudgetBelowOneSimplex) {
  const auto f = [](const std::vector<double>&) { return 0.0; };
  EXPECT_THROW(nelder_mead(f, {}), std::invalid_argument);
  EXPECT_THROW(nelder_mead(f, {0.5, 0.5}, NelderMeadOptions{2, 0.25, 0.0}), std::invalid_argument);
}

}  // namespace
}  // namespace omnitwin::twin
