// Tests physics/platform_mjcf: the generated MJCF compiles without warnings for both
// variants, is deterministic, follows the naming contract and the measured settings of
// facts/platform.md, and the committed models/platform/omni4_<variant>.xml match it.
#include "physics/platform_mjcf.hpp"

#include <gtest/gtest.h>
#include <mujoco/mujoco.h>

#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>

#include <unistd.h>

#include <cstdio>

#include "tests/support/mujoco_fixture.hpp"
#include "tests/support/temp_dir.hpp"

namespace omnitwin::physics {
namespace {

using omnitwin::testing::source_path;

class PlatformMjcf : public omnitwin::testing::MujocoTest {
 protected:
  // Compiles the generated text through a file in a private temp directory (removed on
  // return, also when the model does not compile); fails the test on errors.
  static mjModel* compile(const std::string& xml) {
    const omnitwin::testing::TempDir dir("omnitwin-mjcf");
    const std::string path = dir / "omni4.xml";
    std::ofstream(path) << xml;
    char err[1024] = "";
    mjModel* m = mj_loadXML(path.c_str(), nullptr, err, sizeof err);
    EXPECT_NE(m, nullptr) << err;
    return m;
  }

  static PlatformParams params(ModelVariant v) {
    PlatformParams p;
    p.sim.variant = v;
    return p;
  }
};

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST_F(PlatformMjcf, SameParamsGiveIdenticalText) {
  for (auto v : {ModelVariant::rollers, ModelVariant::capsule}) {
    EXPECT_EQ(platform_mjcf(params(v)), platform_mjcf(params(v)));
  }
  PlatformParams other = params(ModelVariant::rollers);
  other.geometry.L = 0.3;
  EXPECT_NE(platform_mjcf(other), platform_mjcf(params(ModelVariant::rollers)));
}

TEST_F(PlatformMjcf, RollersVariantHasTwelveRollersPerWheelAndMeasuredOptions) {
  mjModel* m = compile(platform_mjcf(params(ModelVariant::rollers)));
  ASSERT_NE(m, nullptr);
  // chassis + 4 wheels + 48 rollers (+ world); root + 4 wheels + 48 roller hinges.
  EXPECT_EQ(m->nbody, 1 + 1 + 4 + 48);
  EXPECT_EQ(m->njnt, 1 + 4 + 48);
  EXPECT_EQ(m->nu, 4);
  EXPECT_EQ(m->opt.integrator, mjINT_EULER);
  EXPECT_EQ(m->opt.solver, mjSOL_NEWTON);
  EXPECT_EQ(m->opt.cone, mjCONE_PYRAMIDAL);
  EXPECT_DOUBLE_EQ(m->opt.timestep, 0.001);
  // Total mass: chassis + 4·(hub + 12 rollers).
  double mass = 0;
  for (int b = 0; b < m->nbody; ++b) mass += m->body_mass[b];
  EXPECT_NEAR(mass, 12.0 + 4 * (0.25 + 12 * 0.01), 1e-9);
  // Roller capsule: radius 15 mm, half-length 35 mm·tan(7.5°).
  const int g = mj_name2id(m, mjOBJ_GEOM, "roller1_1_1");
  ASSERT_GE(g, 0);
  EXPECT_DOUBLE_EQ(m->geom_size[3 * g], 0.015);
  EXPECT_NEAR(m->geom_size[3 * g + 1], 0.035 * std::tan(7.5 * std::numbers::pi / 180), 1e-9);
  mj_deleteModel(m);
}

TEST_F(PlatformMjcf, OnlyRollersAndFloorCanCollide) {
  mjModel* m = compile(platform_mjcf(params(ModelVariant::rollers)));
  ASSERT_NE(m, nullptr);
  const int floor = mj_name2id(m, mjOBJ_GEOM, "floor");
  ASSERT_GE(floor, 0);
  for (int a = 0; a < m->ngeom; ++a) {
    for (int b = a + 1; b < m->ngeom; ++b) {
      const bool can = (m->geom_contype[a] & m->geom_conaffinity[b]) ||
                       (m->geom_contype[b] & m->geom_conaffinity[a]);
      if (!can) continue;
      // Every collidable pair is floor + roller.
      const int other = a == floor ? b : a;
      EXPECT_TRUE(a == floor || b == floor) << mj_id2name(m, mjOBJ_GEOM, a) << " / "
                                            << mj_id2name(m, mjOBJ_GEOM, b);
      EXPECT_EQ(std::string(mj_id2name(m, mjOBJ_GEOM, other)).rfind("roller", 0), 0u);
    }
  }
  mj_deleteModel(m);
}

TEST_F(PlatformMjcf, WheelHingesPointRadiallyOutward) {
  mjModel* m = compile(platform_mjcf(params(ModelVariant::rollers)));
  ASSERT_NE(m, nullptr);
  mjData* d = mj_makeData(m);
  mj_forward(m, d);
  for (int i = 0; i < 4; ++i) {
    const int j = mj_name2id(m, mjOBJ_JOINT, ("wheel" + std::to_string(i + 1)).c_str());
    ASSERT_GE(j, 0);
    const double a = std::numbers::pi / 4 + i * std::numbers::pi / 2;
    EXPECT_NEAR(d->xaxis[3 * j + 0], std::cos(a), 1e-9) << "wheel " << i + 1;
    EXPECT_NEAR(d->xaxis[3 * j + 1], std::sin(a), 1e-9) << "wheel " << i + 1;
    EXPECT_NEAR(d->xaxis[3 * j + 2], 0.0, 1e-9) << "wheel " << i + 1;
  }
  mj_deleteData(d);
  mj_deleteModel(m);
}

TEST_F(PlatformMjcf, CapsuleVariantUsesAnisotropicFloorPairs) {
  mjModel* m = compile(platform_mjcf(params(ModelVariant::capsule)));
  ASSERT_NE(m, nullptr);
  EXPECT_EQ(m->opt.cone, mjCONE_PYRAMIDAL);
  EXPECT_DOUBLE_EQ(m->opt.tolerance, 1e-5);
  ASSERT_EQ(m->npair, 4);
  for (int p = 0; p < 4; ++p) {
    EXPECT_EQ(m->pair_dim[p], 3);
    EXPECT_DOUBLE_EQ(m->pair_friction[5 * p + 0], 0.001);  // along the axle
    EXPECT_DOUBLE_EQ(m->pair_friction[5 * p + 1], 0.9);    // rolling direction
  }
  mj_deleteModel(m);
}

TEST_F(PlatformMjcf, FastModelContactSitsOnTheEffectiveContactLineAndIsHiddenFromCameras) {
  PlatformParams p = params(ModelVariant::capsule);
  p.capsule.half_length = 0.002;
  p.capsule.contact_offset = -0.003;
  mjModel* m = compile(platform_mjcf(p));
  ASSERT_NE(m, nullptr);
  for (int w = 1; w <= 4; ++w) {
    const int g = mj_name2id(m, mjOBJ_GEOM, ("tyre" + std::to_string(w)).c_str());
    ASSERT_GE(g, 0);
    EXPECT_EQ(m->geom_type[g], mjGEOM_CAPSULE);
    EXPECT_NEAR(m->geom_size[3 * g + 0], 0.05, 1e-12);   // the wheel radius
    EXPECT_NEAR(m->geom_size[3 * g + 1], 0.002, 1e-12);  // half-length along the axle
    EXPECT_NEAR(m->geom_pos[3 * g + 0], -0.003, 1e-12);  // wheel frame +x is the radial axle
    EXPECT_EQ(m->geom_group[g], 3);                      // MuJoCo hides group 3 by default
    // The drawn wheel: the real width, no mass, no contact.
    const int rim = mj_name2id(m, mjOBJ_GEOM, ("rim" + std::to_string(w)).c_str());
    ASSERT_GE(rim, 0);
    EXPECT_EQ(m->geom_contype[rim] | m->geom_conaffinity[rim], 0);
  }
  mj_deleteModel(m);
}

TEST_F(PlatformMjcf, SlipGainScalesFloorFriction) {
  PlatformParams p = params(ModelVariant::rollers);
  p.floor.slip_gain = 0.5;
  mjModel* m = compile(platform_mjcf(p));
  ASSERT_NE(m, nullptr);
  EXPECT_DOUBLE_EQ(m->geom_friction[3 * mj_name2id(m, mjOBJ_GEOM, "floor")], 0.45);
  EXPECT_DOUBLE_EQ(m->geom_friction[3 * mj_name2id(m, mjOBJ_GEOM, "roller3_2_4")], 0.45);
  mj_deleteModel(m);
}

TEST_F(PlatformMjcf, CommittedModelsMatchTheGenerator) {
  for (auto v : {ModelVariant::rollers, ModelVariant::capsule}) {
    const std::string rel = std::string("models/platform/omni4_") + to_string(v) + ".xml";
    EXPECT_EQ(read_file(source_path(rel)), platform_mjcf(params(v)))
        << rel << " is stale; regenerate with: omnitwin model --variant " << to_string(v)
        << " --out " << rel;
  }
}

}  // namespace
}  // namespace omnitwin::physics
