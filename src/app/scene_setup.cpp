#include "app/scene_setup.h"

#include <utility>

#include "scene/overrides.h"
#include "scene/view_defaults.h"

namespace mobirt {

void apply_file_image_size(const AnimatedScene& animation, bool size_given, RenderSettings& settings) {
  const Scene& rest = animation.rest();
  if (size_given || !rest.image_size) return;
  settings.width = rest.image_size->x;
  settings.height = rest.image_size->y;
}

PosedScene::PosedScene(const AnimatedScene& animation, SceneEdits edits, int width, int height)
    : scene(animation.rest()),
      animation_(animation),
      edits_(std::move(edits)),
      fallback_(framing_camera(scene, float(width) / float(height))) {}

Camera PosedScene::at(double seconds) {
  if (animation_.animated()) animation_.evaluate(seconds, scene);
  apply_overrides(scene, edits_.lights, edits_.camera);
  if (edits_.background) scene.background = *edits_.background;
  const Camera view = scene.camera ? *scene.camera : fallback_;
  // The headlight follows an animated camera: it is the one light of a scene that had none.
  if (headlit_) {
    scene.lights.clear();
  }
  headlit_ = add_headlight(scene, view) || headlit_;
  return view;
}

}  // namespace mobirt
