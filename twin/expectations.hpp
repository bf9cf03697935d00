// twin layer — scenario expectations: bounds on metrics.json, checked after a run.
//
// The scenario loader validates expectation paths against is_known_metric() (so a typo
// fails before the run, not after), and the orchestrator calls evaluate_expectations() on
// the assembled metrics.json. Failures are plain sentences for the console, metrics.json
// (`expectations.failures`) and JUnit. Not real-time safe; used before and after runs.
#pragma once

#include <nlohmann/json.hpp>

#include <string>
#include <string_view>
#include <vector>

#include "twin/scenario.hpp"

namespace omnitwin::twin {

// True if `path` (dotted, e.g. "platform.final_error_cm", "axes.2.iae_velocity_pulse")
// names a metric that metrics.json carries. The one list of known metric paths.
bool is_known_metric(std::string_view path);

struct ExpectationResult {
  bool passed = true;
  std::vector<std::string> failures;  // e.g. "platform.final_error_cm = 0.73 > max 0.5"

  // {"passed": bool, "failures": [...]}
  nlohmann::json to_json() const;
};

// Looks up each expectation's metric in `metrics` (dotted path; numeric components index
// arrays) and checks its bounds. A missing or non-numeric metric is a failure.
ExpectationResult evaluate_expectations(const std::vector<Expectation>& expectations,
                                        const nlohmann::json& metrics);

// The value at a dotted path, or nullptr if there is none.
const nlohmann::json* find_metric(const nlohmann::json& metrics, std::string_view path);

// Splits a dotted path ("a.b.0.c") into its components (views into `path`). Used for
// metric paths and for --set keys alike.
std::vector<std::string_view> split_dots(std::string_view path);

}  // namespace omnitwin::twin
