// Tests the test-support fixture tests/support/mujoco_fixture (MujocoTest): a real MuJoCo
// warning, raised by MuJoCo itself through mju_user_warning while stepping, is recorded and
// turned into a test failure by ReportWarnings (what TearDown runs), and ExpectNoWarnings
// fails on the mjData that counted it; the same model with room to spare raises nothing.
// The trigger is a box dropped onto a plane with a contact buffer of one (nconmax="1"):
// box–plane collision yields up to four contacts, so MuJoCo 2.2.2 warns "contact buffer is
// full" (mjWARN_CONTACTFULL) — and nothing else, so each check sees exactly one failure.
#include <gtest/gtest-spi.h>
#include <gtest/gtest.h>
#include <unistd.h>
#include <mujoco/mujoco.h>

#include <array>
#include <fstream>
#include <memory>
#include <string>

#include "physics/platform_sim.hpp"
#include "tests/support/mujoco_fixture.hpp"
#include "tests/support/temp_dir.hpp"

namespace omnitwin::testing {
namespace {

using physics::DataPtr;
using physics::ModelPtr;

// A 10 cm box dropped from 20 cm onto a plane; `size_tag` goes inside <mujoco>.
std::string box_on_plane(const std::string& size_tag) {
  return "<mujoco>\n" + size_tag +
         "\n  <worldbody>\n"
         "    <geom name=\"floor\" type=\"plane\" size=\"1 1 0.1\"/>\n"
         "    <body name=\"box\" pos=\"0 0 0.2\">\n"
         "      <freejoint/>\n"
         "      <geom type=\"box\" size=\"0.05 0.05 0.05\" mass=\"1\"/>\n"
         "    </body>\n"
         "  </worldbody>\n"
         "</mujoco>\n";
}

// Loads `xml` through a file in a private temp directory (removed on return); fails the test
// (and returns null) if it does not compile.
ModelPtr load(const std::string& xml, const std::string& name) {
  const TempDir dir("omnitwin-fixture");
  const std::string path = dir / name;
  std::ofstream(path) << xml;
  std::array<char, 1000> err{};
  ModelPtr m(mj_loadXML(path.c_str(), nullptr, err.data(), static_cast<int>(err.size())));
  EXPECT_NE(m, nullptr) << err.data();
  return m;
}

// Steps 1 s (the box lands after ~0.2 s and rests on the plane).
void drop(const mjModel* m, mjData* d) {
  while (d->time < 1.0) mj_step(m, d);
}

using MujocoFixture = MujocoTest;

TEST_F(MujocoFixture, RealContactBufferOverflowFailsTheTest) {
  // A real MuJoCo warning (contact buffer full) reaches the hook, ReportWarnings turns it into
  // exactly one "MuJoCo warning" failure and forgets it, and ExpectNoWarnings fails on the
  // mjData that counted it.
  const ModelPtr m = load(box_on_plane("  <size nconmax=\"1\"/>"), "fixture_box_nconmax1.xml");
  ASSERT_NE(m, nullptr);
  const DataPtr d(mj_makeData(m.get()));
  ASSERT_NE(d, nullptr);
  drop(m.get(), d.get());
  // MuJoCo itself raised it, through mju_user_warning, once per kind.
  EXPECT_GT(d->warning[mjWARN_CONTACTFULL].number, 0);
  ASSERT_EQ(warnings().size(), 1u);
  EXPECT_NE(warnings()[0].find("contact"), std::string::npos) << warnings()[0];
  // The fixture fails the test on it; the failure text names it as a MuJoCo warning.
  EXPECT_NONFATAL_FAILURE(ReportWarnings(), "MuJoCo warning");
  EXPECT_TRUE(warnings().empty()) << "ReportWarnings must forget what it reported";
  EXPECT_NONFATAL_FAILURE(ExpectNoWarnings(d.get()), "MuJoCo warning");
}

TEST_F(MujocoFixture, SameModelWithRoomRaisesNothing) {
  // Control for the test above: with the default contact buffer the same drop raises no
  // warning, so ReportWarnings and ExpectNoWarnings pass (they do not fail unconditionally).
  const ModelPtr m = load(box_on_plane(""), "fixture_box_default.xml");
  ASSERT_NE(m, nullptr);
  const DataPtr d(mj_makeData(m.get()));
  ASSERT_NE(d, nullptr);
  drop(m.get(), d.get());
  EXPECT_GT(d->ncon, 1) << "the box must rest on several contacts";
  EXPECT_TRUE(warnings().empty());
  ReportWarnings();
  ExpectNoWarnings(d.get());
}

}  // namespace
}  // namespace omnitwin::testing
