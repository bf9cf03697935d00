// Test support — a GoogleTest fixture that fails a test on any MuJoCo warning.
//
// MuJoCo reports warnings through the process-wide mju_user_warning hook (and counts them
// in mjData::warning). The fixture installs a hook that records every message, and after
// each test fails it if anything was recorded (ReportWarnings), so a model that goes
// unstable, runs out of contacts or hits a bad value never passes silently. Tests that step
// their own mjData can also call ExpectNoWarnings(d) to check the per-data counters.
// tests/physics/mujoco_fixture_test.cpp shows both fail on a real MuJoCo warning.
#pragma once

#include <gtest/gtest.h>
#include <mujoco/mujoco.h>

#include <string>
#include <vector>

namespace omnitwin::testing {

class MujocoTest : public ::testing::Test {
 protected:
  void SetUp() override;
  void TearDown() override;

  // Fails the current test if d counted any warning since it was made or reset.
  static void ExpectNoWarnings(const mjData* d);

  // Adds one non-fatal failure "MuJoCo warning: <message>" per message the hook recorded,
  // then forgets them. TearDown calls it; a test may call it earlier.
  static void ReportWarnings();

  // Messages recorded by the hook during this test.
  static const std::vector<std::string>& warnings();
};

// Path of a file under the source tree (e.g. "models/platform/omni4.yaml").
std::string source_path(const std::string& relative);
// Path of a file under the build tree (e.g. "omnitwin" for the CLI binary).
std::string binary_path(const std::string& relative);

}  // namespace omnitwin::testing
