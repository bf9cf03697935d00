// twin/web — mjModel to the view's scene JSON (see web_scene.hpp).
#include "twin/web/web_scene.hpp"

#include "physics/mujoco_message.hpp"

#include <memory>
#include <stdexcept>

namespace omnitwin::twin {
namespace {

using nlohmann::json;

json vec(const mjtNum* v, int n) {
  json a = json::array();
  for (int i = 0; i < n; ++i) a.push_back(static_cast<double>(v[i]));
  return a;
}

json vecf(const float* v, int n) {
  json a = json::array();
  for (int i = 0; i < n; ++i) a.push_back(static_cast<double>(v[i]));
  return a;
}

const char* joint_type(int t) {
  switch (t) {
    case mjJNT_FREE: return "free";
    case mjJNT_BALL: return "ball";
    case mjJNT_SLIDE: return "slide";
    case mjJNT_HINGE: return "hinge";
  }
  return "unknown";
}

const char* geom_type(int t) {
  switch (t) {
    case mjGEOM_PLANE: return "plane";
    case mjGEOM_HFIELD: return "hfield";
    case mjGEOM_SPHERE: return "sphere";
    case mjGEOM_CAPSULE: return "capsule";
    case mjGEOM_ELLIPSOID: return "ellipsoid";
    case mjGEOM_CYLINDER: return "cylinder";
    case mjGEOM_BOX: return "box";
    case mjGEOM_MESH: return "mesh";
  }
  return "unknown";
}

std::string name_of(const mjModel* m, mjtObj type, int id) {
  const char* n = mj_id2name(m, type, id);
  return n ? n : "";
}

// A body's first joint, with the role the page poses it by (the platform's free joint is the
// base; hinge joints named wheel1..wheel4 are the wheels); null for a welded body.
json body_joint(const mjModel* m, int b) {
  if (m->body_jntnum[b] < 1) return nullptr;
  const int j = m->body_jntadr[b];
  const std::string name = name_of(m, mjOBJ_JOINT, j);
  json role = nullptr;
  if (m->jnt_type[j] == mjJNT_FREE) role = "base";
  for (int w = 1; w <= 4; ++w)
    if (m->jnt_type[j] == mjJNT_HINGE && name == "wheel" + std::to_string(w)) role = name;
  return {{"type", joint_type(m->jnt_type[j])}, {"axis", vec(m->jnt_axis + 3 * j, 3)}, {"role", role}, {"name", name}};
}

// The colour the renderer uses: the material's unless the geom sets its own.
json geom_rgba(const mjModel* m, int g) {
  const int mat = m->geom_matid[g];
  const float* own = m->geom_rgba + 4 * g;
  const bool default_rgba = own[0] == 0.5f && own[1] == 0.5f && own[2] == 0.5f && own[3] == 1.0f;
  if (mat >= 0 && default_rgba) return vecf(m->mat_rgba + 4 * mat, 4);
  return vecf(own, 4);
}

}  // namespace

json web_scene(const mjModel* m) {
  json bodies = json::array();
  double base_z = 0;
  for (int b = 0; b < m->nbody; ++b) {
    json j = body_joint(m, b);
    if (j.is_object() && j["role"] == "base") base_z = m->body_pos[3 * b + 2];
    bodies.push_back({{"name", name_of(m, mjOBJ_BODY, b)},
                      {"parent", b == 0 ? -1 : m->body_parentid[b]},
                      {"pos", vec(m->body_pos + 3 * b, 3)},
                      {"quat", vec(m->body_quat + 4 * b, 4)},
                      {"joint", std::move(j)}});
  }
  json geoms = json::array();
  for (int g = 0; g < m->ngeom; ++g) {
    geoms.push_back({{"name", name_of(m, mjOBJ_GEOM, g)},
                     {"body", m->geom_bodyid[g]},
                     {"type", geom_type(m->geom_type[g])},
                     {"size", vec(m->geom_size + 3 * g, 3)},
                     {"pos", vec(m->geom_pos + 3 * g, 3)},
                     {"quat", vec(m->geom_quat + 4 * g, 4)},
                     {"rgba", geom_rgba(m, g)},
                     {"group", m->geom_group[g]}});
  }
  return {{"bodies", std::move(bodies)}, {"geoms", std::move(geoms)}, {"base_z", base_z}};
}

json web_scene_from_file(const std::string& mjcf_path) {
  char error[1000] = "";
  std::unique_ptr<mjModel, void (*)(mjModel*)> m(mj_loadXML(mjcf_path.c_str(), nullptr, error, sizeof error),
                                                 mj_deleteModel);
  if (!m) throw std::runtime_error("cannot compile " + mjcf_path + ": " + physics::one_line(error));
  return web_scene(m.get());
}

}  // namespace omnitwin::twin
