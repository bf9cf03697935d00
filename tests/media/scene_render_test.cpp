// Tests media/scene_render: frames of the generated platform model are not blank, the
// platform's pixels move with the pose, the overlay changes with sim time and nothing else
// does, the inset and the drawn paths show up where they should, the offscreen buffer is
// enlarged for frames bigger than the model asks for, and a model that breaks the naming
// contract or names no such camera is a clear error. Any MuJoCo warning fails a test.
#include "media/scene_render.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numbers>
#include <vector>

#include "physics/platform_mjcf.hpp"
#include "tests/support/mujoco_fixture.hpp"
#include "tests/support/temp_dir.hpp"

namespace omnitwin::media {
namespace {

using Image = std::vector<unsigned char>;
constexpr int kW = 160, kH = 120;

physics::ModelPtr compile(const std::string& xml) {
  omnitwin::testing::TempDir dir("omnitwin-scene");
  const auto path = (dir / "model.xml").string();
  std::ofstream(path) << xml;
  char err[1024] = "";
  physics::ModelPtr m(mj_loadXML(path.c_str(), nullptr, err, sizeof err));
  if (!m) ADD_FAILURE() << err;
  return m;
}

physics::ModelPtr platform_model() { return compile(physics::platform_mjcf(physics::PlatformParams{})); }

// Pixels (of a w-wide image) inside [x0,x1) x [y0,y1) that differ between a and b.
struct Region {
  int x0, y0, x1, y1;
};
int count_diff(const Image& a, const Image& b, Region r, int w = kW) {
  int n = 0;
  for (int y = r.y0; y < r.y1; ++y)
    for (int x = r.x0; x < r.x1; ++x) {
      const size_t i = (static_cast<size_t>(y) * w + x) * 3;
      n += std::abs(a[i] - b[i]) + std::abs(a[i + 1] - b[i + 1]) + std::abs(a[i + 2] - b[i + 2]) > 30;
    }
  return n;
}
const Region kAll{0, 0, kW, kH};

// Mean image column of the pixels that differ between a and b.
double diff_centroid_x(const Image& a, const Image& b) {
  double sum = 0;
  int n = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      if (count_diff(a, b, {x, y, x + 1, y + 1})) sum += x, ++n;
  return n ? sum / n : -1;
}

FrameState at(double x, double y, double phi, double t = 1.0) {
  FrameState s;
  s.t = t;
  s.x = x;
  s.y = y;
  s.phi = phi;
  return s;
}

class SceneRender : public omnitwin::testing::MujocoTest {
 protected:
  // A renderer of the platform from the fixed overview camera, no inset, no overlay.
  static SceneRenderer overview_only() {
    return SceneRenderer(platform_model(), SceneOptions{.width = kW, .height = kH, .overview_inset = false,
                                                        .overlay = false, .camera = "overview"});
  }
};

TEST_F(SceneRender, FrameShowsThePlatformNotABlankImage) {
  SceneRenderer r = overview_only();
  const Image with = r.render(at(0, 0, 0));
  const Image without = r.render(at(8, 8, 0));  // far outside the overview camera's view
  ASSERT_EQ(with.size(), static_cast<size_t>(kW * kH * 3));
  EXPECT_GT(count_diff(with, without, kAll), kW * kH / 100) << "platform pixels";
  EXPECT_GT(count_diff(with, Image(with.size(), with[0]), kAll), kW * kH / 2) << "a uniform frame";
}

TEST_F(SceneRender, PlatformPixelsFollowThePose) {
  SceneRenderer r = overview_only();
  const Image empty = r.render(at(8, 8, 0));
  const Image left = r.render(at(-0.3, 0, 0));
  const Image right = r.render(at(0.3, 0, 0));
  const Image turned = r.render(at(0.3, 0, 0.7));
  EXPECT_GT(count_diff(left, right, kAll), kW * kH / 50);
  // The overview camera looks along +x+y from (1.6, -1.6): world +x goes right in the image.
  EXPECT_GT(diff_centroid_x(right, empty), diff_centroid_x(left, empty) + 10);
  EXPECT_GT(count_diff(right, turned, kAll), 50) << "yaw changes the picture";
}

TEST_F(SceneRender, OverlayTextChangesWithSimTimeAndNothingElseDoes) {
  SceneRenderer r(platform_model(), SceneOptions{.width = kW, .height = kH});
  const Image a = r.render(at(0.1, 0.2, 0.3, 1.0));
  const Image b = r.render(at(0.1, 0.2, 0.3, 7.5));
  EXPECT_GT(count_diff(a, b, {0, 0, kW / 2, kH / 4}), 10) << "the time line of the overlay";
  EXPECT_EQ(count_diff(a, b, {0, kH / 2, kW, kH}), 0) << "below the overlay";
}

TEST_F(SceneRender, InsetSitsTopRightAndLeavesTheRestAlone) {
  SceneRenderer with(platform_model(), SceneOptions{.width = kW, .height = kH, .overlay = false});
  SceneRenderer without(platform_model(),
                        SceneOptions{.width = kW, .height = kH, .overview_inset = false, .overlay = false});
  const Image a = with.render(at(0, 0, 0));
  const Image b = without.render(at(0, 0, 0));
  EXPECT_GT(count_diff(a, b, {kW - kW / 3, 0, kW, kH / 3}), kW * kH / 9 / 4) << "inset area";
  EXPECT_EQ(count_diff(a, b, {0, kH / 2, kW / 2, kH}), 0) << "bottom left";
}

TEST_F(SceneRender, ReferencePathAndTraceAreDrawnOnTheFloor) {
  SceneRenderer r = overview_only();
  const Image plain = r.render(at(8, 8, 0));
  const std::vector<PathPoint> ref = {{-0.6, -0.4}, {0.6, -0.4}, {0.6, 0.4}};
  r.set_reference_path(ref);
  const Image with_ref = r.render(at(8, 8, 0));
  EXPECT_GT(count_diff(plain, with_ref, kAll), 40);
  FrameState s = at(8, 8, 0);
  const std::vector<PathPoint> trace = {{-0.8, 0.6}, {0.8, 0.6}, {0.8, -0.6}};
  s.trace = trace;
  EXPECT_GT(count_diff(with_ref, r.render(s), kAll), 20);
}

TEST_F(SceneRender, SimplifyPathKeepsCornersAndDropsStraightRuns) {
  std::vector<PathPoint> p;
  for (int i = 0; i <= 100; ++i) p.push_back({i * 0.01, 0});           // 1 m along x
  for (int i = 1; i <= 100; ++i) p.push_back({1.0, i * 0.01});         // then 1 m along y
  p.push_back({1.0005, 1.0});                                         // a 0.5 mm wiggle
  EXPECT_EQ(simplify_path(p, 0.002), (std::vector<size_t>{0, 100, 201}));
  std::vector<PathPoint> circle;
  for (int i = 0; i <= 360; ++i) circle.push_back({std::cos(i * std::numbers::pi / 180), std::sin(i * std::numbers::pi / 180)});
  const auto kept = simplify_path(circle, 0.002);
  EXPECT_GT(kept.size(), 20u);
  EXPECT_LT(kept.size(), 100u);
  EXPECT_EQ(simplify_path(std::vector<PathPoint>{{0, 0}, {1, 1}}, 0.002).size(), 2u);
}

TEST_F(SceneRender, ThinPathKeepsEndsAndBound) {
  std::vector<PathPoint> p;
  for (int i = 0; i < 1000; ++i) p.push_back({i * 0.001, 0});
  const auto t = thin_path(p, 50);
  ASSERT_EQ(t.size(), 50u);
  EXPECT_DOUBLE_EQ(t.front().x, 0.0);
  EXPECT_DOUBLE_EQ(t.back().x, 0.999);
  EXPECT_EQ(thin_path(std::vector<PathPoint>(p.begin(), p.begin() + 10), 50).size(), 10u);
}

// The smallest model that keeps the naming contract; its offscreen buffer is the default.
constexpr const char* kTinyContractModel = R"(<mujoco>
  <worldbody>
    <geom name="floor" type="plane" size="2 2 0.1"/>
    <camera name="overview" pos="1 -1 1" xyaxes="1 1 0 -0.5 0.5 1"/>
    <body name="chassis" pos="0 0 0.1">
      <freejoint name="root"/>
      <camera name="track" mode="trackcom" pos="0 -1 0.6" xyaxes="1 0 0 0 0.5 1"/>
      <geom type="box" size="0.2 0.15 0.05" rgba="0.9 0.2 0.2 1"/>
      <body name="wheel1" pos="0.2 0.2 0"><joint name="wheel1" type="hinge"/><geom size="0.05"/></body>
      <body name="wheel2" pos="-0.2 0.2 0"><joint name="wheel2" type="hinge"/><geom size="0.05"/></body>
      <body name="wheel3" pos="-0.2 -0.2 0"><joint name="wheel3" type="hinge"/><geom size="0.05"/></body>
      <body name="wheel4" pos="0.2 -0.2 0"><joint name="wheel4" type="hinge"/><geom size="0.05"/></body>
    </body>
  </worldbody>
</mujoco>)";

TEST_F(SceneRender, FramesLargerThanTheModelsOffscreenBufferWork) {
  physics::ModelPtr m = compile(kTinyContractModel);
  ASSERT_TRUE(m);
  ASSERT_LT(m->vis.global.offwidth, 800);
  SceneRenderer r(std::move(m), SceneOptions{.width = 800, .height = 600, .overview_inset = false});
  const Image img = r.render(at(0, 0, 0));
  ASSERT_EQ(img.size(), 800u * 600u * 3u);
  // The bottom-right pixel is drawn (floor), not left black by a too-small buffer.
  const size_t last = img.size() - 3;
  EXPECT_GT(img[last] + img[last + 1] + img[last + 2], 0);
}

TEST_F(SceneRender, UnknownCameraAndBrokenContractAreClearErrors) {
  try {
    SceneRenderer r(platform_model(), SceneOptions{.width = kW, .height = kH, .camera = "nosuch"});
    FAIL() << "no error for an unknown camera";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("camera \"nosuch\""), std::string::npos) << e.what();
  }
  std::string broken = kTinyContractModel;
  const std::string joint = "<joint name=\"wheel3\"";
  broken.replace(broken.find(joint), joint.size(), "<joint name=\"axle3\"");
  try {
    SceneRenderer r(compile(broken), SceneOptions{.width = kW, .height = kH});
    FAIL() << "no error for a model without wheel3";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("\"wheel3\""), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace omnitwin::media
