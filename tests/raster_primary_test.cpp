// --primary raster: the primary rays' closest triangles rasterized (Backend::run_raster) instead of
// traced. Per backend (Vulkan and OpenGL ES 2.0, validation on): the raster pass's index per pixel
// against the CPU traversal of the same primary rays, and whole frames against --primary trace on
// every project scene and effect level. Then what the frame skips and refuses: no kd-tree without
// shadow and secondary rays (flatten_primitives), analytic scenes traced, nothing in front of the
// camera, and the option on the command line.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "accel/closed_parts.h"
#include "accel/kdtree.h"
#include "backend/backend.h"
#include "core/error.h"
#include "raytree/mirror_planes.h"
#include "render/renderer.h"
#include "scene/loader.h"
#include "test_scenes.h"
#include "test_support.h"
#include "vulkan_fixture.h"

namespace mobirt {
namespace {

using test::Api;
using test::api_name;

class RasterPrimary : public test::PerBackendTest {};

Scene project_scene(const std::string& name) {
  return load_scene(std::string(MOBIRT_SOURCE_DIR "/scenes/") + name + ".gltf");
}

// The vertices run_raster takes: position and index + 1 per vertex.
std::vector<float> raster_vertices(const Scene& scene) {
  std::vector<float> v;
  for (size_t i = 0; i < scene.mesh.positions.size(); ++i) {
    const glm::vec3& p = scene.mesh.positions[i];
    v.insert(v.end(), {p.x, p.y, p.z, float(i / 3 + 1)});
  }
  return v;
}

// Every pixel's rasterized triangle against the CPU traversal of the ray through its centre: the
// same triangle, or one the ray meets at the same distance (a shared edge or vertex); at most 0.1 %
// of pixels otherwise. Row 0 is the image's top row on both APIs: a flipped image would miss on
// almost every pixel.
void expect_raster_matches_traversal(Backend& backend, const Scene& scene, const Camera& camera, int width,
                                     int height) {
  RasterView view{};
  ASSERT_TRUE(raster_view(camera, width, height, scene.mesh.positions, view));
  std::vector<uint32_t> texels(size_t(width) * height, 0xFFFFFFFFu);
  backend.run_raster(raster_vertices(scene), view, uint32_t(width), uint32_t(height), texels);
  const FlatKdTree tree = build_kdtree(scene.mesh.positions);
  const RayBatch rays = primary_rays(camera, width, height);
  size_t hits = 0, same = 0, ties = 0, other = 0;
  for (uint32_t i = 0; i < rays.count(); ++i) {
    ASSERT_EQ(texels[i] >> 24, 0u) << "pixel " << i << ": the raster pass writes no shadow bits";
    const int64_t raster = int64_t(texels[i] & 0xFFFFFFu) - 1;
    ASSERT_LT(raster, int64_t(scene.mesh.triangle_count())) << "pixel " << i;
    const Hit traced = traverse(tree, rays.ray(i));
    hits += traced.valid() ? 1 : 0;
    if (raster == traced.prim) {
      ++same;
      continue;
    }
    Hit h;
    if (raster >= 0 && traced.valid() && intersect_triangle(tree, int32_t(raster), rays.ray(i), h) &&
        std::abs(h.t - traced.t) <= 1e-4f * traced.t) {
      ++ties;
    } else {
      ++other;
    }
  }
  EXPECT_GT(hits, rays.count() / 4) << "the view sees the scene";
  EXPECT_LE(double(other), 0.001 * rays.count()) << same << " same, " << ties << " ties";
}

TEST_P(RasterPrimary, EachPixelHoldsTheTriangleItsPrimaryRayHitsFirst) {
  for (const char* name : {"default", "toaster", "fish", "marbles"}) {
    SCOPED_TRACE(name);
    const Scene scene = project_scene(name);
    ASSERT_TRUE(scene.camera);
    expect_raster_matches_traversal(*backend, scene, *scene.camera, 160, 96);
  }
  // Axis-aligned boxes on a grid of whole units: edges that pixel centres can land on exactly.
  const Scene boxes = test::box_grid_scene();
  SCOPED_TRACE("box grid");
  expect_raster_matches_traversal(*backend, boxes, *boxes.camera, 160, 120);
}

// The faces of closed parts turned away from the eye (faces_turned_away), left out of the primary
// raster and of the mirrored scene's (Renderer::start_raster, trace_mirrored), change no pixel's
// triangle but where a pixel's centre lies on a silhouette edge: the toaster's and the marbles'
// (their parts closed, a third to a half of their faces left out) at the bench's size, and the
// mirrored scene drawn from the eye's image in the floor.
TEST_P(RasterPrimary, FacesTurnedAwayLeaveEveryPixelsTriangle) {
  for (const char* name : {"toaster", "marbles"}) {
    SCOPED_TRACE(name);
    const Scene scene = project_scene(name);
    ASSERT_TRUE(scene.camera);
    const Camera& camera = *scene.camera;
    const int width = 400, height = 240;
    const std::vector<glm::vec3>& positions = scene.mesh.positions;
    const ClosedParts parts = find_closed_parts(positions);
    const PosedParts posed = pose_closed_parts(parts, positions);
    ASSERT_GT(parts.parts(), 0u);
    const MirrorPlanes mirrors = find_mirror_planes(scene);
    ASSERT_FALSE(mirrors.planes.empty()) << "the floor";
    MirrorPlane plane = mirrors.planes[0];
    const glm::dvec3 eye(camera.eye);
    if (glm::dot(plane.normal, eye) < plane.offset) {
      plane.normal = -plane.normal;
      plane.offset = -plane.offset;
    }
    const glm::vec3 image(eye - 2.0 * (glm::dot(plane.normal, eye) - plane.offset) * plane.normal);
    for (const bool mirrored : {false, true}) {
      SCOPED_TRACE(mirrored ? "mirrored" : "primary");
      std::vector<uint8_t> away;
      faces_turned_away(posed, positions, mirrored ? image : camera.eye, away, mirrored ? &camera.eye : nullptr);
      size_t left_out = 0;
      for (const uint8_t a : away) left_out += a;
      EXPECT_GT(left_out, scene.mesh.triangle_count() / 4);
      std::vector<float> all, drawn;
      if (mirrored) {
        mirrored_raster_vertices(positions, plane, all);
        mirrored_raster_vertices(positions, plane, drawn, away);
      } else {
        all = raster_vertices(scene);
        for (size_t t = 0; t < away.size(); ++t) {
          if (!away[t]) drawn.insert(drawn.end(), all.begin() + std::ptrdiff_t(12 * t), all.begin() + std::ptrdiff_t(12 * t + 12));
        }
      }
      EXPECT_LT(drawn.size(), all.size());
      std::vector<glm::vec3> corners(all.size() / 4);
      for (size_t k = 0; k < corners.size(); ++k) corners[k] = glm::vec3(all[4 * k], all[4 * k + 1], all[4 * k + 2]);
      RasterView view{};
      ASSERT_TRUE(raster_view(camera, width, height, corners, view));
      std::vector<uint32_t> expected(size_t(width) * height), got(expected.size());
      backend->run_raster(all, view, uint32_t(width), uint32_t(height), expected);
      backend->run_raster(drawn, view, uint32_t(width), uint32_t(height), got);
      // A pixel whose centre lies on a silhouette edge goes to one of the edge's two faces (the
      // raster's tie rule); where that was the face turned away, the pixel now shows what lies
      // behind the edge: a ray through the edge itself, at most a few pixels a frame.
      size_t differing = 0, hits = 0;
      for (size_t i = 0; i < got.size(); ++i) {
        hits += expected[i] != 0 ? 1 : 0;
        if (got[i] == expected[i]) continue;
        ++differing;
        const int64_t was = int64_t(expected[i] & 0xFFFFFFu) - 1;
        EXPECT_TRUE(was >= 0 && away[size_t(was)]) << "pixel " << i << " lost triangle " << was << ", not one left out";
      }
      EXPECT_GT(hits, 1000u);
      EXPECT_LE(differing, 4u);
    }
  }
}

// An eye outside a closed box but nearer to it than the camera's near distance: its rays start
// inside the box and meet the faces turned away from the eye, which the raster must then keep
// (faces_turned_away's reach): rasterized frames as traced ones, every pixel on the box's inside.
TEST_P(RasterPrimary, ABoxWithinTheNearDistanceKeepsItsFaces) {
  Scene scene = test::box_grid_scene();
  scene.closed_parts = std::make_shared<const ClosedParts>(find_closed_parts(scene.mesh.positions));
  ASSERT_GT(scene.closed_parts->parts(), 0u);
  Camera camera;
  camera.eye = glm::vec3(0.0f, 0.5f, 0.55f);  // 0.05 in front of the box at x, z in [-0.5, 0.5]
  camera.target = glm::vec3(0.0f, 0.5f, 0.0f);
  camera.znear = 0.1f;
  RenderSettings settings;
  settings.width = 48;
  settings.height = 32;
  settings.depth = 0;
  settings.shadows = false;
  settings.primary = PrimaryHits::Trace;
  Renderer traced(*backend, settings);
  settings.primary = PrimaryHits::Raster;
  Renderer rasterized(*backend, settings);
  const Image a = traced.render(scene, camera);
  const Image b = rasterized.render(scene, camera);
  const ImageDiff d = compare_images(a, b, 2.0f / 255.0f);
  EXPECT_LE(d.share_over, 0.005) << "share of pixels that differ by more than 2/255, max error " << d.max_error;
}

// A floor that reaches far behind the camera, a metre under it: its nearest visible point is far
// nearer than any of its vertices in front of the eye, and the near plane must not cut it off (it
// did when it sat before the nearest vertex in front). Boxes on it, and a camera whose rays start
// 0.5 along themselves.
TEST_P(RasterPrimary, AFloorReachingBehindTheCameraIsNotClipped) {
  Scene scene = test::base_scene("floor");
  test::add_triangle(scene, {-500, 0, -500}, {-500, 0, 500}, {500, 0, 500}, 0);
  test::add_triangle(scene, {-500, 0, -500}, {500, 0, 500}, {500, 0, -500}, 0);
  for (int i = 0; i < 5; ++i) test::add_box(scene, {-6.0f + 3.0f * float(i), 0, -12}, {-5.0f + 3.0f * float(i), 1.5f, -11}, 1);
  Camera camera{{0, 1, 0}, {0, 0.6f, -10}, {0, 1, 0}, 0.9f, 0.0f};
  {
    SCOPED_TRACE("znear 0");
    expect_raster_matches_traversal(*backend, scene, camera, 120, 80);
  }
  camera.znear = 0.5f;
  {
    SCOPED_TRACE("znear 0.5");
    expect_raster_matches_traversal(*backend, scene, camera, 120, 80);
  }
}

// The largest indices come back exact: GLSL ES 1.00 interpolates them (no flat varyings), in two
// 12-bit halves, so that an ulp of rounding never reaches a neighbour's index (one varying was off
// by one past 2^22, where an ulp is 0.5).
TEST_P(RasterPrimary, LargestIndicesComeBackExact) {
  // Two triangles that cover the image, 5 in front of the eye: the last triangle a scene may have
  // (kKdMaxTriangles; its index + 1) and an odd index just below 2^23.
  const float big[2] = {float(kKdMaxTriangles), float(0x7FF001)};
  const std::vector<float> vertices = {-100, -100, -5, big[0], 100, -100, -5, big[0], 100, 100, -5, big[0],
                                       -100, -100, -5, big[1], 100, 100, -5, big[1], -100, 100, -5, big[1]};
  const RasterView view{{0, 0, 0, 0}, {1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, -1, 0}, {1, 1, 1, 10}};
  std::vector<uint32_t> texels(64 * 48, 0u);
  backend->run_raster(vertices, view, 64, 48, texels);
  size_t n0 = 0, n1 = 0;
  for (uint32_t t : texels) {
    ASSERT_TRUE(t == uint32_t(big[0]) || t == uint32_t(big[1])) << std::hex << t;
    n0 += t == uint32_t(big[0]) ? 1 : 0;
    n1 += t == uint32_t(big[1]) ? 1 : 0;
  }
  EXPECT_GT(n0, 0u);
  EXPECT_GT(n1, 0u);
}

// Whole frames, --primary raster against --primary trace: the same image but for the few pixels
// whose centre lies on an edge (the two pick either triangle), at ray casting, with shadows and
// with two bounces.
TEST_P(RasterPrimary, FramesMatchTracedPrimariesOnProjectScenes) {
  for (const char* name : {"default", "toaster", "fish", "marbles"}) {
    Scene scene = project_scene(name);
    ASSERT_TRUE(scene.camera);
    // Its closed parts, as an animated scene carries them: the raster leaves out their faces
    // turned away from the eye (faces_turned_away).
    scene.closed_parts = std::make_shared<const ClosedParts>(find_closed_parts(scene.mesh.positions));
    for (const auto& [depth, shadows] : {std::pair{0, false}, std::pair{0, true}, std::pair{2, true}}) {
      const std::string what = std::string(api_name(GetParam())) + "-" + name + "-depth" + std::to_string(depth) +
                               (shadows ? "" : "-noshadows");
      SCOPED_TRACE(what);
      RenderSettings settings;
      settings.width = 120;
      settings.height = 72;
      settings.depth = depth;
      settings.shadows = shadows;
      settings.primary = PrimaryHits::Trace;
      Renderer traced(*backend, settings);
      settings.primary = PrimaryHits::Raster;
      Renderer rasterized(*backend, settings);
      FrameTimings t;
      const Image a = traced.render(scene, *scene.camera);
      const Image b = rasterized.render(scene, *scene.camera, &t);
      const ImageDiff d = compare_images(a, b, 2.0f / 255.0f);
      // At 120x72 one pixel whose centre sits on a silhouette edge, taken on the other side, costs
      // the PSNR about 44 dB alone (the toaster's): the share of such pixels is the real bound.
      EXPECT_GE(d.psnr, 38.0) << "share over 2/255 " << d.share_over << ", max error " << d.max_error;
      EXPECT_LE(d.share_over, 0.005) << "share of pixels that differ by more than 2/255";
      if (d.psnr < 38.0) write_image(test::output_path("raster-" + what + "-diff.png").string(), difference_image(a, b));
      EXPECT_EQ(t.primary_rays(), uint32_t(settings.width * settings.height));
    }
  }
}

// More than 8 lights in a general pass: the shadow pass from rasterized hits packs 16/16 as the
// traced one does; without shadows the pass is made for 8 lights and packs 24/8 as the raster does.
TEST_P(RasterPrimary, NineLightsInGeneralPasses) {
  const Scene scene = test::nine_lights_scene();
  for (bool shadows : {true, false}) {
    SCOPED_TRACE(shadows ? "shadows" : "no shadows");
    RenderSettings settings;
    settings.width = 96;
    settings.height = 64;
    settings.depth = 0;
    settings.shadows = shadows;
    settings.specialize = false;
    settings.primary = PrimaryHits::Trace;
    Renderer traced(*backend, settings);
    settings.primary = PrimaryHits::Raster;
    Renderer rasterized(*backend, settings);
    const ImageDiff d = compare_images(traced.render(scene, *scene.camera), rasterized.render(scene, *scene.camera));
    EXPECT_GE(d.psnr, 45.0);
    EXPECT_LE(d.share_over, 0.005);
  }
}

// Every triangle behind the camera: nothing is drawn, every ray misses, the background fills the
// frame. An empty vertex list draws nothing and reads back zeros.
TEST_P(RasterPrimary, NothingInFrontOfTheCamera) {
  Scene scene = test::box_grid_scene();
  scene.background = glm::vec3(0.25f, 0.5f, 0.75f);
  Camera camera = *scene.camera;
  camera.target = camera.eye + (camera.eye - camera.target);  // looking away from every box
  RasterView view{};
  EXPECT_FALSE(raster_view(camera, 32, 24, scene.mesh.positions, view));
  std::vector<uint32_t> texels(32 * 24, 7u);
  backend->run_raster({}, RasterView{{0, 0, 0, 0}, {1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, -1, 0}, {1, 1, 1, 10}}, 32, 24,
                      texels);
  for (uint32_t t : texels) ASSERT_EQ(t, 0u);

  for (int depth : {0, 2}) {
    RenderSettings settings;
    settings.width = 32;
    settings.height = 24;
    settings.depth = depth;
    settings.primary = PrimaryHits::Raster;
    Renderer renderer(*backend, settings);
    const Image image = renderer.render(scene, camera);
    for (const glm::vec3& p : image.pixels) ASSERT_LE(glm::length(p - scene.background), 2e-2f);
  }
}

// start_raster + finish_raster (the frame starts the draw before its uploads) read back what
// run_raster does, with textures created, uploaded and destroyed in between; a second start drops
// the first, a finish without a start is refused, and so is one after drop_raster.
TEST_P(RasterPrimary, AStartedRasterFinishesAsRunRasterDoes) {
  const Scene toaster = project_scene("toaster");
  const Scene boxes = test::box_grid_scene();
  const int width = 96, height = 64;
  RasterView toaster_view{}, boxes_view{};
  ASSERT_TRUE(raster_view(*toaster.camera, width, height, toaster.mesh.positions, toaster_view));
  ASSERT_TRUE(raster_view(*boxes.camera, width, height, boxes.mesh.positions, boxes_view));
  const std::vector<float> toaster_vertices = raster_vertices(toaster), boxes_vertices = raster_vertices(boxes);
  std::vector<uint32_t> expected(size_t(width) * height), got(expected.size(), 0xFFFFFFFFu);
  backend->run_raster(toaster_vertices, toaster_view, uint32_t(width), uint32_t(height), expected);

  backend->start_raster(boxes_vertices, boxes_view, uint32_t(width), uint32_t(height));  // dropped below
  backend->start_raster(toaster_vertices, toaster_view, uint32_t(width), uint32_t(height));
  const std::vector<float> texels(4 * 64 * 64, 0.5f);
  const TextureHandle texture = backend->create_texture(64, 64, TexelFormat::RGBA32F);
  backend->upload(texture, texels.data(), texels.size() * sizeof(float));
  backend->destroy(texture);
  const PassTiming timing = backend->finish_raster(got);
  EXPECT_EQ(timing.bytes_read, got.size() * 4);
  size_t hits = 0, differing = 0;
  for (size_t i = 0; i < got.size(); ++i) {
    hits += got[i] != 0 ? 1 : 0;
    differing += got[i] != expected[i] ? 1 : 0;
  }
  EXPECT_GT(hits, got.size() / 4);
  EXPECT_EQ(differing, 0u);
  try {
    backend->finish_raster(got);
    ADD_FAILURE() << "finish_raster without start_raster";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Internal);
  }
  // A started raster dropped unread (Renderer's mirror raster started ahead and not taken): nothing
  // is left to finish, a dropped nothing is nothing, and the next start and finish read back as
  // run_raster does.
  backend->start_raster(boxes_vertices, boxes_view, uint32_t(width), uint32_t(height));
  backend->drop_raster();
  backend->drop_raster();
  EXPECT_THROW(backend->finish_raster(got), Error);
  backend->start_raster(toaster_vertices, toaster_view, uint32_t(width), uint32_t(height));
  std::fill(got.begin(), got.end(), 0xFFFFFFFFu);
  backend->finish_raster(got);
  EXPECT_EQ(got, expected);
  const std::vector<std::string> messages = backend->take_debug_messages();
  EXPECT_TRUE(messages.empty()) << test::join(messages);
}

// A frame refused before its passes (17 lights: start_frame refuses it, as begin_frame would, after
// the frame pipeline handed in its tree) leaves nothing behind: the next frame, given no tree, is
// its own scene's, pixel for pixel as a fresh renderer's.
TEST_P(RasterPrimary, ARefusedFrameLeavesNoTreeBehind) {
  RenderSettings settings;
  settings.width = 64;
  settings.height = 40;
  settings.depth = 0;
  settings.primary = PrimaryHits::Raster;
  Scene refused = test::box_grid_scene();
  refused.lights.resize(17, refused.lights[0]);
  const Scene toaster = project_scene("toaster");
  Renderer renderer(*backend, settings);
  FlatKdTree tree = build_kdtree(refused.mesh.positions);
  test::expect_bad_input([&] { renderer.render(refused, *refused.camera, tree, 0.0); }, {"17 lights"});
  const Image image = renderer.render(toaster, *toaster.camera);
  Renderer fresh(*backend, settings);
  const Image expected = fresh.render(toaster, *toaster.camera);
  ASSERT_EQ(image.pixels.size(), expected.pixels.size());
  size_t differing = 0;
  for (size_t p = 0; p < image.pixels.size(); ++p) differing += image.pixels[p] != expected.pixels[p] ? 1 : 0;
  EXPECT_EQ(differing, 0u);
}

INSTANTIATE_TEST_SUITE_P(Backends, RasterPrimary, ::testing::Values(Api::Vulkan, Api::Gles), test::api_param_name);

// ---- What the frame skips and refuses ---------------------------------------------------------

TEST(RasterPrimaryFrame, WalksATreeOnlyWhereARayWalksOne) {
  const Scene boxes = test::box_grid_scene();  // two lights, no mirror or glass
  RenderSettings s;
  s.depth = 0;
  s.primary = PrimaryHits::Trace;
  EXPECT_TRUE(frame_walks_tree(boxes, s)) << "traced primaries";
  s.primary = PrimaryHits::Raster;
  EXPECT_TRUE(frame_walks_tree(boxes, s)) << "the sun's shadow rays (a directional light has no light buffer)";
  Scene key_only = boxes;
  key_only.lights.resize(1);
  EXPECT_FALSE(frame_walks_tree(key_only, s)) << "a point light's shadow rays test its light buffer";
  s.shadow_cells = 0;
  EXPECT_TRUE(frame_walks_tree(key_only, s)) << "--shadow-cells 0: they walk";
  s.shadow_cells = -1;
  s.shadow_rays.ray_test.precision = Precision::Medium;
  EXPECT_TRUE(frame_walks_tree(key_only, s)) << "auto under mediump: they walk";
  s.shadow_rays.ray_test.precision = Precision::High;
  s.shadows = false;
  EXPECT_FALSE(frame_walks_tree(boxes, s));
  s.depth = 2;
  EXPECT_FALSE(frame_walks_tree(boxes, s)) << "no material makes secondary rays";
  const Scene toaster = project_scene("toaster");  // a mirror-like toaster
  EXPECT_TRUE(frame_walks_tree(toaster, s)) << "secondary rays";
  s.depth = 0;
  EXPECT_FALSE(frame_walks_tree(toaster, s));
  const Scene shapes = test::shapes_scene();
  EXPECT_TRUE(frame_walks_tree(shapes, s)) << "analytic shapes: primaries traced";
}

// --primary auto rasterizes up to kRasterTrianglesPerPixel triangles per pixel, and past it where
// that spares a tree rebuilt every frame; analytic scenes are traced whatever it says.
TEST(RasterPrimaryFrame, AutoRasterizesWhereItPays) {
  const int w = 400, h = 240;
  const size_t limit = size_t(kRasterTrianglesPerPixel * w * h);
  EXPECT_TRUE(raster_pays(limit, w, h, false, true));
  EXPECT_FALSE(raster_pays(limit + 1, w, h, false, true)) << "a kept tree, rays that walk it";
  EXPECT_FALSE(raster_pays(limit + 1, w, h, true, true)) << "shadow rays walk the rebuilt tree anyway";
  EXPECT_FALSE(raster_pays(limit + 1, w, h, false, false)) << "a still scene keeps its tree";
  EXPECT_TRUE(raster_pays(100 * limit, w, h, true, false)) << "no tree to build every frame";

  const Scene toaster = project_scene("toaster");  // 11,102 triangles
  RenderSettings s;
  EXPECT_EQ(s.primary, PrimaryHits::Auto) << "the default";
  EXPECT_TRUE(primaries_rasterized(toaster, s)) << "400x240: 0.12 triangles per pixel";
  s.width = 100;
  s.height = 60;
  EXPECT_FALSE(primaries_rasterized(toaster, s)) << "100x60: 1.9 triangles per pixel";
  EXPECT_TRUE(frame_walks_tree(toaster, s));
  s.shadows = false;
  s.depth = 0;
  s.always_rebuild = true;
  EXPECT_TRUE(primaries_rasterized(toaster, s)) << "ray casting, the tree rebuilt every frame";
  EXPECT_FALSE(frame_walks_tree(toaster, s));
  s.always_rebuild = false;
  EXPECT_FALSE(primaries_rasterized(toaster, s)) << "ray casting, the tree kept";
  s.primary = PrimaryHits::Raster;
  EXPECT_TRUE(primaries_rasterized(toaster, s)) << "asked for";
  s.primary = PrimaryHits::Auto;
  s.width = 400;
  s.height = 240;
  EXPECT_FALSE(primaries_rasterized(test::shapes_scene(), s)) << "analytic shapes";
}

// The primitives' texels alone are the build's, and so is the box; a non-finite vertex is refused
// as the build refuses it.
TEST(RasterPrimaryFrame, FlattenedPrimitivesAreTheBuildsTexels) {
  const Scene scene = test::shapes_scene();
  const FlatKdTree built = build_kdtree(scene.mesh.positions, scene.shapes);
  FlatKdTree flat;
  flatten_primitives(flat, scene.mesh.positions, scene.shapes);
  ASSERT_EQ(flat.triangles.size(), built.triangles.size());
  for (size_t i = 0; i < flat.triangles.size(); ++i) ASSERT_EQ(flat.triangles[i], built.triangles[i]) << i;
  EXPECT_EQ(flat.bounds.lo, built.bounds.lo);
  EXPECT_EQ(flat.bounds.hi, built.bounds.hi);
  EXPECT_TRUE(flat.nodes.empty());
  EXPECT_TRUE(flat.leaf_prims.empty());

  std::vector<glm::vec3> positions = scene.mesh.positions;
  positions[4].y = std::nanf("");
  try {
    flatten_primitives(flat, positions, {});
    FAIL() << "a NaN vertex was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    EXPECT_NE(std::string(e.what()).find("triangle 1 vertex 1"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(flat.triangles.empty()) << "left empty on an error";
}

// The shapes scene's primaries are traced whatever --primary says. A frame without shadow and
// secondary rays (or with a light buffer for every shadow light) builds no tree, only the primitives' texels, kept while the triangles stay; its
// image is the traced frame's.
class RasterPrimaryVulkan : public test::VulkanTest {};

// Renderer::trace_primary (what `mobirt accuracy` compares with the reference) finds the primary
// hits as the frame does: rasterized, the same triangle and shadow bits as the traversal pass on
// all but the pixels whose centre sits on an edge.
TEST_F(RasterPrimaryVulkan, PrimaryTexelsAsTheFrameFindsThem) {
  const Scene scene = project_scene("toaster");
  RenderSettings settings;
  settings.width = 160;
  settings.height = 96;
  settings.primary = PrimaryHits::Raster;
  Renderer renderer(*backend, settings);
  const FlatKdTree tree = build_kdtree(scene.mesh.positions);
  const RayBatch rays = primary_rays(*scene.camera, settings.width, settings.height);
  const TraceResult rasterized = renderer.trace_primary(scene, *scene.camera, tree, rays);
  const TraceResult traced = renderer.trace(scene, tree, rays);
  ASSERT_EQ(rasterized.texels.size(), rays.count());
  EXPECT_GT(rasterized.timing.gpu_ms, 0.0);
  size_t same = 0;
  for (uint32_t i = 0; i < rays.count(); ++i) same += rasterized.texels[i] == traced.texels[i] ? 1 : 0;
  EXPECT_GE(double(same), 0.999 * rays.count());
}

TEST_F(RasterPrimaryVulkan, AnalyticScenesAreTracedAndStaticScenesKeepTheirTexels) {
  const Scene shapes = test::shapes_scene();
  RenderSettings settings;
  settings.width = 96;
  settings.height = 64;
  settings.primary = PrimaryHits::Trace;
  Renderer traced(*backend, settings);
  settings.primary = PrimaryHits::Raster;
  Renderer rasterized(*backend, settings);
  const ImageDiff d = compare_images(traced.render(shapes, *shapes.camera), rasterized.render(shapes, *shapes.camera));
  EXPECT_EQ(d.max_error, 0.0) << "the shapes scene's primaries are traced either way";

  // Without shadows and bounces: the first frame flattens, the second keeps what it flattened.
  const Scene toaster = project_scene("toaster");
  settings.depth = 0;
  settings.shadows = false;
  Renderer casting(*backend, settings);
  FrameTimings first, second;
  const Image a = casting.render(toaster, *toaster.camera, &first);
  const Image b = casting.render(toaster, *toaster.camera, &second);
  EXPECT_TRUE(first.tree_rebuilt);
  EXPECT_FALSE(second.tree_rebuilt);
  EXPECT_EQ(compare_images(a, b).max_error, 0.0);
  settings.primary = PrimaryHits::Trace;
  Renderer traced_casting(*backend, settings);
  EXPECT_LE(compare_images(traced_casting.render(toaster, *toaster.camera), a).share_over, 0.005)
      << "the frame without a tree against the traced one";
}

}  // namespace
}  // namespace mobirt
