// physics layer — the fast model's wheel contact: one contact per wheel where MuJoCo's
// plane–capsule test makes two.
//
// The fast model's wheel is a 1 mm capsule (platform_mjcf). MuJoCo collides a capsule with a
// plane as two spheres, one at each end, so each wheel gives two contacts 1 mm apart: eight
// contacts and 32 pyramid rows for four wheels, and the second contact of a wheel flickers in
// and out as the chassis tilts by micro-radians, which the Newton solver pays for in Hessian
// updates. A capsule marked by its geom user value (kCentreContactMarker in user[0]) is
// collided here instead as ONE sphere at its centre, with MuJoCo's own conventions: normal
// along the plane's z, first tangent along the capsule's axis (the axle: the pair's first
// friction coefficient is the lateral one), position halfway into the penetration. Every
// other capsule goes to MuJoCo's own function, so the roller model is untouched, and the MJCF
// stays a valid capsule model that plain MuJoCo runs with its two contacts.
//
// MuJoCo's collision table is one per process: install_wheel_contact() patches its plane–
// capsule slot once (idempotent, thread-safe); PlatformSim calls it before compiling any model.
#pragma once

#include <mujoco/mujoco.h>

namespace omnitwin::physics {

// user[0] of a capsule geom that collides with planes as one centre sphere (needs nuser_geom ≥ 1).
inline constexpr double kCentreContactMarker = 1.0;

// Routes plane–capsule collisions through centre_capsule_plane (once per process). Not
// real-time safe the first time (a std::call_once); call it before stepping models.
void install_wheel_contact();

// MuJoCo collision function (mjfCollision) for plane g1 and capsule g2: for a marked capsule
// at most one contact (distance [m] within `margin` [m]), else MuJoCo's own two. Real-time safe.
int centre_capsule_plane(const mjModel* m, const mjData* d, mjContact* con, int g1, int g2, mjtNum margin);

}  // namespace omnitwin::physics
