// physics layer — MJCF text of the four-omniwheel platform, generated from PlatformParams.
//
// The MuJoCo model is derived, never hand-edited: one function turns the parameter struct
// into MJCF so that the parameter file stays the single source of truth, and the committed
// models/platform/omni4_<variant>.xml are just this output for the defaults (a test keeps
// them in step). Two variants (facts/platform.md, measured on MuJoCo 2.2.2):
//  - rollers: per wheel `rows` x `per_row` passive capsule rollers on hinges along the wheel
//    tangent; omni motion comes from contact alone. Euler, Newton, pyramidal cone.
//  - capsule (the fast model): one short capsule per wheel along the axle, on the roller
//    model's effective contact line, with an explicit floor-wheel <pair> whose friction is
//    tiny along the axle and full in the rolling direction. Pyramidal cone, Newton tolerance
//    capsule.solver_tolerance; within 0.5 % of the roller model's twist (docs/platform.md).
//
// Naming contract (PlatformSim resolves these, hand-written models must follow it too):
// body "chassis" with freejoint "root"; bodies and hinge joints "wheel1".."wheel4" (axis
// radial outward, +omega rolls the hub along (sin a, -cos a)); velocity actuators
// "motor1".."motor4"; plane geom "floor" at z = 0. The chassis body origin is the platform
// centre O_m at hub height; its +x axis is X_m.
#pragma once

#include <string>

#include "physics/platform_params.hpp"

namespace omnitwin::physics {

// MJCF for p.sim.variant. Deterministic: equal parameters give byte-identical text.
// Not real-time safe (allocates); call once at set-up.
std::string platform_mjcf(const PlatformParams& p);

}  // namespace omnitwin::physics
