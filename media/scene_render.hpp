// media layer — one video frame of the platform: MuJoCo scene, paths, inset, overlay.
//
// SceneRenderer owns everything a frame needs, so that nothing is global: the off-screen GL
// context, a copy of the model (its offscreen buffer enlarged to the frame size), an mjData
// used only for kinematics, the mjvScene and the mjrContext. A frame is drawn from a
// recorded state, never from a running simulation: set_state() writes the pose and wheel
// angles into qpos and runs forward kinematics only (mj_kinematics, mj_comPos,
// mj_camlight), so rendering cannot disturb, or be disturbed by, the dynamics.
//
// Frame layout: the chosen camera (default "track", which follows the chassis) fills the
// frame; an overview is an inset in the top-right corner, 1/3 of the width (the model's
// "overview" camera until a reference path is set, then a camera from the same direction
// that frames the whole path);
// the reference path (blue) and the driven trace (orange) are capsules appended to the
// scene after mjv_updateScene, slightly above the floor, after simplification (each geom is
// costly in software); text at top left (mjr_overlay). Shadows and multisampling are off by
// default (SceneOptions::high_quality), which makes software frames 3-5x faster.
// Output rows are top to bottom (mjr_readPixels gives them bottom-up; they are flipped).
//
// Threading: use a renderer on the thread that made it (its GL context is current there).
// Nothing here is real-time safe; it is meant for after a run or a separate thread.
#pragma once

#include <mujoco/mujoco.h>

#include <array>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "media/offscreen_gl.hpp"
#include "physics/platform_sim.hpp"

namespace omnitwin::media {

// A point of a path on the floor, world frame [m].
struct PathPoint {
  double x, y;
};

// Everything one frame shows.
struct FrameState {
  double t = 0;                         // sim time [s]
  double x = 0, y = 0, phi = 0;         // chassis pose [m, m, rad]
  std::array<double, 4> wheel_angle{};  // wheel hinge angles, wheel1..wheel4 [rad]
  double speed = 0;                     // planar speed [m/s]
  std::string bus;                      // bus counters, one line ("" = not shown)
  std::string slaves;                   // drive states of the slaves ("" = not shown)
  std::vector<std::string> faults;      // active faults (empty = "none")
  std::span<const PathPoint> trace;     // the driven path up to t (drawn as is)
};

struct SceneOptions {
  int width = 640;                   // frame size [pixels]
  int height = 480;
  bool overview_inset = true;        // draw the "overview" camera top-right
  bool overlay = true;               // draw the text overlay top-left
  // Shadows and 4x multisampling, as the model asks for. In software (llvmpipe) they make a
  // frame 3-5x slower (tests/bench/bench_render), so they are off unless asked for.
  bool high_quality = false;
  std::string camera = "track";      // model camera filling the frame
  GlBackend backend = GlBackend::osmesa;
};

class SceneRenderer {
 public:
  // Takes ownership of a compiled model that follows the naming contract of
  // physics/platform_mjcf.hpp (body "chassis" with freejoint "root", hinges "wheel1..4",
  // cameras named in the options); only its visual settings are changed (offscreen buffer
  // size, facets, multisampling). Throws std::runtime_error naming what is missing, or if
  // the GL context or MuJoCo's offscreen buffer cannot be made. Not real-time safe.
  SceneRenderer(physics::ModelPtr model, const SceneOptions& options);
  ~SceneRenderer();
  SceneRenderer(const SceneRenderer&) = delete;
  SceneRenderer& operator=(const SceneRenderer&) = delete;

  // The reference path drawn in every following frame, simplified by simplify_path; the
  // overview inset is framed on it.
  void set_reference_path(std::span<const PathPoint> path);

  // Draws one frame (the trace capped at kMaxPathPoints by thin_path) and returns its pixels: width*height*3 bytes, RGB24, rows top to bottom.
  // The reference is valid until the next render(). Throws std::runtime_error if GL fails.
  const std::vector<unsigned char>& render(const FrameState& state);

  int width() const { return options_.width; }
  int height() const { return options_.height; }
  const mjModel* model() const { return model_.get(); }
  // Describes the GL implementation in use (vendor / renderer / version).
  std::string gl_description() const { return gl_->describe(); }

  // Most points per drawn path. Each segment is one capsule geom, and every geom costs
  // llvmpipe about 0.3 ms per view (measured), whatever its size: paths are simplified first.
  static constexpr int kMaxPathPoints = 150;
  // Largest distance [m] between a path and its simplification (simplify_path).
  static constexpr double kPathTolerance = 0.002;

 private:
  struct MjvSceneHolder;
  struct MjrContextHolder;

  void resolve_ids();
  void adapt_visual_settings();
  void make_gl_objects();
  void set_state(const FrameState& s);
  void frame_overview(std::span<const PathPoint> path);
  void draw_view(const mjrRect& rect, mjvCamera& camera, std::span<const PathPoint> trace);
  void draw_overlay(const mjrRect& rect, const FrameState& s);
  void read_frame();

  SceneOptions options_;
  std::unique_ptr<OffscreenGl> gl_;  // made first, destroyed last
  physics::ModelPtr model_;
  physics::DataPtr data_;
  std::unique_ptr<MjvSceneHolder> scene_;
  std::unique_ptr<MjrContextHolder> context_;
  mjvOption vopt_{};
  mjvPerturb perturb_{};
  mjvCamera main_cam_{}, inset_cam_{};
  int root_qpos_ = 0;
  std::array<int, 4> wheel_qpos_{};
  std::vector<PathPoint> reference_;
  std::vector<unsigned char> bottom_up_, frame_;
};

// Keeps at most max_points of path, evenly spaced by index, always keeping the last point.
std::vector<PathPoint> thin_path(std::span<const PathPoint> path, int max_points);

// Indices of the points of path that a polyline needs to stay within tolerance [m] of every
// point (Ramer-Douglas-Peucker), ascending, first and last always kept.
std::vector<size_t> simplify_path(std::span<const PathPoint> path, double tolerance);

}  // namespace omnitwin::media
