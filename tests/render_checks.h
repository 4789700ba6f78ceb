// Checks of the whole renderer that hold on every backend.
#pragma once

#include <gtest/gtest.h>

#include "backend/backend.h"
#include "core/image.h"
#include "render/cpu_render.h"
#include "render/renderer.h"
#include "scene/loader.h"
#include "test_scenes.h"
#include "test_support.h"

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

// A peer's frame (render_whitted() with another engine tracing) against mobirt's frame of the same
// scene and settings: within 45 dB (a difference image named after `name` is written when not), and
// the same rays traced generation by generation, within `ray_share` of them (hits that differ on
// shared edges change a few secondary rays).
inline void expect_peer_frame_matches_mobirts(const Image& want, const FrameTimings& want_t, const Image& got,
                                              const FrameTimings& got_t, const std::string& name, double ray_share) {
  const ImageDiff diff = compare_images(want, got);
  EXPECT_GE(diff.psnr, 45.0) << "max error " << diff.max_error;
  if (diff.psnr < 45.0) write_image(output_path(name + ".png").string(), difference_image(want, got));
  ASSERT_EQ(got_t.generations.size(), want_t.generations.size());
  for (size_t k = 0; k < got_t.generations.size(); ++k) {
    EXPECT_NEAR(double(got_t.generations[k].rays), double(want_t.generations[k].rays),
                ray_share * want_t.generations[k].rays + 2) << "generation " << k;
  }
  EXPECT_EQ(got_t.sum.capped, 0u);
  EXPECT_GT(got_t.sum.trace_ms, 0.0);
  EXPECT_GT(got_t.sum.shade_ms, 0.0);
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
  settings.primary = PrimaryHits::Trace;  // the same tree and hits as the CPU's
  Renderer renderer(backend, settings);
  DefaultSceneImages images;
  images.gpu = renderer.render(scene, *scene.camera, timings);
  images.cpu = render_on_cpu(scene, *scene.camera, settings);
  return images;
}

}  // namespace mobirt::test
