// Test support — see mujoco_fixture.hpp.
#include "tests/support/mujoco_fixture.hpp"

namespace omnitwin::testing {
namespace {

std::vector<std::string>& recorded() {
  static std::vector<std::string> messages;
  return messages;
}

void record_warning(const char* msg) { recorded().emplace_back(msg ? msg : "(null)"); }

}  // namespace

void MujocoTest::SetUp() {
  recorded().clear();
  mju_user_warning = record_warning;
}

void MujocoTest::TearDown() {
  mju_user_warning = nullptr;
  ReportWarnings();
}

void MujocoTest::ReportWarnings() {
  for (const auto& m : recorded()) ADD_FAILURE() << "MuJoCo warning: " << m;
  recorded().clear();
}

void MujocoTest::ExpectNoWarnings(const mjData* d) {
  ASSERT_NE(d, nullptr);
  for (int i = 0; i < mjNWARNING; ++i) {
    EXPECT_EQ(d->warning[i].number, 0)
        << "MuJoCo warning #" << i << " counted " << d->warning[i].number
        << " times (last info " << d->warning[i].lastinfo << ")";
  }
}

const std::vector<std::string>& MujocoTest::warnings() { return recorded(); }

std::string source_path(const std::string& relative) {
  return std::string(OMNITWIN_SOURCE_DIR) + "/" + relative;
}

std::string binary_path(const std::string& relative) {
  return std::string(OMNITWIN_BINARY_DIR) + "/" + relative;
}

}  // namespace omnitwin::testing
