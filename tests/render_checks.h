// Checks of the whole renderer that hold on every backend.
#pragma once

#include <gtest/gtest.h>

#include "backend/backend.h"
#include "core/image.h"
#include "render/cpu_render.h"
#include "render/renderer.h"
#include "scene/loader.h"
#include "test_scenes.h"

namespace mobirt::test {

// A loop cap too small for the scene costs time, never pixels: capped rays come back flagged and
// the CPU traces them, so the image of a random soup of `triangles` equals the one rendered with a
// generous cap.
inline void expect_capped_rays_traced_on_the_cpu(Backend& backend, int triangles, int width, int height) {
  const Scene scene = random_soup_scene(triangles);
  RenderSettings tight;
  tight.width = width;
  tight.height = height;
  tight.max_steps = 24;
  RenderSettings loose = tight;
  loose.max_steps = 100000;
  FrameTimings t_tight, t_loose;
  Renderer r_tight(backend, tight);
  const Image a = r_tight.render(scene, *scene.camera, &t_tight);
  Renderer r_loose(backend, loose);
  const Image b = r_loose.render(scene, *scene.camera, &t_loose);
  EXPECT_GT(t_tight.sum.capped, 0u);
  EXPECT_EQ(t_loose.sum.capped, 0u);
  EXPECT_EQ(compare_images(a, b, 0.5f / 255.0f).max_error, 0.0) << "capped rays changed the image";
}

// The project's default scene at 200x120 rendered on `backend` and on the CPU (the expectation).
struct DefaultSceneImages {
  Image gpu, cpu;
};
inline DefaultSceneImages render_default_scene(Backend& backend, FrameTimings* timings = nullptr) {
  const Scene scene = load_scene(MOBIRT_SOURCE_DIR "/scenes/default.gltf");
  RenderSettings settings;
  settings.width = 200;
  settings.height = 120;
  Renderer renderer(backend, settings);
  DefaultSceneImages images;
  images.gpu = renderer.render(scene, *scene.camera, timings);
  images.cpu = render_on_cpu(scene, *scene.camera, settings);
  return images;
}

}  // namespace mobirt::test
