#include "render/scene_features.h"

#include <sstream>

#include "layout.h"
#include "scene/atlas.h"

namespace mobirt {

namespace {
std::string seconds(double s) {
  std::ostringstream o;
  o << s;
  return o.str();
}
}  // namespace

SceneFeatures analyze_scene(const AnimatedScene& animation, const RenderSettings& settings) {
  const Scene& scene = animation.rest();
  SceneFeatures f;
  f.triangles = scene.mesh.triangle_count();
  f.shapes = scene.shapes.size();
  f.lights = int(scene.lights.size());
  f.textures = int(scene.textures.size());
  for (const Material& m : scene.materials) {
    f.reflective = f.reflective || m.reflectance > 0.0f;
    f.refractive = f.refractive || m.transmittance > 0.0f;
  }
  f.animated = animation.animated();
  f.duration = animation.duration();
  const int shadow_lights = settings.shadows ? f.lights : 0;
  f.packing = choose_packing(scene.primitive_count(), shadow_lights, scene.source);
  auto add = [&](std::string what, const std::string& why) { f.choices.push_back(what.append(": ").append(why)); };

  if (f.packing == Packing::Bits24_8) {
    add("packing 24/8", std::to_string(scene.primitive_count()) + " primitives fit 24 bits and " + std::to_string(shadow_lights) +
                            " lights fit 8 shadow bits");
  } else {
    add("packing 16/16", std::to_string(shadow_lights) + " lights need more than 8 shadow bits and " +
                             std::to_string(scene.primitive_count()) + " primitives fit 16 bits");
  }
  if (shadow_lights == 0) {
    add("traversal pass: LIGHT_COUNT 0", f.lights == 0 ? "no lights: no shadow rays at all"
                                                       : "--no-shadows: no shadow rays at all");
  } else {
    add("traversal pass: LIGHT_COUNT " + std::to_string(shadow_lights),
        "the shadow loop runs exactly the scene's lights (a constant trip count)");
  }
  add("traversal pass: STACK_DEPTH " + std::to_string(settings.stack_depth) + ", MAX_STEPS " +
          std::to_string(settings.max_steps),
      "the settings (--stack, --max-steps)");
  const RayTest& test = settings.shadow_rays.ray_test;
  const OffsetMode offset = settings.shadow_rays.offset.mode;
  add(std::string("traversal pass: INTERSECT ") +
          (test.test == IntersectTest::Watertight ? "watertight" : "mt") + ", PRECISION " +
          (test.precision == Precision::Medium ? "mediump" : "highp") + ", OFFSET_MODE " +
          (offset == OffsetMode::Fixed ? "fixed" : offset == OffsetMode::Scaled ? "scaled" : "normal-ulp"),
      "the settings (--intersect, --precision, --offset): only the chosen code is compiled");
  if (f.shapes == 0) {
    add("traversal pass: ANALYTIC 0", "triangles only: no sphere or cone code");
  } else {
    add("traversal pass: ANALYTIC 1", std::to_string(f.shapes) + " analytic spheres and cones beside " +
                                          std::to_string(f.triangles) + " triangles (--primitives analytic)");
  }
  if (settings.colour == ColourDepth::Bits16) {
    add("two shading passes per generation (COLOUR 16 high, low)", "--colour 16: 16 bits per channel");
  } else {
    add("one shading pass per generation (COLOUR 8)", "8 bits per channel");
  }
  if (f.textures == 0) {
    add("shading pass: TEXTURE_COUNT 0", "no textures: no atlas built or uploaded, no texture coordinates, "
                                         "the atlas code folds away");
  } else {
    // The page count depends on the images' sizes: the atlas is built as rendering builds it.
    const Atlas atlas = build_atlas(scene);
    const std::string pages = std::to_string(atlas.page_count());
    const std::string limit = std::to_string(atlas.tile_limit);
    add("shading pass: TEXTURE_COUNT " + std::to_string(f.textures) + ", ATLAS_PAGES " + pages,
        pages + (atlas.page_count() == 1 ? " 2048x2048 atlas page" : " 2048x2048 atlas pages") + " holding the scene's " +
            std::to_string(f.textures) + " textures, tiles up to " + limit + "x" + limit);
  }
  if (!f.reflective && !f.refractive) {
    add("one generation of rays", "no reflective or refractive material: --depth has nothing to bounce");
  } else {
    add("up to " + std::to_string(settings.depth + 1) + " generations of rays",
        std::string(f.reflective ? "mirrors" : "") + (f.reflective && f.refractive ? " and " : "") +
            (f.refractive ? "glass" : "") + ", --depth " + std::to_string(settings.depth));
  }
  if (f.animated) {
    add("kd-tree rebuilt from scratch every frame",
        "the triangles move (" + seconds(f.duration) + " s of animation)");
  } else {
    add("kd-tree built once", "a static scene: later frames keep it");
  }
  return f;
}

}  // namespace mobirt
