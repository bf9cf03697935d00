// Tests the EGL backend of media/offscreen_gl: a frame of the platform rendered through EGL
// (Mesa's surfaceless platform here, llvmpipe; a GPU device elsewhere) is not blank and
// matches the OSMesa frame of the same state closely; backend names and OMNITWIN_GL parse;
// and the two backends refuse to share a process.
//
// MuJoCo binds its GL calls once per process (offscreen_gl.hpp), so the EGL frame is made
// by a child process: this binary re-run with a filter selecting EglChild.RenderFrame and
// OMNITWIN_EGL_CHILD_OUT naming the file for the pixels. Run directly (no such variable),
// that test skips, so `media_tests` run as one process never loads libEGL.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "media/offscreen_gl.hpp"
#include "media/run_video.hpp"
#include "media/scene_render.hpp"
#include "physics/platform_mjcf.hpp"
#include "tests/support/mujoco_fixture.hpp"
#include "tests/support/temp_dir.hpp"

namespace omnitwin::media {
namespace {

using Image = std::vector<unsigned char>;
constexpr int kW = 320, kH = 240;
constexpr const char* kChildVar = "OMNITWIN_EGL_CHILD_OUT";

physics::ModelPtr platform_model() {
  omnitwin::testing::TempDir dir("omnitwin-egl");
  const auto path = (dir / "model.xml").string();
  std::ofstream(path) << physics::platform_mjcf(physics::PlatformParams{});
  char err[1024] = "";
  physics::ModelPtr m(mj_loadXML(path.c_str(), nullptr, err, sizeof err));
  if (!m) ADD_FAILURE() << err;
  return m;
}

// The same frame for both backends: track camera, inset, overlay, a trace.
Image render_frame(GlBackend backend, std::string* description = nullptr) {
  SceneRenderer r(platform_model(), SceneOptions{.width = kW, .height = kH, .backend = backend});
  if (description) *description = r.gl_description();
  static const std::vector<PathPoint> trace{{0, 0}, {0.3, 0.1}, {0.6, 0.3}};
  r.set_reference_path(trace);
  FrameState s;
  s.t = 2.5;
  s.x = 0.6;
  s.y = 0.3;
  s.phi = 0.4;
  s.speed = 0.25;
  s.trace = trace;
  return r.render(s);
}

double mean_abs_diff(const Image& a, const Image& b) {
  double sum = 0;
  for (size_t i = 0; i < a.size(); ++i) sum += std::abs(a[i] - b[i]);
  return sum / static_cast<double>(a.size());
}

int distinct_colours(const Image& img) {
  std::set<int> colours;
  for (size_t i = 0; i + 2 < img.size(); i += 3) colours.insert(img[i] << 16 | img[i + 1] << 8 | img[i + 2]);
  return static_cast<int>(colours.size());
}

// Runs this test binary again with only `test` selected and env_assignment set; returns
// its exit status (-1 if it did not exit normally).
int run_child(const std::string& test, const std::string& env_assignment) {
  const auto self = std::filesystem::read_symlink("/proc/self/exe").string();
  const std::string cmd = env_assignment + " '" + self + "' --gtest_filter=" + test;
  const int status = std::system(cmd.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// Child side: renders the frame with EGL and writes its pixels (and the GL description
// on a second file) for the parent. Skipped unless run as a child.
TEST(EglChild, RenderFrame) {
  const char* out = std::getenv(kChildVar);
  if (!out) GTEST_SKIP() << "run by EglRender.FrameMatchesOsmesa in a process of its own";
  std::string description;
  const Image img = render_frame(GlBackend::egl, &description);
  std::ofstream(out, std::ios::binary).write(reinterpret_cast<const char*>(img.data()),
                                             static_cast<std::streamsize>(img.size()));
  std::ofstream(std::string(out) + ".txt") << description;
  // Now libEGL is in the process: OSMesa must refuse clearly rather than misrender.
  try {
    make_offscreen_gl(8, 8, GlBackend::osmesa);
    ADD_FAILURE() << "OSMesa accepted a process with libEGL loaded";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("eglGetProcAddress"), std::string::npos) << e.what();
  }
}

class EglRender : public omnitwin::testing::MujocoTest {};

TEST_F(EglRender, FrameIsNotBlankAndMatchesOsmesa) {
  omnitwin::testing::TempDir dir("omnitwin-egl");
  const auto out = (dir / "egl.rgb").string();
  ASSERT_EQ(run_child("EglChild.RenderFrame", std::string(kChildVar) + "='" + out + "'"), 0);
  std::ifstream in(out, std::ios::binary);
  const Image egl((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_EQ(egl.size(), static_cast<size_t>(kW) * kH * 3);
  std::ifstream desc_in(out + ".txt");
  const std::string desc((std::istreambuf_iterator<char>(desc_in)), std::istreambuf_iterator<char>());
  EXPECT_NE(desc.find("EGL"), std::string::npos) << desc;
  std::cout << "EGL renderer: " << desc << "\n";

  EXPECT_GT(distinct_colours(egl), 100) << "the EGL frame is (nearly) blank";
  const Image osmesa = render_frame(GlBackend::osmesa);
  const double mad = mean_abs_diff(egl, osmesa);
  std::cout << "mean |EGL - OSMesa| per channel: " << mad << "\n";
  // Both are llvmpipe here, so nearly identical; on an NVIDIA H200 the difference was 0.16
  // (docs/benchmarks.md, "Off-screen rendering on a GPU").
  EXPECT_LT(mad, 3.0);
}

TEST_F(EglRender, RefusedInAProcessThatUsedOsmesa) {
  (void)make_offscreen_gl(8, 8, GlBackend::osmesa);
  try {
    make_offscreen_gl(8, 8, GlBackend::egl);
    ADD_FAILURE() << "EGL accepted a process that already used OSMesa";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("OSMesa context was already made"), std::string::npos) << e.what();
  }
}

TEST(GlBackendNames, ParseAndEnvironment) {
  EXPECT_EQ(gl_backend_from_name("osmesa"), GlBackend::osmesa);
  EXPECT_EQ(gl_backend_from_name("egl"), GlBackend::egl);
  EXPECT_STREQ(gl_backend_name(GlBackend::egl), "egl");
  EXPECT_STREQ(gl_backend_name(GlBackend::osmesa), "osmesa");
  EXPECT_THROW(gl_backend_from_name("vulkan"), std::invalid_argument);

  const char* saved = std::getenv("OMNITWIN_GL");
  const std::string saved_value = saved ? saved : "";
  ::unsetenv("OMNITWIN_GL");
  EXPECT_EQ(gl_backend_from_env(), GlBackend::osmesa);
  ::setenv("OMNITWIN_GL", "egl", 1);
  EXPECT_EQ(gl_backend_from_env(), GlBackend::egl);
  ::setenv("OMNITWIN_GL", "glx", 1);
  EXPECT_THROW(gl_backend_from_env(), std::invalid_argument);
  if (saved) ::setenv("OMNITWIN_GL", saved_value.c_str(), 1); else ::unsetenv("OMNITWIN_GL");
}

TEST(GlBackendNames, UnknownVideoBackendIsAnOptionError) {
  VideoOptions o;
  o.backend = "vulkan";
  EXPECT_THROW(render_run("/nonexistent-run", "/nonexistent/out.mp4", o), std::invalid_argument);
}

}  // namespace
}  // namespace omnitwin::media
