// Tests twin/web/web_scene: the platform model as the browser view draws it — every body and
// geom of the compiled model, the body tree, the joint roles the page poses (the free joint
// is the base, wheel1..wheel4 the wheels), colours resolved from materials as the renderer
// does, and a model that does not compile named in the error.
#include "twin/web/web_scene.hpp"

#include <gtest/gtest.h>

#include <fstream>

#include "physics/platform_params.hpp"
#include "physics/platform_sim.hpp"
#include "tests/support/mujoco_fixture.hpp"
#include "tests/support/temp_dir.hpp"

namespace omnitwin::twin {
namespace {

class WebScene : public omnitwin::testing::MujocoTest {};

TEST_F(WebScene, HoldsEveryBodyAndGeomWithTheTreeAndRoles) {
  const physics::PlatformSim sim(physics::PlatformParams{});
  const mjModel* m = sim.model();
  const nlohmann::json s = web_scene(m);
  ASSERT_EQ(s["bodies"].size(), static_cast<std::size_t>(m->nbody));
  ASSERT_EQ(s["geoms"].size(), static_cast<std::size_t>(m->ngeom));
  EXPECT_EQ(s["bodies"][0]["parent"], -1);
  int wheels = 0, bases = 0;
  for (std::size_t b = 1; b < s["bodies"].size(); ++b) {
    const auto& body = s["bodies"][b];
    EXPECT_EQ(body["parent"].get<int>(), m->body_parentid[b]);
    if (!body["joint"].is_object() || body["joint"]["role"].is_null()) continue;
    const std::string role = body["joint"]["role"];
    if (role == "base") {
      ++bases;
      EXPECT_EQ(body["joint"]["type"], "free");
      EXPECT_DOUBLE_EQ(s["base_z"].get<double>(), m->body_pos[3 * b + 2]);
    } else {
      ++wheels;
      EXPECT_EQ(body["joint"]["type"], "hinge");
      EXPECT_EQ(role, body["name"].get<std::string>());  // the generated model names them so
    }
  }
  EXPECT_EQ(bases, 1);
  EXPECT_EQ(wheels, 4);
}

TEST_F(WebScene, ResolvesMaterialColoursAsTheRendererDoes) {
  const physics::PlatformSim sim(physics::PlatformParams{});
  const mjModel* m = sim.model();
  const nlohmann::json s = web_scene(m);
  bool chassis_seen = false;
  for (int g = 0; g < m->ngeom; ++g) {
    const auto& geom = s["geoms"][g];
    ASSERT_EQ(geom["rgba"].size(), 4u);
    if (geom["name"] != "chassis") continue;
    chassis_seen = true;
    ASSERT_GE(m->geom_matid[g], 0);  // the chassis takes its colour from a material
    for (int k = 0; k < 4; ++k)
      EXPECT_FLOAT_EQ(geom["rgba"][k].get<float>(), m->mat_rgba[4 * m->geom_matid[g] + k]);
    EXPECT_EQ(geom["type"], "box");
  }
  EXPECT_TRUE(chassis_seen);
}

TEST_F(WebScene, ReadsARunDirectorysModelFileAndNamesABadOne) {
  omnitwin::testing::TempDir dir("webscene");
  std::ofstream(dir / "ok.xml") << "<mujoco><worldbody><body name=\"b\"><freejoint/>"
                                   "<geom type=\"sphere\" size=\"0.1\" rgba=\"1 0 0 1\"/></body></worldbody></mujoco>";
  const nlohmann::json s = web_scene_from_file((dir / "ok.xml").string());
  EXPECT_EQ(s["bodies"].size(), 2u);
  EXPECT_EQ(s["geoms"][0]["type"], "sphere");
  EXPECT_EQ(s["bodies"][1]["joint"]["role"], "base");
  std::ofstream(dir / "bad.xml") << "<mujoco><worldbody><geom type=\"nonsense\"/></worldbody></mujoco>";
  try {
    (void)web_scene_from_file((dir / "bad.xml").string());
    FAIL() << "a model that does not compile was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.xml"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace omnitwin::twin
