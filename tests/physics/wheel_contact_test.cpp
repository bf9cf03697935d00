// Tests physics/wheel_contact: the fast model's single centre contact per wheel. A marked
// capsule resting on the floor gives one contact at its centre (position, depth, normal and
// the axle as first tangent, as MuJoCo's own function gives for each end); an unmarked
// capsule still gets MuJoCo's two; the platform's fast model has four floor contacts at rest
// where the unmarked variant (capsule.centre_contact: false) has eight, and both compile and
// settle without a MuJoCo warning.
#include "physics/wheel_contact.hpp"

#include <gtest/gtest.h>
#include <mujoco/mujoco.h>

#include <cmath>
#include <string>

#include "physics/platform_params.hpp"
#include "physics/platform_sim.hpp"
#include "tests/support/mujoco_fixture.hpp"

namespace omnitwin::physics {
namespace {

class WheelContact : public omnitwin::testing::MujocoTest {
 protected:
  // A floor and two fixed capsules along world x, 1 mm into the floor: `a` marked, `b` not.
  static mjModel* two_capsules() {
    const std::string xml = R"(<mujoco>
  <size nuser_geom="1"/>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 0.1"/>
    <body pos="0 0 0.049"><geom name="a" type="capsule" fromto="-0.001 0 0 0.001 0 0" size="0.05" user="1"/></body>
    <body pos="1 0 0.049"><geom name="b" type="capsule" fromto="-0.001 0 0 0.001 0 0" size="0.05"/></body>
  </worldbody>
  <contact>
    <pair geom1="floor" geom2="a" condim="3" friction="0.001 0.9 0.005 0.0001 0.0001"/>
    <pair geom1="floor" geom2="b" condim="3" friction="0.001 0.9 0.005 0.0001 0.0001"/>
  </contact>
</mujoco>)";
    mjVFS vfs;
    mj_defaultVFS(&vfs);
    mj_makeEmptyFileVFS(&vfs, "two.xml", static_cast<int>(xml.size()));
    std::copy(xml.begin(), xml.end(), static_cast<char*>(vfs.filedata[mj_findFileVFS(&vfs, "two.xml")]));
    char err[512] = "";
    mjModel* m = mj_loadXML("two.xml", &vfs, err, sizeof err);
    mj_deleteVFS(&vfs);
    EXPECT_NE(m, nullptr) << err;
    return m;
  }
};

TEST_F(WheelContact, AMarkedCapsuleHasOneCentreContactAndAnUnmarkedOneMuJoCosTwo) {
  install_wheel_contact();
  install_wheel_contact();  // idempotent
  mjModel* m = two_capsules();
  ASSERT_NE(m, nullptr);
  mjData* d = mj_makeData(m);
  mj_forward(m, d);
  const int a = mj_name2id(m, mjOBJ_GEOM, "a"), b = mj_name2id(m, mjOBJ_GEOM, "b");
  int on_a = 0, on_b = 0;
  for (int i = 0; i < d->ncon; ++i) {
    const mjContact& c = d->contact[i];
    if (c.geom2 == b) ++on_b;
    if (c.geom2 != a) continue;
    ++on_a;
    EXPECT_NEAR(c.dist, -0.001, 1e-12);                 // 1 mm into the floor
    EXPECT_NEAR(c.pos[0], 0.0, 1e-12);                  // the centre, not an end
    EXPECT_NEAR(c.pos[2], -0.0005, 1e-12);              // halfway into the penetration
    EXPECT_NEAR(c.frame[2], 1.0, 1e-12);                // normal: the floor's z
    EXPECT_NEAR(std::abs(c.frame[3]), 1.0, 1e-12);      // first tangent: the axle (world x)
    EXPECT_EQ(c.dim, 3);
  }
  EXPECT_EQ(on_a, 1);
  EXPECT_EQ(on_b, 2);
  ExpectNoWarnings(d);
  mj_deleteData(d);
  mj_deleteModel(m);
}

// Floor contacts of the platform after it settled for 0.5 s with the wheels still.
int floor_contacts(bool centre) {
  PlatformParams p;
  p.sim.variant = ModelVariant::capsule;
  p.capsule.centre_contact = centre;
  PlatformSim sim(p);
  for (int i = 0; i < 500; ++i) mj_step(sim.model(), sim.data());
  EXPECT_EQ(sim.data()->warning[mjWARN_CONTACTFULL].number + sim.data()->warning[mjWARN_BADQACC].number, 0);
  return sim.data()->ncon;
}

TEST_F(WheelContact, TheFastModelRestsOnFourContactsWhereMuJoCosCapsulesGiveEight) {
  EXPECT_EQ(floor_contacts(true), 4);
  EXPECT_EQ(floor_contacts(false), 8);
}

}  // namespace
}  // namespace omnitwin::physics
