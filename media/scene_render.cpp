// media layer — SceneRenderer on MuJoCo 2.2.2's mjv/mjr API (see scene_render.hpp).
#include "media/scene_render.hpp"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>
#include <stdexcept>

namespace omnitwin::media {
namespace {

constexpr float kReferenceRgba[4] = {0.25f, 0.55f, 1.0f, 1.0f};
constexpr float kTraceRgba[4] = {1.0f, 0.55f, 0.1f, 1.0f};
// Capsule radius and height above the floor [m] of the drawn paths; the trace is thicker and
// higher, so that it stays visible where the platform follows the reference closely.
constexpr double kReferenceRadius = 0.004, kReferenceHeight = 0.004;
constexpr double kTraceRadius = 0.006, kTraceHeight = 0.007;
constexpr int kExtraGeoms = 64;        // room for MuJoCo's decor geoms
constexpr int kSlices = 16, kStacks = 8;  // most facets of round geoms (mjVisual quality)

int id_of(const mjModel* m, mjtObj type, const char* name, const char* what) {
  const int id = mj_name2id(m, type, name);
  if (id < 0) throw std::runtime_error(fmt::format("platform model has no {} \"{}\"", what, name));
  return id;
}

// A fixed camera of the model, by name.
mjvCamera fixed_camera(const mjModel* m, const std::string& name) {
  mjvCamera cam;
  mjv_defaultCamera(&cam);
  cam.type = mjCAMERA_FIXED;
  cam.fixedcamid = id_of(m, mjOBJ_CAMERA, name.c_str(), "camera");
  return cam;
}

// How a path is drawn.
struct PathStyle {
  const float* rgba;
  double radius, z;  // [m]
};
constexpr PathStyle kReferenceStyle{kReferenceRgba, kReferenceRadius, kReferenceHeight};
constexpr PathStyle kTraceStyle{kTraceRgba, kTraceRadius, kTraceHeight};

// Appends one capsule from a to b if the scene has room.
void append_segment(mjvScene& scn, const PathPoint& a, const PathPoint& b, const PathStyle& st) {
  if (scn.ngeom >= scn.maxgeom) return;
  if (std::hypot(b.x - a.x, b.y - a.y) < 1e-6) return;
  mjvGeom* g = scn.geoms + scn.ngeom;
  mjv_initGeom(g, mjGEOM_CAPSULE, nullptr, nullptr, nullptr, st.rgba);
  mjv_makeConnector(g, mjGEOM_CAPSULE, st.radius, a.x, a.y, st.z, b.x, b.y, st.z);
  g->category = mjCAT_DECOR;
  ++scn.ngeom;
}

void append_path(mjvScene& scn, std::span<const PathPoint> path, const PathStyle& st) {
  for (size_t i = 1; i < path.size(); ++i) append_segment(scn, path[i - 1], path[i], st);
}

std::string join_lines(const std::vector<std::string>& lines) {
  std::string out;
  for (const auto& l : lines) out += (out.empty() ? "" : "\n") + l;
  return out;
}

}  // namespace

// Owning holders of MuJoCo's visualisation and rendering structs (freed on destruction).
struct SceneRenderer::MjvSceneHolder {
  mjvScene scn;
  MjvSceneHolder(const mjModel* m, int maxgeom) {
    mjv_defaultScene(&scn);
    mjv_makeScene(m, &scn, maxgeom);
  }
  ~MjvSceneHolder() { mjv_freeScene(&scn); }
};

struct SceneRenderer::MjrContextHolder {
  mjrContext con;
  MjrContextHolder(const mjModel* m, int font_scale) {
    mjr_defaultContext(&con);
    mjr_makeContext(m, &con, font_scale);
  }
  ~MjrContextHolder() { mjr_freeContext(&con); }
};

std::vector<PathPoint> thin_path(std::span<const PathPoint> path, int max_points) {
  if (max_points < 2 || static_cast<int>(path.size()) <= max_points)
    return {path.begin(), path.end()};
  std::vector<PathPoint> out;
  out.reserve(max_points);
  const double step = static_cast<double>(path.size() - 1) / (max_points - 1);
  for (int i = 0; i < max_points; ++i)
    out.push_back(path[std::min(path.size() - 1, static_cast<size_t>(std::lround(i * step)))]);
  return out;
}

// Distance [m] of p from the segment a-b.
double distance_to_segment(const PathPoint& p, const PathPoint& a, const PathPoint& b) {
  const double dx = b.x - a.x, dy = b.y - a.y, len2 = dx * dx + dy * dy;
  const double u = len2 > 0 ? std::clamp(((p.x - a.x) * dx + (p.y - a.y) * dy) / len2, 0.0, 1.0) : 0.0;
  return std::hypot(p.x - a.x - u * dx, p.y - a.y - u * dy);
}

std::vector<size_t> simplify_path(std::span<const PathPoint> path, double tolerance) {
  if (path.size() < 3) {
    std::vector<size_t> all(path.size());
    for (size_t i = 0; i < all.size(); ++i) all[i] = i;
    return all;
  }
  std::vector<bool> keep(path.size(), false);
  keep.front() = keep.back() = true;
  std::vector<std::pair<size_t, size_t>> todo = {{0, path.size() - 1}};  // explicit stack
  while (!todo.empty()) {
    const auto [a, b] = todo.back();
    todo.pop_back();
    size_t worst = a;
    double worst_d = tolerance;
    for (size_t i = a + 1; i < b; ++i) {
      const double d = distance_to_segment(path[i], path[a], path[b]);
      if (d > worst_d) worst = i, worst_d = d;
    }
    if (worst == a) continue;
    keep[worst] = true;
    todo.push_back({a, worst});
    todo.push_back({worst, b});
  }
  std::vector<size_t> out;
  for (size_t i = 0; i < keep.size(); ++i)
    if (keep[i]) out.push_back(i);
  return out;
}

SceneRenderer::SceneRenderer(physics::ModelPtr model, const SceneOptions& options)
    : options_(options), model_(std::move(model)) {
  if (!model_) throw std::runtime_error("SceneRenderer: no model");
  if (options_.width < 2 || options_.height < 2)
    throw std::runtime_error(fmt::format("video frame size {}x{} is too small", options_.width, options_.height));
  resolve_ids();
  main_cam_ = fixed_camera(model_.get(), options_.camera);
  inset_cam_ = fixed_camera(model_.get(), "overview");
  adapt_visual_settings();
  data_.reset(mj_makeData(model_.get()));
  if (!data_) throw std::runtime_error("SceneRenderer: out of memory (mjData)");
  make_gl_objects();
  mjv_defaultOption(&vopt_);
  mjv_defaultPerturb(&perturb_);
  bottom_up_.resize(static_cast<size_t>(options_.width) * options_.height * 3);
  frame_.resize(bottom_up_.size());
}

// Rendering-only settings of the model copy this renderer owns.
void SceneRenderer::adapt_visual_settings() {
  mjVisual& vis = model_->vis;
  // MuJoCo renders into its own offscreen buffer, sized by the model: make it fit the frame.
  vis.global.offwidth = std::max(vis.global.offwidth, options_.width);
  vis.global.offheight = std::max(vis.global.offheight, options_.height);
  // Round geoms with fewer facets: llvmpipe's cost is mostly vertices (the rollers are many
  // small capsules), and at video sizes 16 x 8 facets look the same as MuJoCo's 28 x 16.
  vis.quality.numslices = std::min(vis.quality.numslices, kSlices);
  vis.quality.numstacks = std::min(vis.quality.numstacks, kStacks);
  if (!options_.high_quality) vis.quality.offsamples = 0;
}

// The GL context, then the scene and MuJoCo's GL resources, drawing off-screen.
void SceneRenderer::make_gl_objects() {
  gl_ = make_offscreen_gl(options_.width, options_.height, options_.backend);
  scene_ = std::make_unique<MjvSceneHolder>(model_.get(), model_->ngeom + 2 * kMaxPathPoints + kExtraGeoms);
  scene_->scn.flags[mjRND_SHADOW] = options_.high_quality;
  // The larger font from 720 rows up; below, it would cover a third of the frame.
  context_ = std::make_unique<MjrContextHolder>(
      model_.get(), options_.height >= 720 ? mjFONTSCALE_150 : mjFONTSCALE_100);
  mjr_setBuffer(mjFB_OFFSCREEN, &context_->con);
  if (context_->con.currentBuffer != mjFB_OFFSCREEN)
    throw std::runtime_error("MuJoCo's offscreen framebuffer is not available (" + gl_->describe() + ")");
}

SceneRenderer::~SceneRenderer() {
  // mjr_freeContext deletes GL objects: the context must be current while it runs.
  try {
    if (gl_) gl_->make_current();
  } catch (const std::exception&) {
    // Nothing to do: the GL objects die with the context anyway.
  }
}

void SceneRenderer::resolve_ids() {
  const mjModel* m = model_.get();
  const int root = id_of(m, mjOBJ_JOINT, "root", "freejoint");
  if (m->jnt_type[root] != mjJNT_FREE) throw std::runtime_error("platform model: joint \"root\" is not a freejoint");
  root_qpos_ = m->jnt_qposadr[root];
  for (int i = 0; i < 4; ++i) {
    const std::string name = "wheel" + std::to_string(i + 1);
    const int j = id_of(m, mjOBJ_JOINT, name.c_str(), "hinge joint");
    if (m->jnt_type[j] != mjJNT_HINGE) throw std::runtime_error("platform model: joint \"" + name + "\" is not a hinge");
    wheel_qpos_[i] = m->jnt_qposadr[j];
  }
}

void SceneRenderer::set_reference_path(std::span<const PathPoint> path) {
  std::vector<PathPoint> kept;
  for (size_t i : simplify_path(path, kPathTolerance)) kept.push_back(path[i]);
  reference_ = thin_path(kept, kMaxPathPoints);
  frame_overview(path);
}

// The inset shows the whole planned path from the model's "overview" direction: the model's
// fixed camera looks at the origin from 2.6 m and lost the platform beyond about 1.4 m, so
// on the 2 m thesis line the inset ended on an empty floor (found in review). A free camera
// at the fixed one's azimuth and elevation, aimed at the middle of the path, far enough back
// for its larger side (45° field of view) and never nearer than the fixed camera.
void SceneRenderer::frame_overview(std::span<const PathPoint> path) {
  if (path.empty()) return;
  double x0 = path[0].x, x1 = x0, y0 = path[0].y, y1 = y0;
  for (const PathPoint& p : path) x0 = std::min(x0, p.x), x1 = std::max(x1, p.x), y0 = std::min(y0, p.y), y1 = std::max(y1, p.y);
  const mjModel* m = model_.get();
  const mjtNum* pos = m->cam_pos + 3 * inset_cam_.fixedcamid;  // the fixed camera looks at the origin
  const double horizontal = std::hypot(pos[0], pos[1]), reach = std::hypot(horizontal, pos[2]);
  const double span = std::max(x1 - x0, y1 - y0) + 0.8;  // the platform's size either side
  inset_cam_.type = mjCAMERA_FREE;
  inset_cam_.lookat[0] = 0.5 * (x0 + x1);
  inset_cam_.lookat[1] = 0.5 * (y0 + y1);
  inset_cam_.lookat[2] = 0;
  inset_cam_.azimuth = std::atan2(-pos[1], -pos[0]) * 180.0 / std::numbers::pi;
  inset_cam_.elevation = -std::atan2(pos[2], horizontal) * 180.0 / std::numbers::pi;
  inset_cam_.distance = std::max(reach, 1.3 * span);
}

// Pose and wheel angles into qpos (height and tilt from qpos0), then kinematics only.
void SceneRenderer::set_state(const FrameState& s) {
  const mjModel* m = model_.get();
  mjData* d = data_.get();
  std::copy(m->qpos0, m->qpos0 + m->nq, d->qpos);
  mjtNum* q = d->qpos + root_qpos_;
  q[0] = s.x;
  q[1] = s.y;  // q[2]: the model's initial chassis height
  const mjtNum yaw[4] = {std::cos(s.phi / 2), 0, 0, std::sin(s.phi / 2)};
  mjtNum q0[4];
  mju_copy4(q0, m->qpos0 + root_qpos_ + 3);
  mju_mulQuat(q + 3, yaw, q0);
  for (int i = 0; i < 4; ++i) d->qpos[wheel_qpos_[i]] = s.wheel_angle[i];
  d->time = s.t;
  mj_kinematics(m, d);
  mj_comPos(m, d);
  mj_camlight(m, d);
}

void SceneRenderer::draw_view(const mjrRect& rect, mjvCamera& camera, std::span<const PathPoint> trace) {
  mjvScene& scn = scene_->scn;
  mjv_updateScene(model_.get(), data_.get(), &vopt_, &perturb_, &camera, mjCAT_ALL, &scn);
  append_path(scn, reference_, kReferenceStyle);
  append_path(scn, trace, kTraceStyle);
  mjr_render(rect, &scn, &context_->con);
}

void SceneRenderer::draw_overlay(const mjrRect& rect, const FrameState& s) {
  std::vector<std::string> labels = {"time", "x, y", "phi", "speed"};
  std::vector<std::string> values = {
      fmt::format("{:.2f} s", s.t), fmt::format("{:+.3f}, {:+.3f} m", s.x, s.y),
      fmt::format("{:+.1f} deg", s.phi * 180.0 / std::numbers::pi), fmt::format("{:.3f} m/s", s.speed)};
  if (!s.bus.empty()) {
    labels.emplace_back("bus");
    values.push_back(s.bus);
  }
  if (!s.slaves.empty()) {
    labels.emplace_back("slaves");
    values.push_back(s.slaves);
  }
  labels.emplace_back("faults");
  values.push_back(s.faults.empty() ? "none" : fmt::format("{}", fmt::join(s.faults, "; ")));
  mjr_overlay(mjFONT_NORMAL, mjGRID_TOPLEFT, rect, join_lines(labels).c_str(),
              join_lines(values).c_str(), &context_->con);
}

void SceneRenderer::read_frame() {
  const mjrRect full{0, 0, options_.width, options_.height};
  mjr_readPixels(bottom_up_.data(), nullptr, full, &context_->con);
  const size_t row = static_cast<size_t>(options_.width) * 3;
  for (int r = 0; r < options_.height; ++r)
    std::memcpy(frame_.data() + r * row, bottom_up_.data() + (options_.height - 1 - r) * row, row);
}

const std::vector<unsigned char>& SceneRenderer::render(const FrameState& state) {
  gl_->make_current();
  set_state(state);
  const std::vector<PathPoint> trace = thin_path(state.trace, kMaxPathPoints);
  const mjrRect full{0, 0, options_.width, options_.height};
  draw_view(full, main_cam_, trace);
  if (options_.overview_inset) {
    const int w = options_.width / 3, h = options_.height / 3, border = 2;
    const mjrRect frame{options_.width - w - 2 * border, options_.height - h - 2 * border, w + 2 * border, h + 2 * border};
    mjr_rectangle(frame, 0.9f, 0.9f, 0.9f, 1.0f);
    draw_view({frame.left + border, frame.bottom + border, w, h}, inset_cam_, trace);
  }
  if (options_.overlay) draw_overlay(full, state);
  read_frame();
  return frame_;
}

}  // namespace omnitwin::media
