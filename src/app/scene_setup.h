// The scene as every command renders it at a time t: the file's animation posed at t, then the
// command line's edits (--light, --camera, --background), and the view: the scene's camera, else
// one framing the scene at rest. render, accuracy and bench all go through PosedScene.
#pragma once

#include <optional>
#include <vector>

#include "core/camera.h"
#include "scene/animation.h"
#include "scene/scene.h"

namespace mobirt {

// What the command line changes in a scene: lights given replace the file's, a camera replaces
// the file's, a background replaces the colour of rays that miss.
struct SceneEdits {
  std::vector<Light> lights;
  std::optional<Camera> camera;
  std::optional<glm::vec3> background;
};

class PosedScene {
 public:
  // The fallback camera frames the scene at rest once, for WIDTH x HEIGHT, so that the view does
  // not jump from frame to frame. `animation` must outlive this object.
  PosedScene(const AnimatedScene& animation, SceneEdits edits, int width, int height);

  // Poses `scene` at `seconds` (a static scene stays as it is), applies the edits and returns the
  // view to render it from.
  Camera at(double seconds);

  Scene scene;

 private:
  const AnimatedScene& animation_;
  SceneEdits edits_;
  Camera fallback_;
};

}  // namespace mobirt
