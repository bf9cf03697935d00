// controller programs — CLI11 checks shared by omni-master, omni-pc and omni-tml.
#pragma once

#include <CLI/CLI.hpp>

#include <string>

#include "controller/program_support.hpp"

namespace omnitwin::controller {

// A time option (seconds or milliseconds): a finite number in [0, max]. CLI::NonNegativeNumber
// let NaN through (a run until a signal), printed DBL_MAX in full, and took values whose ns
// deadlines overflow int64 (a run that ended at once) — found in review.
inline CLI::Validator time_check(double max) {
  return CLI::Validator([max](std::string& s) { return time_value_problem(s, max); }, "0..MAX", "TIME");
}

}  // namespace omnitwin::controller
