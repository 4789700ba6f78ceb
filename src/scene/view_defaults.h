// What a scene gets when its file leaves something out, so that it renders visibly with no
// options: a camera framing it (honouring the file's up axis) and a headlight when it has no lights.
#pragma once

#include "core/camera.h"
#include "scene/scene.h"

namespace mobirt {

// A camera framing the scene's bounds as frame_box (core/camera.h) does for +Y up, turned by the
// shortest rotation that takes +Y onto Scene::up: the same view for +Y scenes, and a Z-up scene
// (NFF's `v` up 0 0 1) seen upright from its front-above instead of from above.
Camera framing_camera(const Scene& scene, float aspect, float yfov = 0.7854f);

// The scene's own camera, else framing_camera(scene, aspect).
Camera default_camera(const Scene& scene, float aspect);

// A scene without lights gets a headlight: a white point light at view.eye whose intensity is the
// squared distance from the eye to view.target, so that it lights what the camera looks at with
// irradiance 1 (as a directional light of intensity 1 would). Returns whether it added one; a
// scene with lights is left as it is. Silent: the caller prints note_headlight once the frame is
// made, so that an error later on is still the only line a failed run prints.
bool add_headlight(Scene& scene, const Camera& view);

// Prints "mobirt: note: FILE: the scene has no lights: a headlight at the camera lit it (--light
// gives others)" on stderr.
void note_headlight(const Scene& scene);

}  // namespace mobirt
