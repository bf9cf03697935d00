// twin/web — the platform's MuJoCo model as the browser view draws it: the body tree, each
// body's joint and the geoms with their resolved colours, from the compiled mjModel, so that
// the page shows the same model and colours as the video (media/scene_render) without parsing
// MJCF in JavaScript. The page poses it from a run's samples: the free joint's body ("base")
// at (x, y, base_z) turned by phi, hinge joints "wheel1".."wheel4" by the wheel angles.
// Not real-time code; called once per view.
#pragma once

#include <string>

#include <mujoco/mujoco.h>
#include <nlohmann/json.hpp>

namespace omnitwin::twin {

// The scene of a compiled model (docs/web-view.md, "GET /api/scene"). Units: m, quaternions
// (w, x, y, z) relative to the parent body, as in mjModel.
nlohmann::json web_scene(const mjModel* m);

// The scene of an MJCF file (a run directory's platform.xml). Throws std::runtime_error with
// MuJoCo's message when the file does not compile.
nlohmann::json web_scene_from_file(const std::string& mjcf_path);

}  // namespace omnitwin::twin
