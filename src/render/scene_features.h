// What a scene needs, and every choice mobirt derives from it: the packing, the shader
// specialisation, which passes run and whether the kd-tree is rebuilt. `mobirt info SCENE` prints it.
#pragma once

#include <string>
#include <vector>

#include "raytree/packing.h"
#include "render/renderer.h"
#include "scene/animation.h"

namespace mobirt {

struct SceneFeatures {
  size_t triangles = 0;
  size_t shapes = 0;          // analytic spheres and cones
  int lights = 0;
  int textures = 0;
  bool reflective = false;
  bool refractive = false;
  bool animated = false;
  double duration = 0.0;      // seconds of animation
  Packing packing = Packing::Bits24_8;
  // Each choice derived from the features, as "what: why".
  std::vector<std::string> choices;
};

// Throws Error(BadInput) when the scene is over a limit (the same error rendering would give).
SceneFeatures analyze_scene(const AnimatedScene& scene, const RenderSettings& settings);

}  // namespace mobirt
