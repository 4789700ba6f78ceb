#include "app/scene_setup.h"

#include <utility>

#include "scene/overrides.h"

namespace mobirt {

PosedScene::PosedScene(const AnimatedScene& animation, SceneEdits edits, int width, int height)
    : scene(animation.rest()),
      animation_(animation),
      edits_(std::move(edits)),
      fallback_(frame_box(scene.bounds(), 0.7854f, float(width) / float(height))) {}

Camera PosedScene::at(double seconds) {
  if (animation_.animated()) animation_.evaluate(seconds, scene);
  apply_overrides(scene, edits_.lights, edits_.camera);
  if (edits_.background) scene.background = *edits_.background;
  return scene.camera ? *scene.camera : fallback_;
}

}  // namespace mobirt
