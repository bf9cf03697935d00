// physics layer — the fast model's single wheel contact; see wheel_contact.hpp.
#include "physics/wheel_contact.hpp"

#include <cmath>
#include <mutex>

namespace omnitwin::physics {

namespace {

// MuJoCo's own plane–capsule function, saved when the slot is patched.
mjfCollision g_mujoco_plane_capsule = nullptr;  // written once under call_once, then read-only

bool marked(const mjModel* m, int g) {
  return m->nuser_geom > 0 && m->geom_user[g * m->nuser_geom] == kCentreContactMarker;
}

}  // namespace

void install_wheel_contact() {
  static std::once_flag once;
  std::call_once(once, [] {
    g_mujoco_plane_capsule = mjCOLLISIONFUNC[mjGEOM_PLANE][mjGEOM_CAPSULE];
    mjCOLLISIONFUNC[mjGEOM_PLANE][mjGEOM_CAPSULE] = &centre_capsule_plane;
  });
}

int centre_capsule_plane(const mjModel* m, const mjData* d, mjContact* con, int g1, int g2, mjtNum margin) {
  if (!marked(m, g2)) return g_mujoco_plane_capsule(m, d, con, g1, g2, margin);
  // The plane's normal is its z axis (row-major xmat: column 2).
  const mjtNum* pm = d->geom_xmat + 9 * g1;
  const mjtNum n[3] = {pm[2], pm[5], pm[8]};
  const mjtNum* p0 = d->geom_xpos + 3 * g1;
  const mjtNum* c = d->geom_xpos + 3 * g2;
  const mjtNum r = m->geom_size[3 * g2];
  // Signed distance of the centre sphere's surface from the plane.
  const mjtNum dist = n[0] * (c[0] - p0[0]) + n[1] * (c[1] - p0[1]) + n[2] * (c[2] - p0[2]) - r;
  if (dist > margin) return 0;
  con->dist = dist;
  for (int i = 0; i < 3; ++i) con->pos[i] = c[i] - n[i] * (r + dist / 2);
  // Frame: normal, then the axle (the capsule's z axis) projected into the plane.
  const mjtNum* gm = d->geom_xmat + 9 * g2;
  mjtNum t[3] = {gm[2], gm[5], gm[8]};
  const mjtNum an = t[0] * n[0] + t[1] * n[1] + t[2] * n[2];
  for (int i = 0; i < 3; ++i) t[i] -= an * n[i];
  const mjtNum len = std::sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
  mju_zero(con->frame, 9);
  mju_copy3(con->frame, n);
  // An upright axle has no direction in the plane: MuJoCo then makes the tangents itself.
  if (len > 1e-9)
    for (int i = 0; i < 3; ++i) con->frame[3 + i] = t[i] / len;
  return 1;
}

}  // namespace omnitwin::physics
