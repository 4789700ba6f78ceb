#include "render/renderer.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <iterator>
#include <map>
#include <memory>
#include <optional>
#include <tuple>
#include <type_traits>
#include <utility>

#include "accel/closed_parts.h"
#include "accel/light_buffer.h"
#include "core/error.h"
#include "core/parallel.h"
#include "layout.h"
#include "raytree/mirror_planes.h"
#include "raytree/ray_order.h"
#include "render/whitted.h"
#include "scene/atlas.h"
#include "texels.h"

namespace mobirt {

namespace {

using Clock = std::chrono::steady_clock;

constexpr uint32_t kDataWidth = MOBIRT_DATA_WIDTH;

uint32_t data_rows(size_t elements) {
  return std::max<uint32_t>(1, uint32_t((elements + kDataWidth - 1) / kDataWidth));
}

// Texels written where a pass reads them: in place where the backend maps the texture
// (Backend::begin_write: Vulkan's buffers), else into an array of its own (or the caller's `kept`,
// grown to `count` and kept from use to use), uploaded by done(). For arrays that exist only to be
// uploaded (the shading inputs, the tree's arrays with the light buffers after them): in place
// they are written once, with no copy after.
template <class T>
class TexelWriter {
  static_assert(sizeof(T) % sizeof(glm::vec4) == 0 && std::is_trivially_copyable_v<T>);

 public:
  TexelWriter(Backend& backend, TextureHandle texture, size_t count, std::vector<T>* kept = nullptr)
      : backend_(backend), texture_(texture), count_(count) {
    data_ = static_cast<T*>(backend.begin_write(texture, count * sizeof(T)));
    if (data_) return;
    if (kept) {
      if (kept->size() < count) kept->resize(count);
      data_ = kept->data();
    } else {
      own_ = std::make_unique_for_overwrite<T[]>(count);
      data_ = own_.get();
    }
    uploads_ = true;
  }
  TexelWriter(const TexelWriter&) = delete;
  TexelWriter& operator=(const TexelWriter&) = delete;

  T* data() const { return data_; }
  T& operator[](size_t i) const { return data_[i]; }
  // The first `written` texels (at most the count) made visible to the next pass.
  void done(size_t written) {
    if (!uploads_) {
      backend_.end_write(texture_);
    } else if (written > 0) {
      backend_.upload(texture_, data_, std::min(written, count_) * sizeof(T));
    }
  }
  void done() { done(count_); }

 private:
  Backend& backend_;
  TextureHandle texture_;
  size_t count_;
  bool uploads_ = false;      // not written in place: uploaded by done()
  std::unique_ptr<T[]> own_;  // where the backend has no memory to write in place and no `kept`
  T* data_ = nullptr;
};

// Writes `v` (a vec4 or a uniform struct of texels.h) from vec4 number `index` on.
template <class T>
void put(std::vector<float>& u, size_t index, const T& v) {
  static_assert(sizeof(T) % sizeof(glm::vec4) == 0 && std::is_trivially_copyable_v<T>);
  const size_t end = 4 * index + sizeof(T) / sizeof(float);
  if (u.size() < end) u.resize(end, 0.0f);
  std::memcpy(&u[4 * index], &v, sizeof(T));
}

float light_type(LightType type) {
  switch (type) {
    case LightType::Point: return float(MOBIRT_LIGHT_POINT);
    case LightType::Spot: return float(MOBIRT_LIGHT_SPOT);
    case LightType::Directional: return float(MOBIRT_LIGHT_DIRECTIONAL);
  }
  return 0.0f;
}

// Where a light is, as both passes see it: a position, or the direction towards the light.
glm::vec3 light_where(const Light& light) {
  return light.type == LightType::Directional ? -light.direction : light.position;
}

// A traversal or raster pass's cost, as a generation counts it.
void add_pass(GenerationTimings& g, const PassTiming& t) {
  g.add_trace_pass(t.upload_ms, t.gpu_ms, t.readback_ms, t.bytes_read);
}

// A pass's shader for how it reads its data: one SPIR-V module per kind (a binding's type cannot
// be specialised).
ShaderId by_data_kind(TextureKind kind, ShaderId images, ShaderId texel_buffers, ShaderId storage_buffers,
                      ShaderId device_addresses) {
  switch (kind) {
    case TextureKind::TexelBuffer: return texel_buffers;
    case TextureKind::StorageBuffer: return storage_buffers;
    case TextureKind::DeviceAddress: return device_addresses;
    case TextureKind::Image2D: break;
  }
  return images;
}

}  // namespace

std::vector<float> trace_uniforms(const FlatKdTree& tree, std::span<const Light> lights,
                                  const ShadowSettings& s, int pass_lights) {
  std::vector<float> u;
  put(u, MOBIRT_TP_BOUNDS_LO, glm::vec4(tree.bounds.lo, absolute_offset(tree.bounds, s.offset)));
  put(u, MOBIRT_TP_BOUNDS_HI, glm::vec4(tree.bounds.hi, 0.0f));
  // Slots of a general pass beyond the scene's lights never light anything.
  for (size_t l = lights.size(); l < size_t(std::max(pass_lights, 0)); ++l) {
    put(u, MOBIRT_TP_LIGHTS + MOBIRT_TP_VEC4S_PER_LIGHT * l,
        TraceLightParams{glm::vec3(0.0f), float(MOBIRT_LIGHT_NONE), glm::vec3(0.0f), 0.0f});
  }
  for (size_t l = 0; l < lights.size(); ++l) {
    const Light& light = lights[l];
    put(u, MOBIRT_TP_LIGHTS + MOBIRT_TP_VEC4S_PER_LIGHT * l,
        TraceLightParams{light_where(light), light_type(light.type), light.direction, std::cos(light.outer_cone)});
  }
  return u;
}

std::vector<float> shade_uniforms(const Scene& scene, int pass_lights) {
  std::vector<float> u;
  put(u, MOBIRT_SP_BACKGROUND, glm::vec4(scene.background, 0.0f));
  // A general pass's unused light slots: zero radiance, and their mask bits are never set.
  for (size_t l = scene.lights.size(); l < size_t(std::max(pass_lights, 0)); ++l) {
    ShadeLightParams none{};
    none.type = float(MOBIRT_LIGHT_NONE);
    put(u, MOBIRT_SP_LIGHTS + MOBIRT_SP_VEC4S_PER_LIGHT * l, none);
  }
  for (size_t l = 0; l < scene.lights.size(); ++l) {
    const Light& light = scene.lights[l];
    put(u, MOBIRT_SP_LIGHTS + MOBIRT_SP_VEC4S_PER_LIGHT * l,
        ShadeLightParams{light_where(light), light_type(light.type), light.color * light.intensity, light.range,
                         light.direction, std::cos(light.inner_cone), std::cos(light.outer_cone), {0.0f, 0.0f, 0.0f}});
  }
  return u;
}

bool device_address_reads_fault(const DeviceInfo& info) {
#if defined(__x86_64__) || defined(__i386__)
  return info.device.find("llvmpipe") != std::string::npos && __builtin_cpu_supports("avx512f");
#else
  (void)info;
  return false;
#endif
}

const char* mirror_hits_name(MirrorHits mirrors) {
  switch (mirrors) {
    case MirrorHits::Trace: return "trace";
    case MirrorHits::Raster: return "raster";
    case MirrorHits::Auto: return "auto";
  }
  return "?";
}

const char* tree_fit_name(TreeFit fit) { return fit == TreeFit::Walks ? "walks" : "full"; }
const char* shading_passes_name(ShadingPasses passes) { return passes == ShadingPasses::Frame ? "frame" : "generation"; }
const char* worker_priority_name(WorkerPriority priority) { return priority == WorkerPriority::Idle ? "idle" : "normal"; }

const char* primary_hits_name(PrimaryHits primary) {
  switch (primary) {
    case PrimaryHits::Trace: return "trace";
    case PrimaryHits::Raster: return "raster";
    case PrimaryHits::Auto: return "auto";
  }
  return "?";
}

bool raster_pays(size_t triangles, int width, int height, bool tree_per_frame, bool walks_tree) {
  if (tree_per_frame && !walks_tree) return true;
  return double(triangles) <= kRasterTrianglesPerPixel * double(width) * double(height);
}

namespace {

// Whether a frame with rasterized primaries still walks a kd-tree: its secondary rays, and shadow
// rays without light buffers.
bool rays_walk_tree(const Scene& scene, const RenderSettings& settings) {
  if (!shadow_rays_buffered(scene, settings)) return true;
  return settings.depth > 0 && scene_has_secondary_rays(scene);
}

}  // namespace

int shadow_cells(size_t triangles, const RenderSettings& settings) {
  if (settings.shadow_cells >= 0) return settings.shadow_cells;
  // Under emulated mediump the test's fp16 rounding moves triangles out of the cells they were
  // listed in, where the walk's leaves still test them as the CPU's does: auto walks there.
  const bool highp = settings.shadow_rays.ray_test.precision == Precision::High;
  return highp && triangles <= kAutoShadowCellsTriangles ? kAutoShadowCells : 0;
}

namespace {

// shadow_cells for `scene`: 0 with analytic shapes (light buffers test triangles only).
int scene_shadow_cells(const Scene& scene, const RenderSettings& settings) {
  return scene.shapes.empty() ? shadow_cells(scene.mesh.triangle_count(), settings) : 0;
}

}  // namespace

bool shadow_rays_buffered(const Scene& scene, const RenderSettings& settings) {
  if (!settings.shadows || scene.lights.empty()) return true;
  if (scene_shadow_cells(scene, settings) <= 0) return false;
  return std::all_of(scene.lights.begin(), scene.lights.end(),
                     [](const Light& l) { return l.type != LightType::Directional; });
}

namespace {

// The scene's closed parts, whose faces turned away from a light its buffer leaves out: under
// highp only (the argument needs the front face's test to hold at t up to 1 - 1e-5; fp16 rounds
// coarser), null elsewhere.
const ClosedParts* closed_parts_for(const Scene& scene, const RenderSettings& settings) {
  return settings.shadow_rays.ray_test.precision == Precision::High ? scene.closed_parts.get() : nullptr;
}

// One light buffer per light of `lights` at `res` cells a face edge (none where res <= 0) over the
// triangles `positions`; resolution 0 where a light gets none (a directional light). parts (may be
// null): the closed parts of `positions`, whose faces turned away from a light stay out of its lists.
// known (may be null): `parts` as posed at `positions` already; posed_out (may be null): the
// pose used, or none (`of` null) where no buffer needed one.
void light_buffers_for(std::span<const glm::vec3> positions, std::span<const Light> lights, int res,
                       const ClosedParts* parts, std::vector<LightBuffer>& out, const PosedParts* known,
                       PosedParts* posed_out) {
  out.resize(lights.size());  // each buffer built into its arrays' memory, when it has some
  std::vector<int8_t> winding;
  PosedParts posed;  // measured once a frame, for the first light that uses it
  bool measured = false;
  for (size_t l = 0; l < lights.size(); ++l) {
    if (res <= 0 || lights[l].type == LightType::Directional) {
      out[l].resolution = 0;
      out[l].left_out = 0;
      continue;
    }
    if (parts && !measured) {
      posed = known && known->of == parts ? *known : pose_closed_parts(*parts, positions);
      measured = true;
    }
    if (parts) light_windings(posed, positions, lights[l].position, winding);
    build_light_buffer(positions, lights[l].position, res, out[l], 0, winding);
  }
  if (posed_out) *posed_out = measured ? std::move(posed) : PosedParts{};
}

}  // namespace

void frame_light_buffers(const Scene& scene, const RenderSettings& settings, std::vector<LightBuffer>& out,
                         PosedParts* posed) {
  if (!settings.shadows) {
    out.clear();
    if (posed) *posed = PosedParts{};
    return;
  }
  light_buffers_for(scene.mesh.positions, scene.lights, scene_shadow_cells(scene, settings),
                    closed_parts_for(scene, settings), out, nullptr, posed);
}

bool primaries_rasterized(const Scene& scene, const RenderSettings& settings) {
  if (!scene.shapes.empty()) return false;
  switch (settings.primary) {
    case PrimaryHits::Trace: return false;
    case PrimaryHits::Raster: return true;
    case PrimaryHits::Auto:
      return raster_pays(scene.mesh.triangle_count(), settings.width, settings.height,
                         settings.always_rebuild || settings.tree_per_frame, rays_walk_tree(scene, settings));
  }
  return false;
}

bool frame_may_draw_mirrors(const Scene& scene, const RenderSettings& settings) {
  if (settings.mirrors == MirrorHits::Trace || settings.depth < 1 || !scene.shapes.empty()) return false;
  // Auto draws only where the raster pays as --primary auto's does: up to kRasterTrianglesPerPixel
  // triangles a pixel (llvmpipe sets up every triangle, and the mirror's pass draws every one in
  // front of the plane).
  if (settings.mirrors == MirrorHits::Auto &&
      double(scene.mesh.triangle_count()) > kRasterTrianglesPerPixel * double(settings.width) * double(settings.height)) {
    return false;
  }
  return std::any_of(scene.materials.begin(), scene.materials.end(),
                     [](const Material& m) { return m.reflectance > 0.0f && m.transmittance == 0.0f; });
}

bool frame_walks_tree(const Scene& scene, const RenderSettings& settings) {
  return !primaries_rasterized(scene, settings) || rays_walk_tree(scene, settings);
}

namespace {

// The nearest point of triangle `c` (in the camera's frame: x right, y up, z forward) inside the
// view pyramid |x| <= z tx, |y| <= z ty, by clipping it to the pyramid's four sides
// (Sutherland-Hodgman); infinity where none of it is inside. A convex polygon gains at most one
// vertex per plane (7), but rounding on points that lie on a plane can make it emit two per edge:
// the buffers hold that, and a polygon that would outgrow them returns 0 (the eye: conservative).
float nearest_in_view(const glm::vec3 (&c)[3], float tx, float ty) {
  constexpr int kMaxVertices = 48;  // 3 x 2^4
  glm::vec3 polygon[2][kMaxVertices];
  int count = 3;
  for (int k = 0; k < 3; ++k) polygon[0][k] = c[k];
  int from = 0;
  const glm::vec3 planes[4] = {{-1.0f, 0.0f, tx}, {1.0f, 0.0f, tx}, {0.0f, -1.0f, ty}, {0.0f, 1.0f, ty}};
  for (const glm::vec3& plane : planes) {
    const glm::vec3* in = polygon[from];
    glm::vec3* out = polygon[1 - from];
    int kept = 0;
    for (int k = 0; k < count; ++k) {
      if (kept + 2 > kMaxVertices) return 0.0f;
      const glm::vec3& a = in[k];
      const glm::vec3& b = in[(k + 1) % count];
      const float da = glm::dot(plane, a), db = glm::dot(plane, b);
      if (da >= 0.0f) out[kept++] = a;
      if ((da >= 0.0f) != (db >= 0.0f)) out[kept++] = a + (da / (da - db)) * (b - a);
    }
    count = kept;
    from = 1 - from;
    if (count == 0) return kInfinity;
  }
  float nearest = kInfinity;
  for (int k = 0; k < count; ++k) nearest = std::min(nearest, polygon[from][k].z);
  return nearest;
}

}  // namespace

bool raster_view(const Camera& camera, int width, int height, std::span<const glm::vec3> positions,
                 RasterView& view) {
  const CameraBasis basis(camera, width, height);
  // The view pyramid, 1 % wider than the image: what a pixel centre's ray can reach.
  const float tx = 1.01f * basis.tan_half * basis.aspect, ty = 1.01f * basis.tan_half;
  // Per triangle, on all cores (a 1M-triangle mesh): the farthest vertex, and the nearest point
  // that a primary ray can see. That is the nearest vertex of a triangle wholly in front of the eye
  // (conservative: it may lie outside the image), and of one that reaches behind the eye (a floor
  // under the camera, a room around it) the nearest point of its part inside the view pyramid,
  // which may be far nearer than any of its vertices in front.
  constexpr uint32_t kChunk = 4096;
  const uint32_t triangles = uint32_t(positions.size() / 3);
  const uint32_t chunks = chunk_count(triangles, kChunk);
  std::vector<float> chunk_near(chunks, kInfinity), chunk_far(chunks, 0.0f);
  parallel_for_chunks(triangles, kChunk, 0, [&](uint32_t ch, uint32_t begin, uint32_t end) {
    float lo = kInfinity, hi = 0.0f;
    for (uint32_t t = begin; t < end; ++t) {
      glm::vec3 c[3];
      bool behind = false;
      for (int k = 0; k < 3; ++k) {
        const glm::vec3 v = positions[3 * size_t(t) + k] - basis.eye;
        c[k] = glm::vec3(glm::dot(v, basis.right), glm::dot(v, basis.up), glm::dot(v, basis.forward));
        hi = std::max(hi, c[k].z);
        behind = behind || !(c[k].z > 0.0f);
      }
      lo = std::min(lo, behind ? nearest_in_view(c, tx, ty) : std::min({c[0].z, c[1].z, c[2].z}));
    }
    chunk_near[ch] = lo;
    chunk_far[ch] = hi;
  });
  float nearest = kInfinity, farthest = 0.0f;
  for (uint32_t c = 0; c < chunks; ++c) {
    nearest = std::min(nearest, chunk_near[c]);
    farthest = std::max(farthest, chunk_far[c]);
  }
  if (!(farthest > 0.0f) || !std::isfinite(farthest) || !(nearest < kInfinity)) return false;
  // The depth buffer's resolution spent where the triangles are (a near plane at the camera's
  // znear left 24-bit depth too coarse for the Utah toasters' and the wood doll's neighbouring
  // surfaces: mobirt_raster_probe, docs/performance-history.md *Session 26*). Never nearer than
  // rays start: a ray leaves the eye at znear along itself, which is at least znear cos(corner)
  // along the view axis.
  // A scene that reaches the eye itself gets a near plane at far / 10^6: every hit kept, the
  // depth resolution of 24-bit GLES much coarser (Vulkan's reversed 32-bit float depth keeps it).
  const float far_distance = farthest * 1.01f;
  const float cos_corner = 1.0f / std::sqrt(1.0f + tx * tx + ty * ty);
  const float near_distance =
      std::max({camera.znear * cos_corner, std::min(nearest * 0.99f, far_distance), far_distance * 1e-6f});
  const auto put3 = [](float* out, const glm::vec3& v) {
    out[0] = v.x;
    out[1] = v.y;
    out[2] = v.z;
    out[3] = 0.0f;
  };
  put3(view.eye, basis.eye);
  put3(view.right, basis.right);
  put3(view.up, basis.up);
  put3(view.forward, basis.forward);
  view.projection[0] = 1.0f / (basis.tan_half * basis.aspect);
  view.projection[1] = 1.0f / basis.tan_half;
  view.projection[2] = near_distance;
  view.projection[3] = far_distance;
  return true;
}

struct Renderer::Data {
  struct Texture {
    TextureHandle handle;
    uint32_t rows = 0;
  };
  Texture nodes, leaf_prims, triangles, materials;
  Texture ray_origin, ray_direction, hit_position, hit_normal, hit_texcoord;
  Texture shade_direction;  // the shading pass's rays' directions, hits compacted (Renderer::shade)
  // Every texture the renderer owns, each named once: the scene data's, and those in rows of the
  // rays' width (made again when the width changes).
  std::array<Texture*, 4> scene_data() { return {&nodes, &leaf_prims, &triangles, &materials}; }
  std::array<Texture*, 6> ray_layout() {
    return {&ray_origin, &ray_direction, &hit_position, &hit_normal, &hit_texcoord, &shade_direction};
  }
  // The scene's atlas pages, or one 1x1 stand-in without textures (the pass binds every page slot).
  std::vector<TextureHandle> atlas_pages;
  Atlas atlas_data;             // placements for the uniforms, kept while the scene's textures stay
  std::string atlas_scene;      // the scene (source + texture count) the atlas was built for
  bool has_atlas = false;
  FlatKdTree tree;                         // the last tree built, and the triangles it was built on
  std::vector<glm::vec3> tree_positions;
  std::vector<Shape> tree_shapes;
  bool tree_valid = false;
  bool tree_prebuilt = false;   // the next begin_frame uploads `tree`, built elsewhere in prebuilt_ms
  bool upload_stale = false;    // `tree` was made a kd-tree after its upload (a capped ray): upload again
  double prebuilt_ms = 0.0;
  uint32_t ray_width = 0;  // the ray textures' row width; a change recreates them
  bool tree_walkable = false;   // `tree` is a kd-tree, not only the primitives' texels (frame_walks_tree)
  // --primary raster: the vertices drawn, the raster pass's texels and the rays that hit, each with
  // its rasterized index + 1 in its direction's w (kept: their memory reused frame after frame).
  std::vector<float> raster_vertices;
  // The frame's closed parts as posed (pose_closed_parts), for the raster passes' faces left out
  // (faces_turned_away); measured at most once a frame (frame, posed_frame).
  uint64_t frame = 0;
  uint64_t posed_frame = 0;
  PosedParts posed;
  bool posed_prebuilt = false;  // `posed` was handed in for the next frame (Renderer::render)
  // mirror_planes handed in for the next frame (Renderer::render), and the frame they are for
  // (start_frame); the cache's keys below are then cleared (they describe no planes held).
  bool mirror_planes_prebuilt = false;
  uint64_t mirror_planes_frame = UINT64_MAX;
  size_t mirror_plane_searches = 0;  // find_mirror_planes calls here (Renderer::mirror_plane_searches)
  std::vector<uint8_t> away;  // per triangle: left out of the raster pass being drawn
  std::vector<uint32_t> raster_texels;
  bool raster_started = false;  // by Engine::start_frame, for this frame's trace_primary
  double raster_start_ms = 0.0;  // start_raster's CPU time, for the generation's upload stage
  RayBatch hit_rays;
  // find_mirror_planes of the last frame that looked for them here, with the triangles, normals
  // and materials it saw: a mesh that did not move (the serial bench rebuilds the Utah toasters'
  // still tray every frame) keeps them. Planes handed in with a frame (Renderer::render) replace
  // them and clear these keys.
  MirrorPlanes mirror_planes;
  std::vector<glm::vec3> mirror_positions;
  std::vector<glm::vec3> mirror_normals;  // find_mirror_planes reads them (a flat mirror's normals)
  std::vector<uint32_t> mirror_material_ids;
  std::vector<glm::vec2> mirror_materials;  // reflectance, transmittance
  uint64_t mirror_planes_checked = UINT64_MAX;  // the frame whose planes mirror_planes holds, checked
  // A mirror raster started ahead (start_mirror_raster_ahead, once the primary hits are shaded) for
  // the plane the primary hits predict; trace_mirrored finishes it where the rays choose that
  // plane, settle_mirror_raster before any other pass or raster.
  bool mirror_raster_pending = false;
  MirrorPlane mirror_raster_plane;
  MirrorRastersAhead mirror_rasters_ahead;  // Renderer::mirror_rasters_ahead
  // --shadow-cells: per shadow light the head of its light buffer (MOBIRT_TP_LIGHT_BUFFERS; z = 0
  // where it has none) and the lights' positions they were built for.
  std::vector<glm::vec4> light_buffer_heads;
  std::vector<glm::vec3> light_buffer_positions;  // the shadow lights of the last upload
  std::vector<LightType> light_buffer_types;
  bool light_buffers = false;  // some light has one
  // Built with a tree handed in (Renderer::render with light buffers; light_buffers_prebuilt until
  // the next begin_frame takes them), or by the last upload.
  std::vector<LightBuffer> prebuilt_light_buffers;
  bool light_buffers_prebuilt = false;
  size_t light_buffers_built = 0;  // by this renderer itself, since it was made
  // Where each light's buffer goes in the uploaded arrays (texels): its windows and cells after the
  // tree's nodes, its entries after the tree's leaf entries; and the arrays' lengths with them.
  struct LightBufferPlace {
    size_t light, node_texel, entry_texel;
  };
  std::vector<LightBufferPlace> light_buffer_places;
  size_t light_buffer_node_texels = 0, light_buffer_entry_texels = 0;
  // upload_tree's copies of the tree's arrays with light buffers after them since the last pass
  // (TexelWriter: in place, or where the backend has no such memory into an array it uploads): that
  // pass's upload, as the backend counts an upload's own copy.
  double written_ms = 0.0;
  // The frame's generations queued for shading (Renderer::queue_shade), in order, until
  // shade_queued hands their colours over.
  struct QueuedShade {
    uint32_t rays = 0;
    std::vector<uint8_t> hit;     // per ray: 1 where it hit (its colour is a shaded texel's)
    std::vector<uint32_t> first;  // per chunk of kShadeChunk rays: its first hit's input texel
    uint32_t hits = 0;
    bool shaded = false;          // a pass ran for it: `colors` holds its colours
    std::vector<glm::vec3> colors;
    GenerationTimings pass;       // its share of that pass (upload, shade, read-back, bytes, shaded)
  };
  std::vector<QueuedShade> shade_queue;
  const Scene* shade_queue_scene = nullptr;  // the scene of the queued generations
  uint32_t shade_texels = 0;    // input texels of the queued generations no pass has shaded yet
  bool shade_miss = false;      // one of those has a miss (one texel at shade_texels shades them all)
  // The inputs' textures while open (open_shade_inputs): written in place or, where the backend
  // has no such memory, into `kept` (from frame to frame: its memory reused), uploaded when closed.
  struct ShadeInput {
    std::optional<TexelWriter<glm::vec4>> writer;
    std::vector<glm::vec4> kept;
  };
  std::array<ShadeInput, 4> shade_inputs;  // position, normal, direction, texture coordinates
  bool shade_inputs_open = false;
  uint32_t shade_capacity = 0;      // texels each open input holds
  uint32_t shade_texels_hint = 0;   // the last frame's inputs: the room the next frame opens with
  size_t shading_passes = 0;
  // (lights, packing, analytic, wide, primary hits, light buffers)
  std::map<std::tuple<int, int, int, bool, int, bool>, PassHandle> trace_passes;
  std::map<std::tuple<int, int, int, int, bool>, PassHandle> shade_passes;  // (lights, textures, pages, colour, wide)
};

// The frame loop's view of the passes: the tree built or kept once per frame, one traversal pass per
// generation, and one shading pass a frame (two for 16-bit colour; with --shading generation, one
// a generation). Its shading (shade(), or at the frame's end) is ShadedByRenderer's on the
// renderer itself.
class Renderer::Engine final : public ShadedByRenderer {
 public:
  explicit Engine(Renderer& renderer) : ShadedByRenderer(renderer), r_(renderer) {}
  const char* name() const override { return "mobirt fragment passes"; }

  void begin_frame(const Scene& scene, const RenderSettings&, FrameTimings& t) override {
    // A tree built elsewhere is this frame's only (taken first, so that a refused frame leaves none).
    const bool prebuilt = std::exchange(r_.data_->tree_prebuilt, false);
    const bool buffers_prebuilt = std::exchange(r_.data_->light_buffers_prebuilt, false);
    // Refuse a scene over a limit before any work.
    choose_packing(scene.primitive_count(), r_.pass_lights(int(r_.shadow_lights(scene).size())),
                   scene.source);
    // The tree is rebuilt from scratch whenever the geometry changed (every frame of an animation,
    // as in the paper); a static scene, or a frame whose triangles did not move, keeps it.
    const auto stage = Clock::now();
    Data& cache = *r_.data_;
    // A frame that walks no tree (frame_walks_tree) gets only the primitives' texels; a cached one
    // of those never serves a frame that walks.
    const bool walks = frame_walks_tree(scene, r_.settings_);
    const bool reuse = !prebuilt && !r_.settings_.always_rebuild && cache.tree_valid &&
                       (cache.tree_walkable || !walks) && cache.tree_positions == scene.mesh.positions &&
                       cache.tree_shapes == scene.shapes;
    if (prebuilt) {
      t.build_ms = cache.prebuilt_ms;  // on the frame pipeline's worker, during the previous frame
      if (walks && cache.tree.nodes.empty()) {
        throw Error(ErrorKind::Internal, "a frame that walks a kd-tree was handed the primitives' texels only");
      }
      cache.tree_walkable = !cache.tree.nodes.empty();
    } else if (!reuse) {
      // Into the last tree's arrays (their memory kept); until uploaded again it is no cache.
      cache.tree_valid = false;
      if (walks) {
        rebuild_kdtree(cache.tree, scene.mesh.positions, scene.shapes, r_.settings_.kd);
      } else {
        flatten_primitives(cache.tree, scene.mesh.positions, scene.shapes);
      }
      cache.tree_walkable = walks;
      if (!r_.settings_.always_rebuild) {  // else never looked at (Renderer::render)
        cache.tree_positions = scene.mesh.positions;
        cache.tree_shapes = scene.shapes;
      }
      t.build_ms = elapsed_ms(stage);
    }
    // A kept tree whose lights moved needs new light buffers (--shadow-cells); so does one without
    // a kd-tree, whose shadow rays have nothing else (a light added where none had a buffer).
    bool lights_moved = false;
    if (cache.light_buffers || !cache.tree_walkable) {
      const std::span<const Light> lights = r_.shadow_lights(scene);
      lights_moved = lights.size() != cache.light_buffer_positions.size();
      for (size_t l = 0; !lights_moved && l < lights.size(); ++l) {
        lights_moved = lights[l].position != cache.light_buffer_positions[l] || lights[l].type != cache.light_buffer_types[l];
      }
    }
    if (!reuse || lights_moved || cache.upload_stale) {
      // The light buffers are part of the acceleration structure: their build (on this thread,
      // unless built with the tree ahead) and their packing count as build time.
      t.build_ms += r_.upload_tree(cache.tree, scene, buffers_prebuilt && prebuilt);
      cache.tree_valid = true;
      cache.upload_stale = false;
      // A frame without a tree with a light that turned out to get no buffer (its lists too long,
      // past a texture's reach): that light's shadow rays walk, so the tree is built after all
      // (its buffers, just made for these triangles, kept).
      if (!cache.tree_walkable && r_.light_buffers_used() < int(r_.shadow_lights(scene).size())) {
        t.build_ms += make_walkable(scene);
        t.build_ms += r_.upload_tree(cache.tree, scene, true);
        t.tree_rebuilt = true;
      }
    }
    t.tree_rebuilt = t.tree_rebuilt || !reuse;
    r_.upload_materials(scene);
  }

  const FlatKdTree& tree() const override { return r_.data_->tree; }

  // The frame's kd-tree built over the primitives' texels it had (the same triangles, in the same
  // order: flatten_primitives); returns its milliseconds.
  double make_walkable(const Scene& scene) {
    const auto start = Clock::now();
    Data& cache = *r_.data_;
    rebuild_kdtree(cache.tree, scene.mesh.positions, scene.shapes, r_.settings_.kd);
    cache.tree_walkable = true;
    return elapsed_ms(start);
  }

  void shaded(const Scene& scene, const Camera& camera, int generation, const RayBatch& rays, const SurfaceHits& hits,
              GenerationTimings& g) override {
    if (generation == 0) r_.start_mirror_raster_ahead(scene, camera, rays, hits, g);
  }

  // A raster started ahead of mirror rays that never came is dropped within its frame: another
  // renderer on the same backend would drop it unseen (Backend::start_raster).
  // So is a queue of generations a frame that ended early never shaded.
  void end_frame() override {
    try {
      ShadedByRenderer::end_frame();
    } catch (...) {
      r_.settle_mirror_raster();
      throw;
    }
    r_.settle_mirror_raster();
  }

  TracedGeneration trace_secondary(const Scene& scene, const Camera& camera, int generation, const RayBatch& rays,
                                   GenerationTimings& g) override {
    TracedGeneration traced;
    if (generation == 1 && r_.data_->tree_walkable && r_.trace_mirrored(scene, camera, r_.data_->tree, rays, g, traced)) {
      return traced;
    }
    // Under highp only: the pass's mediump hits are decoded in fp32 from their index (decode_hits),
    // which the hits the CPU walk hands back are not.
    if (r_.data_->tree_walkable && rays.count() <= uint32_t(std::max(r_.settings_.cpu_walks, 0)) &&
        r_.settings_.shadow_rays.ray_test.precision == Precision::High) {
      return r_.trace_on_cpu(scene, rays, g);
    }
    return trace(scene, rays, g);
  }

  TracedGeneration trace(const Scene& scene, const RayBatch& rays, GenerationTimings& g) override {
    TraceResult result = r_.trace_uploaded(scene, r_.data_->tree, rays);
    add_pass(g, result.timing);
    g.walks += result.walks;
    TracedGeneration traced;
    traced.form = TracedGeneration::Form::PackedTexels;
    traced.texels = std::move(result.texels);
    traced.packing = result.packing;
    return traced;
  }

  // The raster pass starts before begin_frame's uploads and the primary rays: the driver sets up
  // its triangles on a thread of its own while this thread works (alone, that setup left a core
  // idle: docs/performance-history.md, *Session 30*).
  void start_frame(const Scene& scene, const Camera& camera, const RenderSettings&) override {
    Data& d = *r_.data_;
    r_.settle_mirror_raster();  // none left by an earlier frame (end_frame), but never two at once
    d.raster_started = false;
    ++d.frame;
    if (std::exchange(d.posed_prebuilt, false)) d.posed_frame = d.frame;  // handed in with this frame
    if (std::exchange(d.mirror_planes_prebuilt, false)) d.mirror_planes_frame = d.frame;
    if (!primaries_rasterized(scene, r_.settings_)) return;
    try {
      // A scene over a limit is refused here, as begin_frame would, before any pass starts.
      choose_packing(scene.primitive_count(), r_.pass_lights(int(r_.shadow_lights(scene).size())), scene.source);
      r_.start_raster(scene, camera, uint32_t(r_.settings_.width), uint32_t(r_.settings_.height));
    } catch (...) {
      // As begin_frame does first: a refused frame leaves no tree or light buffers handed in
      // behind, for the next frame to take as its own.
      d.tree_prebuilt = false;
      d.light_buffers_prebuilt = false;
      throw;
    }
    d.raster_started = true;
  }

  TracedGeneration trace_primary(const Scene& scene, const Camera& camera, const RayBatch& rays,
                                 GenerationTimings& g) override {
    const bool started = std::exchange(r_.data_->raster_started, false);
    if (!primaries_rasterized(scene, r_.settings_)) return trace(scene, rays, g);
    TracedGeneration traced =
        r_.trace_rasterized(scene, camera, r_.data_->tree, rays, g, r_.data_->tree_walkable, started);
    // A ray the loop cap stopped (a light buffer's cell listing more than --max-steps triangles)
    // is retraced on the CPU through the kd-tree (decode_hits): a frame without one builds it now,
    // counted with the decoding. The GPU still holds the primitives' texels alone: the next frame
    // uploads the tree it keeps (upload_stale), and its edge misses walk it.
    Data& cache = *r_.data_;
    if (!cache.tree_walkable) {
      const uint32_t capped = pack_capped(traced.packing);
      if (std::find(traced.texels.begin(), traced.texels.end(), capped) != traced.texels.end()) {
        g.decode_ms += make_walkable(scene);
        cache.upload_stale = true;
      }
    }
    return traced;
  }

  void order_rays(RayBatch& rays) const override {
    order_for_traversal(rays, r_.data_->tree.bounds);  // coherent rays per SIMD group (raytree/ray_order.h)
  }

 private:
  Renderer& r_;
};

Renderer::Renderer(Backend& backend, const RenderSettings& settings)
    : backend_(backend), settings_(settings), data_(std::make_unique<Data>()),
      engine_(std::make_unique<Engine>(*this)) {
  const DeviceInfo info = backend_.device_info();
  if (settings_.data == DataReads::TexelBuffers && info.texel_buffers) data_kind_ = TextureKind::TexelBuffer;
  if (settings_.data == DataReads::StorageBuffers && info.storage_buffers) data_kind_ = TextureKind::StorageBuffer;
  if (settings_.data == DataReads::DeviceAddresses && info.device_addresses) data_kind_ = TextureKind::DeviceAddress;
  if (data_kind_ == TextureKind::DeviceAddress && device_address_reads_fault(info)) {
    throw Error(ErrorKind::BadInput,
                "--data device-addresses: llvmpipe's reads through buffer references fault at random on a CPU with "
                "AVX-512 (seen on a Zen 4: a masked gather of a finished lane's address), and this is one; use "
                "--data storage-buffers (the same buffers, bounds-checked) or texel-buffers");
  }
  if (settings_.stack_depth < 0 || settings_.stack_depth > MOBIRT_MAX_STACK_DEPTH) {
    throw Error(ErrorKind::BadInput, "--stack " + std::to_string(settings_.stack_depth) +
                                         ": the short stack holds 0 to " +
                                         std::to_string(MOBIRT_MAX_STACK_DEPTH) + " entries");
  }
  if (settings_.max_steps < 1) {
    throw Error(ErrorKind::BadInput, "--max-steps must be at least 1");
  }
  if (settings_.width < 1 || settings_.height < 1) {
    throw Error(ErrorKind::BadInput, "--size: width and height must be at least 1");
  }
}

Renderer::~Renderer() {
  Data& d = *data_;
  const auto destroy = [&](Data::Texture* t) {
    if (t->handle) backend_.destroy(t->handle);
  };
  for (Data::Texture* t : d.scene_data()) destroy(t);
  for (Data::Texture* t : d.ray_layout()) destroy(t);
  for (TextureHandle page : d.atlas_pages) backend_.destroy(page);
  for (auto& [key, pass] : d.trace_passes) backend_.destroy(pass);
  for (auto& [key, pass] : d.shade_passes) backend_.destroy(pass);
}

TextureHandle Renderer::ensure_texture(TextureHandle& handle, uint32_t& capacity_rows, uint32_t width,
                                       uint32_t rows, TexelFormat format, TextureKind kind) {
  if (handle && capacity_rows >= rows) return handle;
  // Grow with headroom so that an animation whose tree changes size does not reallocate often;
  // where the headroom alone passes the backend's limit (2^24 texels a buffer, the largest
  // 2D texture), the exact size, so that a frame that fits is never refused for its headroom.
  uint32_t grown = std::max(rows, capacity_rows + capacity_rows / 2);
  if (handle) backend_.destroy(handle);
  handle = {};
  capacity_rows = 0;
  // A buffer holds the same rows end to end: DATA_TEXEL's index is the texel's.
  const auto create = [&](uint32_t n) {
    switch (kind) {
      case TextureKind::TexelBuffer: return backend_.create_texel_buffer(width * n, format);
      case TextureKind::StorageBuffer:
      case TextureKind::DeviceAddress: return backend_.create_storage_buffer(width * n, format);
      case TextureKind::Image2D: break;
    }
    return backend_.create_texture(width, n, format);
  };
  try {
    handle = create(grown);
  } catch (const Error& e) {
    if (e.kind() != ErrorKind::BadInput || grown == rows) throw;
    grown = rows;
    handle = create(grown);
  }
  capacity_rows = grown;
  return handle;
}

bool Renderer::wide_indices(std::initializer_list<std::pair<uint32_t, uint32_t>> rows_and_widths) const {
  // 2D images are indexed by coordinates (data_coord), exact up to 2^24 without the trick.
  if (data_kind_ == TextureKind::Image2D) return false;
  return std::any_of(rows_and_widths.begin(), rows_and_widths.end(), [](const std::pair<uint32_t, uint32_t>& t) {
    return uint64_t(t.first) * t.second > MOBIRT_NARROW_INDEX_TEXELS;
  });
}

PassHandle Renderer::trace_pass(int lights, Packing packing, bool analytic, bool wide, int primary_hits,
                                bool light_buffers) {
  auto key = std::make_tuple(lights, int(packing), int(analytic), wide, primary_hits, light_buffers);
  auto it = data_->trace_passes.find(key);
  if (it != data_->trace_passes.end()) return it->second;
  PassDesc desc;
  desc.shader = by_data_kind(data_kind_, ShaderId::Traverse, ShaderId::TraverseTexelBuffers,
                             ShaderId::TraverseStorageBuffers, ShaderId::TraverseDeviceAddresses);
  desc.specialization = {{MOBIRT_SPEC_LIGHT_COUNT, lights},
                         {MOBIRT_SPEC_STACK_DEPTH, settings_.stack_depth},
                         {MOBIRT_SPEC_MAX_STEPS, settings_.max_steps},
                         {MOBIRT_SPEC_PACKING, int(packing)},
                         {MOBIRT_SPEC_INTERSECT, int(settings_.shadow_rays.ray_test.test)},
                         {MOBIRT_SPEC_PRECISION, int(settings_.shadow_rays.ray_test.precision)},
                         {MOBIRT_SPEC_OFFSET, int(settings_.shadow_rays.offset.mode)},
                         {MOBIRT_SPEC_ANALYTIC, int(analytic)}};
  if (wide) desc.specialization.push_back({MOBIRT_SPEC_WIDE_INDICES, 1});
  if (primary_hits) desc.specialization.push_back({MOBIRT_SPEC_PRIMARY_HITS, primary_hits});
  if (light_buffers) desc.specialization.push_back({MOBIRT_SPEC_LIGHT_BUFFERS, 1});
  desc.uniform_vec4s = light_buffers ? MOBIRT_TP_LIGHT_BUFFERS + uint32_t(lights)
                                     : MOBIRT_TP_LIGHTS + MOBIRT_TP_VEC4S_PER_LIGHT * uint32_t(lights);
  desc.texture_bindings = {MOBIRT_BIND_NODES, MOBIRT_BIND_LEAF_PRIMS, MOBIRT_BIND_TRIANGLES,
                           MOBIRT_BIND_RAY_ORIGIN, MOBIRT_BIND_RAY_DIRECTION};
  desc.texture_kinds.assign(desc.texture_bindings.size(), data_kind_);
  PassHandle pass = backend_.create_pass(desc);
  data_->trace_passes.emplace(key, pass);
  return pass;
}

PassHandle Renderer::shade_pass(int lights, int textures, int pages, int colour, bool wide) {
  const auto key = std::make_tuple(lights, textures, pages, colour, wide);
  auto it = data_->shade_passes.find(key);
  if (it != data_->shade_passes.end()) return it->second;
  PassDesc desc;
  desc.shader = by_data_kind(data_kind_, ShaderId::Shade, ShaderId::ShadeTexelBuffers, ShaderId::ShadeStorageBuffers,
                             ShaderId::ShadeDeviceAddresses);
  desc.specialization = {{MOBIRT_SPEC_LIGHT_COUNT, lights},
                         {MOBIRT_SPEC_TEXTURE_COUNT, textures},
                         {MOBIRT_SPEC_ATLAS_PAGES, pages},
                         {MOBIRT_SPEC_COLOUR, colour}};
  if (wide) desc.specialization.push_back({MOBIRT_SPEC_WIDE_INDICES, 1});
  desc.uniform_vec4s = MOBIRT_SP_TEXTURES(uint32_t(lights)) + MOBIRT_SP_VEC4S_PER_TEXTURE * uint32_t(textures);
  // The pages get the units that the data textures leave (layout.h counts both).
  constexpr uint32_t data_slots[] = {MOBIRT_BIND_HIT_POSITION, MOBIRT_BIND_HIT_NORMAL, MOBIRT_BIND_MATERIALS,
                                     MOBIRT_BIND_SHADE_RAY_DIRECTION, MOBIRT_BIND_HIT_TEXCOORD};
  constexpr uint32_t page_slots[] = {MOBIRT_BIND_ATLAS_PAGE_0, MOBIRT_BIND_ATLAS_PAGE_1, MOBIRT_BIND_ATLAS_PAGE_2};
  static_assert(std::size(data_slots) == MOBIRT_SHADE_DATA_TEXTURES && std::size(page_slots) == MOBIRT_ATLAS_MAX_PAGES);
  desc.texture_bindings.assign(std::begin(data_slots), std::end(data_slots));
  desc.texture_bindings.insert(desc.texture_bindings.end(), std::begin(page_slots), std::end(page_slots));
  desc.texture_kinds.assign(std::size(data_slots), data_kind_);
  desc.texture_kinds.resize(desc.texture_bindings.size(), TextureKind::Image2D);  // the pages stay 2D images
  desc.linear_bindings = atlas_linear_bindings(backend_.device_info());
  PassHandle pass = backend_.create_pass(desc);
  data_->shade_passes.emplace(key, pass);
  return pass;
}

void Renderer::prepare_atlas(const Scene& scene) {
  Data& d = *data_;
  // Textures never change during an animation: rebuild only for another set of textures.
  // 16-bit colour reads exact pages (atlas_page_format).
  const bool exact = settings_.colour != ColourDepth::Bits8;
  std::string key = atlas_key(scene) + (exact ? "/exact" : "");
  if (!d.atlas_pages.empty() && key == d.atlas_scene) return;
  for (TextureHandle page : d.atlas_pages) backend_.destroy(page);
  d.atlas_pages.clear();
  d.atlas_data = build_atlas(scene);
  d.has_atlas = !d.atlas_data.empty();
  const uint32_t size = uint32_t(d.atlas_data.size);
  const TexelFormat format = atlas_page_format(backend_.device_info(), exact);
  for (const std::vector<uint32_t>& pixels : d.atlas_data.pages) {
    d.atlas_pages.push_back(backend_.create_texture(size, size, format));
    backend_.upload(d.atlas_pages.back(), pixels.data(), pixels.size() * sizeof(uint32_t));
  }
  if (d.atlas_pages.empty()) {
    // The shading pass always binds the page slots; specialised to no textures, it never reads them.
    d.atlas_pages.push_back(backend_.create_texture(1, 1, format));
    const uint32_t black = 0;
    backend_.upload(d.atlas_pages.back(), &black, sizeof(black));
  }
  d.atlas_scene = key;
}

void Renderer::build_light_buffers(const FlatKdTree& tree, const Scene& scene, bool prebuilt) {
  Data& d = *data_;
  const std::span<const Light> lights = shadow_lights(scene);
  d.light_buffers = false;
  d.light_buffer_heads.assign(lights.size(), glm::vec4(0.0f));
  // What the buffers were built for: a kept tree's lights that move or change kind rebuild them.
  d.light_buffer_positions.clear();
  d.light_buffer_types.clear();
  for (const Light& light : lights) {
    d.light_buffer_positions.push_back(light.position);
    d.light_buffer_types.push_back(light.type);
  }
  // Over the triangles of `tree` as uploaded (a tree handed to trace() need not be scene.mesh's:
  // the buffers index its triangles); a tree of triangles only (analytic shapes have no
  // light-buffer test). The tree may be the primitives' texels alone (frame_walks_tree).
  const size_t triangles = tree.triangles.size() / MOBIRT_TEXELS_PER_TRIANGLE;
  bool analytic = false;
  for (size_t t = 0; t < triangles && !analytic; ++t) {
    analytic = tree.triangles[t * MOBIRT_TEXELS_PER_TRIANGLE][MOBIRT_PRIM_KIND] != MOBIRT_PRIM_TRIANGLE;
  }
  const int res = analytic ? 0 : shadow_cells(triangles, settings_);
  // The buffers built with the tree (the frame pipeline's worker, or the last upload of the same
  // triangles) where they are these lights' at this resolution, else built here.
  std::vector<LightBuffer>& buffers = d.prebuilt_light_buffers;
  prebuilt = prebuilt && buffers.size() == lights.size();
  for (size_t l = 0; prebuilt && l < lights.size(); ++l) {
    prebuilt = lights[l].type == LightType::Directional || res <= 0
                   ? buffers[l].resolution == 0
                   : buffers[l].resolution == res && buffers[l].light == lights[l].position;
  }
  if (!prebuilt) {
    std::vector<glm::vec3> positions(res > 0 ? triangles * 3 : 0);
    for (size_t i = 0; i < positions.size(); ++i) {
      positions[i] = glm::vec3(tree.triangles[(i / 3) * MOBIRT_TEXELS_PER_TRIANGLE + i % 3]);
    }
    // The scene's closed parts where the tree's triangles are the scene's mesh as posed.
    const bool same = scene.closed_parts && positions == scene.mesh.positions;
    // The frame's pose where the raster pass measured it already (faces_away_from; light_buffers_for
    // takes it only where it is of these parts).
    light_buffers_for(positions, lights, res, same ? closed_parts_for(scene, settings_) : nullptr, buffers,
                      d.posed_frame == d.frame ? &d.posed : nullptr, nullptr);
    d.light_buffers_built += size_t(std::count_if(buffers.begin(), buffers.end(),
                                                  [](const LightBuffer& lb) { return lb.resolution > 0; }));
  }
  // Where each buffer goes: its windows and cells after the tree's nodes (and the buffers before
  // it), its entries after the tree's leaf entries; written by upload_tree.
  d.light_buffer_places.clear();
  size_t nodes = tree.nodes.size(), entries = tree.leaf_prims.size();
  for (size_t l = 0; l < lights.size(); ++l) {
    const LightBuffer& lb = buffers[l];
    if (!light_buffer_pays(lb)) continue;  // a directional light, or long lists: the walk is faster
    const size_t entry_base = entries / MOBIRT_TEXELS_PER_TRIANGLE;
    const size_t head = nodes + MOBIRT_LIGHT_BUFFER_WINDOWS;
    if (head + lb.cells() >= size_t(MOBIRT_MAX_INDEX_TEXELS) ||
        (entry_base + lb.prims.size()) * MOBIRT_TEXELS_PER_TRIANGLE >= size_t(MOBIRT_MAX_INDEX_TEXELS)) {
      continue;  // past what a texture index reaches: this light's rays walk the tree
    }
    d.light_buffer_places.push_back({l, nodes, entries});
    nodes = head + lb.cells();
    entries += lb.prims.size() * MOBIRT_TEXELS_PER_TRIANGLE;
    d.light_buffer_heads[l] = glm::vec4(float(head), float(res), 1.0f, 0.0f);
    d.light_buffers = true;
  }
  d.light_buffer_node_texels = nodes;
  d.light_buffer_entry_texels = entries;
}

void Renderer::write_light_buffer_nodes(glm::vec4* nodes) const {
  const Data& d = *data_;
  for (const Data::LightBufferPlace& place : d.light_buffer_places) {
    const LightBuffer& lb = d.prebuilt_light_buffers[place.light];
    const size_t entry_base = place.entry_texel / MOBIRT_TEXELS_PER_TRIANGLE;
    glm::vec4* windows = nodes + place.node_texel;
    std::copy(lb.window.begin(), lb.window.end(), windows);
    glm::vec4* cells = windows + MOBIRT_LIGHT_BUFFER_WINDOWS;
    parallel_for_chunks(uint32_t(lb.cells()), 16384, 0, [&](uint32_t, uint32_t begin, uint32_t end) {
      for (uint32_t c = begin; c < end; ++c) {
        cells[c] = glm::vec4(float(entry_base + lb.first[c]), float(lb.first[c + 1] - lb.first[c]), MOBIRT_NODE_LEAF,
                             0.0f);
      }
    });
  }
}

void Renderer::write_light_buffer_entries(glm::vec4* entries, const FlatKdTree& tree) const {
  const Data& d = *data_;
  for (const Data::LightBufferPlace& place : d.light_buffer_places) {
    const LightBuffer& lb = d.prebuilt_light_buffers[place.light];
    // Each entry (glsl/layout.h): (near, part, v0.x, v0.y), (v0.z, v1), (v2, 0); the part is an
    // exact integer below 2^24.
    glm::vec4* out = entries + place.entry_texel;
    parallel_for_chunks(uint32_t(lb.prims.size()), 8192, 0, [&](uint32_t, uint32_t begin, uint32_t end) {
      for (uint32_t k = begin; k < end; ++k) {
        const glm::vec4* tri = &tree.triangles[size_t(lb.prims[k]) * MOBIRT_TEXELS_PER_TRIANGLE];
        glm::vec4* e = out + size_t(k) * MOBIRT_TEXELS_PER_TRIANGLE;
        e[0] = glm::vec4(lb.near[k], float(lb.sub[k]), tri[0].x, tri[0].y);
        e[1] = glm::vec4(tri[0].z, glm::vec3(tri[1]));
        e[2] = glm::vec4(glm::vec3(tri[2]), 0.0f);
      }
    });
  }
}

int Renderer::light_buffers_used() const {
  const Data& d = *data_;
  if (!d.light_buffers) return 0;
  return int(std::count_if(d.light_buffer_heads.begin(), d.light_buffer_heads.end(),
                           [](const glm::vec4& h) { return h.z > 0.5f; }));
}

size_t Renderer::light_buffer_faces_left_out() const {
  const Data& d = *data_;
  size_t n = 0;
  if (!d.light_buffers) return 0;
  for (const Data::LightBufferPlace& place : d.light_buffer_places) n += d.prebuilt_light_buffers[place.light].left_out;
  return n;
}

bool Renderer::frame_had_kd_tree() const { return data_->tree_walkable; }

size_t Renderer::light_buffers_built() const { return data_->light_buffers_built; }

size_t Renderer::mirror_plane_searches() const { return data_->mirror_plane_searches; }

Renderer::MirrorRastersAhead Renderer::mirror_rasters_ahead() const { return data_->mirror_rasters_ahead; }

double Renderer::upload_tree(const FlatKdTree& tree, const Scene& scene, bool buffers_prebuilt) {
  Data& d = *data_;
  auto start = Clock::now();
  build_light_buffers(tree, scene, buffers_prebuilt);
  double buffers_ms = elapsed_ms(start);
  // An array with nothing after it is uploaded as it is (Vulkan's upload is itself one copy into
  // the mapped buffer). One with light buffers after it is written where the pass reads it
  // (TexelWriter): the tree's array copied in, counted as the upload (as the backend counts its
  // own copy), the light buffers packed after it on all cores, counted as their build. Texture
  // rows are uploaded whole: each array padded to full rows; an empty one is one zero texel.
  auto write = [&](Data::Texture& t, std::span<const glm::vec4> texels, size_t total, auto&& pack) {
    ensure_texture(t.handle, t.rows, kDataWidth, data_rows(total), TexelFormat::RGBA32F, data_kind_);
    if (total == texels.size()) {
      const glm::vec4 zero(0.0f);
      backend_.upload(t.handle, total > 0 ? texels.data() : &zero, std::max<size_t>(total, 1) * sizeof(glm::vec4));
      return;
    }
    start = Clock::now();
    TexelWriter<glm::vec4> out(backend_, t.handle, total);
    parallel_copy(out.data(), texels.data(), texels.size_bytes());
    d.written_ms += elapsed_ms(start);
    start = Clock::now();
    pack(out.data());
    buffers_ms += elapsed_ms(start);
    out.done();  // an upload where not written in place: the backend counts it
  };
  const bool lb = d.light_buffers;
  write(d.nodes, tree.nodes, lb ? d.light_buffer_node_texels : tree.nodes.size(),
        [&](glm::vec4* out) { write_light_buffer_nodes(out); });
  write(d.leaf_prims, tree.leaf_prims, lb ? d.light_buffer_entry_texels : tree.leaf_prims.size(),
        [&](glm::vec4* out) { write_light_buffer_entries(out, tree); });
  write(d.triangles, tree.triangles, tree.triangles.size(), [](glm::vec4*) {});
  return buffers_ms;
}

void Renderer::fit_ray_layout(uint32_t width) {
  Data& d = *data_;
  if (d.ray_width == width) return;
  if (d.shade_inputs_open) {
    throw Error(ErrorKind::Internal, "the rays' layout changed while shading inputs were queued in it");
  }
  for (Data::Texture* t : d.ray_layout()) {
    if (t->handle) backend_.destroy(t->handle);
    *t = {};
  }
  d.ray_width = width;
}

void Renderer::upload_rays(const RayBatch& rays) {
  Data& d = *data_;
  fit_ray_layout(rays.width);
  ensure_texture(d.ray_origin.handle, d.ray_origin.rows, rays.width, rays.rows(), TexelFormat::RGBA32F, data_kind_);
  ensure_texture(d.ray_direction.handle, d.ray_direction.rows, rays.width, rays.rows(), TexelFormat::RGBA32F,
                 data_kind_);
  backend_.upload(d.ray_origin.handle, rays.origin.data(), rays.origin.size() * sizeof(glm::vec4));
  backend_.upload(d.ray_direction.handle, rays.direction.data(), rays.direction.size() * sizeof(glm::vec4));
}

TraceResult Renderer::trace(const Scene& scene, const FlatKdTree& tree, const RayBatch& rays) {
  data_->tree_valid = false;  // the GPU now holds this tree, not the cached one
  upload_tree(tree, scene, false);
  return trace_uploaded(scene, tree, rays);
}

TraceResult Renderer::trace_primary(const Scene& scene, const Camera& camera, const FlatKdTree& tree,
                                    const RayBatch& rays) {
  if (!primaries_rasterized(scene, settings_)) return trace(scene, tree, rays);
  ++data_->frame;  // a frame of its own: the closed parts are posed anew (faces_away_from)
  data_->posed_prebuilt = false;
  data_->mirror_planes_prebuilt = false;
  data_->tree_valid = false;  // the GPU now holds this tree, not the cached one
  upload_tree(tree, scene, false);
  GenerationTimings g;
  // Edge misses as the frame treats them: walked where it has a kd-tree (frame_walks_tree, or a
  // light whose buffer did not pay, for which the frame builds one).
  const bool walks = frame_walks_tree(scene, settings_) || light_buffers_used() < int(shadow_lights(scene).size());
  TracedGeneration traced = trace_rasterized(scene, camera, tree, rays, g, walks);
  TraceResult result;
  result.texels = std::move(traced.texels);
  result.packing = traced.packing;
  result.timing.gpu_ms = g.trace_ms;
  result.timing.upload_ms = g.upload_ms;
  result.timing.readback_ms = g.trace_readback_ms;
  result.timing.bytes_read = g.bytes_read;
  return result;
}

TraceResult Renderer::trace_uploaded(const Scene& scene, const FlatKdTree& tree, const RayBatch& rays,
                                     int primary_hits) {
  settle_mirror_raster();  // no pass runs while a raster is in flight (Backend::start_raster)
  TraceResult result;
  // Without shadows the pass is specialised to no lights: it casts no shadow rays at all.
  const int lights = pass_lights(int(shadow_lights(scene).size()));
  result.packing = choose_packing(scene.primitive_count(), lights, scene.source);
  upload_rays(rays);
  // A general pass carries the sphere and cone tests; a specialised one only where the scene has them.
  const Data& d = *data_;
  const bool wide = wide_indices({{d.nodes.rows, kDataWidth}, {d.leaf_prims.rows, kDataWidth},
                                  {d.triangles.rows, kDataWidth}, {d.ray_origin.rows, rays.width},
                                  {d.ray_direction.rows, rays.width}});
  const bool light_buffers = d.light_buffers && lights > 0;
  const PassHandle pass = trace_pass(lights, result.packing, !settings_.specialize || !scene.shapes.empty(), wide,
                                     primary_hits, light_buffers);
  std::vector<float> uniforms = trace_uniforms(tree, shadow_lights(scene), settings_.shadow_rays, lights);
  if (light_buffers) {
    for (int l = 0; l < lights; ++l) {
      put(uniforms, MOBIRT_TP_LIGHT_BUFFERS + size_t(l),
          size_t(l) < d.light_buffer_heads.size() ? d.light_buffer_heads[size_t(l)] : glm::vec4(0.0f));
    }
  }
  const TextureHandle textures[] = {d.nodes.handle, d.leaf_prims.handle, d.triangles.handle,
                                    d.ray_origin.handle, d.ray_direction.handle};
  result.texels.resize(rays.count());
  result.timing = backend_.run_pass(pass, textures, uniforms, rays.width, rays.count(), result.texels);
  result.timing.upload_ms += std::exchange(data_->written_ms, 0.0);
  result.walks = pass_walks(scene, rays.count(), primary_hits == 0);
  return result;
}

uint64_t Renderer::pass_walks(const Scene& scene, uint32_t rays, bool closest_hits) const {
  // A pass's walks of the tree: its closest hits unless they are drawn hits (an edge miss walks:
  // rare), and its shadow rays for each light without a buffer.
  const size_t shadow_count = shadow_lights(scene).size();
  const size_t buffered = data_->light_buffers ? std::min(shadow_count, size_t(light_buffers_used())) : 0;
  return uint64_t(rays) * ((closest_hits ? 1 : 0) + (shadow_count - buffered));
}

TracedGeneration Renderer::trace_on_cpu(const Scene& scene, const RayBatch& rays, GenerationTimings& g) {
  const Data& d = *data_;
  const FlatKdTree& tree = d.tree;
  const std::span<const Light> lights = shadow_lights(scene);
  const ShadowSettings& shadows = settings_.shadow_rays;
  const uint32_t n = rays.count();
  TracedGeneration traced;
  traced.form = TracedGeneration::Form::Hits;
  traced.hits.resize(n);
  traced.masks.assign(n, 0u);
  // A light's shadow rays as the pass casts them: through its light buffer where the pass reads
  // one (light_buffer_heads), else a walk.
  const auto buffered = [&](size_t l) {
    return d.light_buffers && l < d.light_buffer_heads.size() && d.light_buffer_heads[l].z > 0.5f;
  };
  std::atomic<uint64_t> shadow_rays{0};
  const auto start = Clock::now();
  parallel_for_chunks(n, 32, 0, [&](uint32_t, uint32_t begin, uint32_t end) {
    uint64_t cast = 0;
    for (uint32_t i = begin; i < end; ++i) {
      const Ray ray = rays.ray(i);
      const Hit h = traverse_fast(tree, ray, shadows.ray_test);
      traced.hits[i] = h;
      if (!h.valid() || lights.empty()) continue;
      traced.masks[i] = shadow_mask_by_light(tree, lights, h.prim, ray, h.t, shadows, [&](size_t l, const Ray& s) {
        ++cast;
        return buffered(l) ? light_buffer_occluded(d.prebuilt_light_buffers[l], tree, s.origin, nullptr, nullptr,
                                                   &shadows.ray_test)
                           : occluded_fast(tree, s, shadows.ray_test);
      });
    }
    shadow_rays.fetch_add(cast, std::memory_order_relaxed);
  });
  g.trace_ms += elapsed_ms(start);
  g.cpu_walked += n;
  traced.shadow_rays = shadow_rays.load();
  // The walks the pass would have counted, so that the next frame's tree is the same.
  g.walks += pass_walks(scene, n, true);
  return traced;
}

const std::vector<uint8_t>& Renderer::faces_away_from(const Scene& scene, glm::vec3 eye, const glm::vec3* rays_from,
                                                      float reach) {
  Data& d = *data_;
  d.away.clear();
  if (!scene.closed_parts || scene.closed_parts->triangles != scene.mesh.triangle_count()) return d.away;
  if (d.posed_frame != d.frame || d.posed.of != scene.closed_parts.get()) {
    d.posed = pose_closed_parts(*scene.closed_parts, scene.mesh.positions);
    d.posed_frame = d.frame;
  }
  faces_turned_away(d.posed, scene.mesh.positions, eye, d.away, rays_from, reach);
  return d.away;
}

void Renderer::start_raster(const Scene& scene, const Camera& camera, uint32_t width, uint32_t height) {
  settle_mirror_raster();  // its vertices are about to be written over
  Data& d = *data_;
  // The vertices: each triangle's three, with its index + 1 (an exact float below 2^24), on all cores.
  const auto stage = Clock::now();
  const std::vector<glm::vec3>& positions = scene.mesh.positions;
  const uint32_t triangles = uint32_t(scene.mesh.triangle_count());
  RasterView view{};
  const bool visible = raster_view(camera, int(width), int(height), positions, view);
  // The faces of closed parts turned away from the eye are left out: never a pixel's nearest
  // triangle, they cost llvmpipe's setup, which runs on one thread (faces_turned_away).
  const std::vector<uint8_t>& away = faces_away_from(scene, camera.eye, nullptr, camera.znear);
  constexpr uint32_t kChunk = 4096;
  const uint32_t chunks = chunk_count(triangles, kChunk);
  std::vector<uint32_t> first(size_t(chunks) + 1, 0);  // the triangles drawn before chunk c
  if (visible) {
    parallel_for_chunks(triangles, kChunk, 0, [&](uint32_t c, uint32_t begin, uint32_t end) {
      uint32_t drawn = 0;
      for (uint32_t t = begin; t < end; ++t) drawn += away.empty() || !away[t] ? 1u : 0u;
      first[c + 1] = drawn;
    });
    for (uint32_t c = 0; c < chunks; ++c) first[c + 1] += first[c];
  }
  d.raster_vertices.resize(size_t(first[chunks]) * 12);
  if (visible) {
    float* out = d.raster_vertices.data();
    parallel_for_chunks(triangles, kChunk, 0, [&](uint32_t c, uint32_t begin, uint32_t end) {
      float* v = out + size_t(first[c]) * 12;
      for (uint32_t t = begin; t < end; ++t) {
        if (!away.empty() && away[t]) continue;
        const float index = float(t + 1);
        for (uint32_t k = 0; k < 3; ++k, v += 4) {
          const glm::vec3& p = positions[3 * t + k];
          v[0] = p.x;
          v[1] = p.y;
          v[2] = p.z;
          v[3] = index;
        }
      }
    });
  }
  d.raster_start_ms = elapsed_ms(stage);  // the backend counts its own copy of the vertices
  backend_.start_raster(d.raster_vertices, view, width, height);
}

TracedGeneration Renderer::trace_rasterized(const Scene& scene, const Camera& camera, const FlatKdTree& tree,
                                            const RayBatch& rays, GenerationTimings& g, bool walk_edge_misses,
                                            bool started) {
  if (walk_edge_misses && tree.nodes.empty()) {
    throw Error(ErrorKind::Internal, "--primary raster: edge misses to walk a tree that has no nodes");
  }
  Data& d = *data_;
  const uint32_t width = rays.width, height = rays.rows();
  std::atomic<uint32_t> out_of_order{0};
  parallel_for_chunks(rays.count(), 16384, 0, [&](uint32_t, uint32_t begin, uint32_t end) {
    uint32_t wrong = 0;
    for (uint32_t i = begin; i < end; ++i) wrong += rays.pixel[i] != i ? 1u : 0u;
    if (wrong) out_of_order.fetch_add(wrong, std::memory_order_relaxed);
  });
  if (uint64_t(width) * height != rays.count() || out_of_order.load() != 0) {
    throw Error(ErrorKind::Internal, "--primary raster: the primary rays are not one per pixel in pixel order");
  }
  if (!started) start_raster(scene, camera, width, height);
  g.upload_ms += std::exchange(d.raster_start_ms, 0.0) + std::exchange(d.written_ms, 0.0);
  d.raster_texels.resize(rays.count());
  add_pass(g, backend_.finish_raster(d.raster_texels));

  TracedGeneration traced;
  traced.form = TracedGeneration::Form::PackedTexels;
  const int lights = pass_lights(int(shadow_lights(scene).size()));
  traced.packing = choose_packing(scene.primitive_count(), lights, scene.source);
  if (shadow_lights(scene).empty()) {
    // No shadow rays: the raster's texels are what the trace pass would write without them (index
    // + 1 in 24 bits, mask 0). A pass without shadow rays is made for 8 lights at most, so 24/8.
    if (traced.packing != Packing::Bits24_8) throw Error(ErrorKind::Internal, "--primary raster: 16/16 without shadows");
    traced.texels = d.raster_texels;
    return traced;
  }
  // Shadow rays from the rasterized hits: the trace pass specialised to PRIMARY_HITS, each ray's
  // index + 1 in its direction's w (its tmax is infinite: a primary ray's). Over the hits alone,
  // as the shading pass shades the hits alone: a miss needs no fragment (its texel is 0, no hit and
  // no shadow bits), and the Utah wood doll's rays mostly miss. The hits in pixel order, 8 to a 4x2
  // tile (order_in_simd_tiles' layout): neighbouring pixels in one SIMD group.
  const auto stage = Clock::now();
  constexpr uint32_t kChunk = 4096;
  const uint32_t n = rays.count();
  const uint32_t chunks = chunk_count(n, kChunk);
  std::vector<uint32_t> first(size_t(chunks) + 1, 0);
  parallel_for_chunks(n, kChunk, 0, [&](uint32_t c, uint32_t begin, uint32_t end) {
    uint32_t count = 0;
    for (uint32_t i = begin; i < end; ++i) count += d.raster_texels[i] != 0 ? 1u : 0u;
    first[c + 1] = count;
  });
  for (uint32_t c = 0; c < chunks; ++c) first[c + 1] += first[c];
  RayBatch& hit_rays = d.hit_rays;
  const uint32_t hit_count = first[chunks];
  hit_rays.width = width;
  hit_rays.unique_pixels = true;
  hit_rays.resize(hit_count);
  // The k-th hit straight to its place in the tiles (order_in_simd_tiles' layout, without its
  // second pass over the rays and their arrays allocated again).
  const uint32_t tiled = simd_tiled_rays(hit_rays);
  parallel_for_chunks(n, kChunk, 0, [&](uint32_t c, uint32_t begin, uint32_t end) {
    uint32_t k = first[c];
    for (uint32_t i = begin; i < end; ++i) {
      const uint32_t index_plus_one = d.raster_texels[i] & 0xFFFFFFu;
      if (index_plus_one == 0) continue;
      const uint32_t to = simd_tile_place(k, tiled, width);
      hit_rays.origin[to] = rays.origin[i];
      hit_rays.direction[to] = glm::vec4(glm::vec3(rays.direction[i]), float(index_plus_one));
      hit_rays.pixel[to] = i;  // the primary ray it stands for
      hit_rays.weight[to] = glm::vec3(0.0f);
      ++k;
    }
  });
  g.upload_ms += elapsed_ms(stage);
  traced.texels.assign(n, pack_trace(traced.packing, 0, 0));
  // Edge misses walk where the frame has a kd-tree, else keep their triangle (trace_main.glsl).
  trace_part(scene, tree, hit_rays, walk_edge_misses ? MOBIRT_PRIMARY_HITS_WALK : MOBIRT_PRIMARY_HITS_PLANE, g, traced);
  return traced;
}

void Renderer::trace_part(const Scene& scene, const FlatKdTree& tree, const RayBatch& part, int primary_hits,
                          GenerationTimings& g, TracedGeneration& out) {
  if (part.count() == 0) return;
  TraceResult result = trace_uploaded(scene, tree, part, primary_hits);
  add_pass(g, result.timing);
  g.walks += result.walks;
  if (result.packing != out.packing) throw Error(ErrorKind::Internal, "a pass over part of a generation packed otherwise");
  parallel_for(part.count(), 0, [&](uint32_t k) { out.texels[part.pixel[k]] = result.texels[k]; }, 4096);
}

namespace {
// Of `planes` planes counted per chunk (counts[c * planes + p], `chunks` chunks), the one with the
// largest total, the first on a tie, and that total.
std::pair<size_t, uint32_t> busiest_plane(const std::vector<uint32_t>& counts, uint32_t chunks, size_t planes) {
  size_t best = 0;
  uint32_t most = 0;
  for (size_t p = 0; p < planes; ++p) {
    uint32_t total = 0;
    for (uint32_t c = 0; c < chunks; ++c) total += counts[size_t(c) * planes + p];
    if (total > most) {
      most = total;
      best = p;
    }
  }
  return {best, most};
}
}  // namespace

const MirrorPlanes& Renderer::frame_mirror_planes(const Scene& scene) {
  Data& d = *data_;
  if (d.mirror_planes_checked == d.frame) return d.mirror_planes;
  // The planes handed in with the frame (found on the pipeline's worker), else those of the last
  // frame that looked, while its triangles and materials are the same.
  if (d.mirror_planes_frame != d.frame || d.mirror_planes.plane_of.size() != scene.mesh.triangle_count()) {
    std::vector<glm::vec2> materials(scene.materials.size());
    for (size_t m = 0; m < materials.size(); ++m) {
      materials[m] = glm::vec2(scene.materials[m].reflectance, scene.materials[m].transmittance);
    }
    if (d.mirror_positions != scene.mesh.positions || d.mirror_normals != scene.mesh.normals ||
        d.mirror_material_ids != scene.mesh.material_ids || d.mirror_materials != materials ||
        d.mirror_planes.plane_of.size() != scene.mesh.triangle_count()) {
      d.mirror_planes = find_mirror_planes(scene);
      ++d.mirror_plane_searches;
      d.mirror_positions = scene.mesh.positions;
      d.mirror_normals = scene.mesh.normals;
      d.mirror_material_ids = scene.mesh.material_ids;
      d.mirror_materials = std::move(materials);
    }
  }
  d.mirror_planes_checked = d.frame;
  return d.mirror_planes;
}

std::vector<MirrorPlane> Renderer::mirror_candidates(const Camera& camera, double on_plane,
                                                     std::vector<int>* candidate_of) const {
  const MirrorPlanes& planes = data_->mirror_planes;
  if (candidate_of) candidate_of->assign(planes.planes.size(), -1);
  // The planes facing the eye (up to the 8 largest), each turned to face it.
  const glm::dvec3 eye(camera.eye);
  std::vector<MirrorPlane> candidates;
  for (size_t p = 0; p < planes.planes.size() && candidates.size() < 8; ++p) {
    MirrorPlane plane = planes.planes[p];
    const double eye_side = glm::dot(plane.normal, eye) - plane.offset;
    if (std::abs(eye_side) <= on_plane) continue;  // the eye in the plane sees it edge-on
    if (eye_side < 0.0) {
      plane.normal = -plane.normal;
      plane.offset = -plane.offset;
    }
    if (candidate_of) (*candidate_of)[p] = int(candidates.size());
    candidates.push_back(plane);
  }
  return candidates;
}

// A mirror ray's origin is its hit point offset along the normal (secondary.cpp, offset_origin): by
// the absolute offset, at least a few ulps of the point, or (normal-ulp) up to 256 ulps of each
// coordinate. Twice that, and no more, counts as on the plane.
double Renderer::mirror_on_plane(const FlatKdTree& tree) const {
  const auto largest = [](const glm::dvec3& v) { return std::max({std::abs(v.x), std::abs(v.y), std::abs(v.z)}); };
  const double scale = std::max(largest(glm::dvec3(tree.bounds.lo)), largest(glm::dvec3(tree.bounds.hi)));
  const double absolute = double(absolute_offset(tree.bounds, settings_.secondary.offset));
  const double ulps = (settings_.secondary.offset.mode == OffsetMode::NormalUlp ? 300.0 : 8.0) * scale * 0x1p-23;
  return 2.0 * std::max(absolute, ulps);
}

bool Renderer::start_mirror_raster(const Scene& scene, const Camera& camera, const MirrorPlane& plane,
                                   double& prepare_ms) {
  const auto stage = Clock::now();
  settle_mirror_raster();  // its vertices are about to be written over
  Data& d = *data_;
  const uint32_t width = uint32_t(settings_.width), height = uint32_t(settings_.height);
  // The raster pass of the mirrored scene, clipped to the plane's front side.
  d.raster_vertices.clear();
  // The faces turned away from the eye's mirror image are left out, of the closed parts both the
  // eye and its image are outside of (faces_turned_away).
  const glm::dvec3 eye(camera.eye);
  const glm::dvec3 mirrored_eye = eye - 2.0 * (glm::dot(plane.normal, eye) - plane.offset) * plane.normal;
  mirrored_raster_vertices(scene.mesh.positions, plane, d.raster_vertices,
                           faces_away_from(scene, glm::vec3(mirrored_eye), &camera.eye, camera.znear));
  std::vector<glm::vec3> mirrored_positions(d.raster_vertices.size() / 4);
  for (size_t k = 0; k < mirrored_positions.size(); ++k) {
    mirrored_positions[k] = glm::vec3(d.raster_vertices[4 * k], d.raster_vertices[4 * k + 1], d.raster_vertices[4 * k + 2]);
  }
  RasterView view{};
  if (!raster_view(camera, int(width), int(height), mirrored_positions, view)) d.raster_vertices.clear();
  prepare_ms = elapsed_ms(stage);  // the backend counts its own copy of the vertices
  try {
    backend_.start_raster(d.raster_vertices, view, width, height);
  } catch (const Error& e) {
    // A raster pass over the device's limits (the frame's size): auto traces the mirror rays as
    // every other ray; --mirrors raster says which option to change.
    if (settings_.mirrors == MirrorHits::Auto && (e.kind() == ErrorKind::BadInput || e.kind() == ErrorKind::Unsupported)) {
      return false;
    }
    throw Error(e.kind(), std::string("--mirrors raster: ") + e.what() + " (or --mirrors trace)");
  }
  return true;
}

void Renderer::settle_mirror_raster() {
  if (std::exchange(data_->mirror_raster_pending, false)) backend_.drop_raster();
}

void Renderer::start_mirror_raster_ahead(const Scene& scene, const Camera& camera, const RayBatch& rays,
                                         const SurfaceHits& hits, GenerationTimings& g) {
  Data& d = *data_;
  const FlatKdTree& tree = d.tree;
  if (!d.tree_walkable || !frame_may_draw_mirrors(scene, settings_) || tree.nodes.empty() || rays.count() == 0 ||
      settings_.depth < 1) {
    return;
  }
  const uint32_t pixels = uint32_t(settings_.width) * uint32_t(settings_.height);
  if (rays.count() != pixels || hits.size() != rays.count()) return;  // not the primaries of a whole image
  const auto stage = Clock::now();
  const MirrorPlanes& planes = frame_mirror_planes(scene);
  std::vector<int> candidate_of;
  const std::vector<MirrorPlane> candidates = mirror_candidates(camera, mirror_on_plane(tree), &candidate_of);
  if (candidates.empty()) {
    g.upload_ms += elapsed_ms(stage);
    return;
  }
  // The primary hits on each candidate's reflective triangles: the mirror rays it will send, near
  // enough to pick the plane trace_mirrored picks from the rays themselves (where they differ, it
  // draws its own and this raster is thrown away).
  const size_t k = candidates.size();
  constexpr uint32_t kChunk = 8192;
  const uint32_t chunks = chunk_count(rays.count(), kChunk);
  std::vector<uint32_t> counts(size_t(chunks) * k, 0);
  const std::vector<int32_t>& plane_of = planes.plane_of;
  parallel_for_chunks(rays.count(), kChunk, 0, [&](uint32_t c, uint32_t begin, uint32_t end) {
    for (uint32_t i = begin; i < end; ++i) {
      if (!hits[i].valid()) continue;
      const int32_t prim = hits[i].prim;
      if (prim < 0 || size_t(prim) >= plane_of.size() || plane_of[size_t(prim)] < 0) continue;
      const int candidate = candidate_of[size_t(plane_of[size_t(prim)])];
      if (candidate >= 0) ++counts[size_t(c) * k + size_t(candidate)];
    }
  });
  const auto [best, most] = busiest_plane(counts, chunks, k);
  g.upload_ms += elapsed_ms(stage);
  if (most == 0 || (settings_.mirrors == MirrorHits::Auto && double(most) < kMirrorRasterMinShare * pixels)) return;
  double prepare_ms = 0.0;
  try {
    if (start_mirror_raster(scene, camera, candidates[best], prepare_ms)) {
      d.mirror_raster_pending = true;
      d.mirror_raster_plane = candidates[best];
      ++d.mirror_rasters_ahead.started;
    }
  } catch (const Error&) {
    // A raster the device refuses (--mirrors raster): not drawn ahead, nothing left in flight;
    // trace_mirrored reports it where the rays ask for that plane's raster, as it did before
    // rasters were started ahead.
    backend_.drop_raster();
  }
  g.upload_ms += prepare_ms;
}

bool Renderer::trace_mirrored(const Scene& scene, const Camera& camera, const FlatKdTree& tree, const RayBatch& rays,
                              GenerationTimings& g, TracedGeneration& out) {
  if (!frame_may_draw_mirrors(scene, settings_) || tree.nodes.empty() || rays.count() == 0) return false;
  const uint32_t width = uint32_t(settings_.width), height = uint32_t(settings_.height);
  const uint32_t pixels = width * height;
  Data& d = *data_;
  const auto stage = Clock::now();
  const MirrorPlanes& planes = frame_mirror_planes(scene);
  if (planes.planes.empty()) {
    g.upload_ms += elapsed_ms(stage);
    return false;
  }
  const double on_plane = mirror_on_plane(tree);
  const std::vector<MirrorPlane> candidates = mirror_candidates(camera, on_plane, nullptr);
  // Each ray's plane where it is a mirror ray off one: starting on it, leaving it on the eye's
  // side, the mirror image of its pixel's primary ray (the ray through the pixel centre, which the
  // raster pass samples; mirror_ray_plane). The plane that sends the most is drawn.
  const MirrorRayTest test{candidates, CameraBasis(camera, int(width), int(height)), width, height, on_plane};
  const uint32_t n = rays.count();
  constexpr uint8_t kNone = kNoMirrorPlane;
  std::vector<uint8_t> plane_of(n, kNone);
  constexpr uint32_t kChunk = 4096;
  const uint32_t chunks = chunk_count(n, kChunk);
  const size_t planes_tried = candidates.size();
  if (settings_.mirrors == MirrorHits::Auto) {
    // One ray in 16 first: a frame whose planes are far from auto's share is declined for a
    // sixteenth of the work (the Utah toasters' tray, under session 36's share of half: 0.7 ms a
    // frame for all its rays).
    std::vector<uint32_t> sampled(planes_tried + 1, 0);
    for (uint32_t i = 0; i < n; i += 16) {
      const uint8_t p = mirror_ray_plane(test, rays, i);
      ++sampled[p == kNone ? planes_tried : size_t(p)];
    }
    const uint32_t most = planes_tried == 0 ? 0 : *std::max_element(sampled.begin(), sampled.end() - 1);
    if (16.0 * most < 0.75 * kMirrorRasterMinShare * pixels) {
      g.upload_ms += elapsed_ms(stage);
      return false;
    }
  }
  // Every ray, four at a time in vector lanes where the CPU has AVX2 (mirror_ray_planes: the
  // scalar test took 0.6-0.8 ms of the rendering thread's frame on the toaster and the marbles).
  std::vector<uint32_t> counts(size_t(chunks) * planes_tried, 0);
  parallel_for_chunks(n, kChunk, 0, [&](uint32_t c, uint32_t begin, uint32_t end) {
    mirror_ray_planes(test, rays, begin, end, plane_of.data());
    for (uint32_t i = begin; i < end; ++i) {
      if (plane_of[i] != kNone) ++counts[size_t(c) * planes_tried + plane_of[i]];
    }
  });
  const auto [best, mirrored] = busiest_plane(counts, chunks, planes_tried);
  if (mirrored == 0 || (settings_.mirrors == MirrorHits::Auto && double(mirrored) < kMirrorRasterMinShare * pixels)) {
    g.upload_ms += elapsed_ms(stage);
    return false;
  }
  const MirrorPlane& plane = candidates[best];
  const MirrorPlane& ahead = d.mirror_raster_plane;
  if (d.mirror_raster_pending && ahead.normal == plane.normal && ahead.offset == plane.offset) {
    d.mirror_raster_pending = false;  // started ahead for this plane: its vertices are this one's
    ++d.mirror_rasters_ahead.taken;
    g.upload_ms += elapsed_ms(stage);
  } else {
    g.upload_ms += elapsed_ms(stage);
    double prepare_ms = 0.0;  // the raster started ahead for another plane, if any, dropped first
    const bool started = start_mirror_raster(scene, camera, plane, prepare_ms);
    g.upload_ms += prepare_ms;
    if (!started) return false;
  }
  d.raster_texels.resize(pixels);
  add_pass(g, backend_.finish_raster(d.raster_texels));

  // The mirror rays that met a triangle, with its index + 1, through the PRIMARY_HITS pass (their
  // shadow rays, and a walk where the raster's triangle misses at an edge); the other rays walk in
  // the same pass (below).
  const auto split = Clock::now();
  RayBatch& hit_rays = d.hit_rays;
  hit_rays.clear();
  hit_rays.width = rays.width;
  hit_rays.unique_pixels = false;
  // In the generation's coherent order (the k-th ray of the order sits at simd_tile_place(k)), so
  // that each part, laid out in tiles again, keeps neighbouring rays in one SIMD group. One pass
  // for both parts (a pass has a fixed cost: the toaster's 983 other rays took 0.9-1.3 ms in a
  // pass of their own): the other rays after the mirror hits, their w MOBIRT_HIT_UNKNOWN, so that
  // they walk (trace_main.glsl); each part keeps its tiles, so a SIMD group mixes the two only
  // where the first part ends. Counted per chunk, then each ray written straight to its tile place
  // (order_in_simd_tiles' layout) on all cores: one thread's push_back and a second pass to tile
  // them were 0.3 ms of the toaster's frame.
  const uint32_t tiled = simd_tiled_rays(rays);
  std::vector<uint32_t> hits_before(size_t(chunks) + 1, 0), rest_before(size_t(chunks) + 1, 0);
  const auto mirror_hit = [&](uint32_t i) { return (d.raster_texels[rays.pixel[i]] & 0xFFFFFFu) != 0; };
  parallel_for_chunks(n, kChunk, 0, [&](uint32_t c, uint32_t begin, uint32_t end) {
    uint32_t hits = 0, rest = 0;
    for (uint32_t k = begin; k < end; ++k) {
      const uint32_t i = simd_tile_place(k, tiled, rays.width);
      if (plane_of[i] != uint8_t(best)) {
        ++rest;
      } else if (mirror_hit(i)) {  // else the mirror shows nothing there: a miss
        ++hits;
      }
    }
    hits_before[c + 1] = hits;
    rest_before[c + 1] = rest;
  });
  for (uint32_t c = 0; c < chunks; ++c) {
    hits_before[c + 1] += hits_before[c];
    rest_before[c + 1] += rest_before[c];
  }
  const uint32_t hit_count = hits_before[chunks];
  const size_t rest_count = rest_before[chunks];
  const uint32_t total = hit_count + uint32_t(rest_count);
  hit_rays.resize(total);
  const uint32_t tiled_out = simd_tiled_rays(hit_rays);
  parallel_for_chunks(n, kChunk, 0, [&](uint32_t c, uint32_t begin, uint32_t end) {
    uint32_t next_hit = hits_before[c], next_rest = hit_count + rest_before[c];
    // Ray i of the generation as the j-th of the pass, its direction's w the hit's index + 1 or
    // MOBIRT_HIT_UNKNOWN.
    const auto put = [&](uint32_t j, uint32_t i, float w) {
      const uint32_t to = simd_tile_place(j, tiled_out, hit_rays.width);
      hit_rays.origin[to] = rays.origin[i];
      hit_rays.direction[to] = glm::vec4(glm::vec3(rays.direction[i]), w);
      hit_rays.pixel[to] = i;  // the ray it stands for
      hit_rays.weight[to] = glm::vec3(0.0f);
    };
    for (uint32_t k = begin; k < end; ++k) {
      const uint32_t i = simd_tile_place(k, tiled, rays.width);
      if (plane_of[i] != uint8_t(best)) {
        put(next_rest++, i, float(MOBIRT_HIT_UNKNOWN));
      } else if (mirror_hit(i)) {
        put(next_hit++, i, float(d.raster_texels[rays.pixel[i]] & 0xFFFFFFu));
      }
    }
  });
  g.upload_ms += elapsed_ms(split);
  g.mirrored += mirrored;
  out = TracedGeneration{};
  out.form = TracedGeneration::Form::PackedTexels;
  const int lights = pass_lights(int(shadow_lights(scene).size()));
  out.packing = choose_packing(scene.primitive_count(), lights, scene.source);
  out.texels.assign(n, pack_trace(out.packing, 0, 0));
  trace_part(scene, tree, hit_rays, MOBIRT_PRIMARY_HITS_WALK, g, out);
  g.walks += rest_count;  // their closest hits walk (the pass counts its shadow rays' walks)
  return true;
}

int Renderer::pass_lights(int scene_lights) const {
  if (settings_.specialize) return scene_lights;
  return scene_lights <= MOBIRT_MAX_LIGHTS_24_8 ? MOBIRT_MAX_LIGHTS_24_8 : MOBIRT_MAX_LIGHTS_16_16;
}

std::span<const Light> Renderer::shadow_lights(const Scene& scene) const {
  return settings_.shadows ? std::span<const Light>(scene.lights) : std::span<const Light>();
}

void Renderer::upload_materials(const Scene& scene) {
  std::vector<MaterialTexels> materials;
  materials.reserve(scene.materials.size());
  for (const Material& m : scene.materials) {
    materials.push_back({m.diffuse, float(m.texture), m.specular, m.shininess, m.reflectance, m.transmittance, m.ior,
                         m.ambient});
  }
  Data& d = *data_;
  ensure_texture(d.materials.handle, d.materials.rows, kDataWidth,
                 data_rows(materials.size() * MOBIRT_TEXELS_PER_MATERIAL), TexelFormat::RGBA32F, data_kind_);
  backend_.upload(d.materials.handle, materials.data(), materials.size() * sizeof(MaterialTexels));
}

namespace {
constexpr uint32_t kShadeChunk = 1024;  // rays a chunk of the shading inputs' loops takes
}  // namespace

std::vector<glm::vec3> Renderer::shade(const Scene& scene, const RayBatch& rays,
                                       const SurfaceHits& hits, GenerationTimings& timings) {
  if (!data_->shade_queue.empty()) {
    throw Error(ErrorKind::Internal, "Renderer::shade: generations are queued for the frame's shading");
  }
  try {
    queue_shade(scene, rays, hits, timings);
    std::vector<std::vector<glm::vec3>> colors = shade_queued(scene, std::span<GenerationTimings>(&timings, 1));
    return std::move(colors.front());
  } catch (...) {
    drop_shade_queue();  // the next call starts with an empty queue
    throw;
  }
}

void Renderer::queue_shade(const Scene& scene, const RayBatch& rays, const SurfaceHits& hits,
                           GenerationTimings& timings) {
  // The shading pass shades the hits only, compacted, and one miss: a miss's colour is the
  // background's, the same for every miss (glsl/shade_main.glsl), so the one texel the pass writes
  // for it serves them all, bit for bit, in every generation the pass shades. A pass over every ray
  // ran the whole Phong code for groups of 8 fragments that all missed (the shader has no branch
  // around it; llvmpipe skips an `if` only when no lane of a group takes it, and a group with one
  // hit runs it for all 8) and uploaded, read back and decoded a texel per miss: the Utah wood
  // doll's rays mostly miss.
  //
  // Its inputs, one texel per shaded ray: position and material, normal and shadow bits, the ray's
  // direction, and texture coordinates where the scene has textures (the CPU computed them in
  // decoding). On all cores in chunks, into arrays not zeroed first: every texel is written below.
  Data& d = *data_;
  const uint32_t n = rays.count();
  if (rays.width == 0 && n > 0) {
    throw Error(ErrorKind::Internal, "Renderer::shade: a batch of rays with rows of width 0");
  }
  if (hits.size() != n) throw Error(ErrorKind::Internal, "Renderer::shade: not one surface record per ray");
  Data::QueuedShade q;
  q.rays = n;
  if (n == 0) {
    q.shaded = true;  // nothing to shade: no pass, no colour
    d.shade_queue.push_back(std::move(q));
    return;
  }
  // One scene per queue (its atlas and materials are the pass's), and one ray layout for every
  // generation a pass shades (a frame's generations share it).
  if (!d.shade_queue.empty() && d.shade_queue_scene != &scene) {
    throw Error(ErrorKind::Internal, "Renderer::queue_shade: generations of another scene are queued");
  }
  d.shade_queue_scene = &scene;
  if (d.shade_inputs_open && rays.width != d.ray_width) shade_pending(scene);
  fit_ray_layout(rays.width);
  prepare_atlas(scene);  // says whether the scene has textures
  auto stage = Clock::now();
  const uint32_t chunks = chunk_count(n, kShadeChunk);
  // first[c + 1]: the hits of chunk c, counted from the records' hit bytes (SurfaceHits), never
  // from the records, which exist for the hits only; chunks without a hit are skipped below.
  const uint8_t* hit = hits.hit_flags();
  q.first.assign(size_t(chunks) + 1, 0);
  parallel_for_chunks(n, kShadeChunk, 0, [&](uint32_t c, uint32_t begin, uint32_t end) {
    uint32_t count = 0;
    for (uint32_t i = begin; i < end; ++i) count += hit[i] != 0 ? 1u : 0u;
    q.first[c + 1] = count;
  });
  for (uint32_t c = 0; c < chunks; ++c) q.first[c + 1] += q.first[c];
  q.hits = q.first[chunks];
  const bool any_miss = q.hits < n;
  q.hit.assign(hit, hit + n);
  timings.decode_ms += elapsed_ms(stage);
  // Room for these hits and a miss after those queued; where there is none, those are shaded first.
  if (d.shade_inputs_open && uint64_t(d.shade_texels) + q.hits + 1 > d.shade_capacity) shade_pending(scene);
  if (!d.shade_inputs_open) {
    // The last frame's room where the backend can make it; else room for this generation alone
    // (its later generations then shaded early), as one pass a generation needs.
    try {
      open_shade_inputs(std::max(q.hits + 1, d.shade_texels_hint));
    } catch (const Error& e) {
      if (e.kind() != ErrorKind::BadInput || d.shade_texels_hint <= q.hits + 1) throw;
      d.shade_texels_hint = 0;
      open_shade_inputs(q.hits + 1);
    }
  }
  stage = Clock::now();
  const uint32_t base = d.shade_texels;
  for (uint32_t c = 0; c <= chunks; ++c) q.first[c] += base;
  auto* position = reinterpret_cast<HitPositionTexel*>(d.shade_inputs[0].writer->data());
  auto* normal = reinterpret_cast<HitNormalTexel*>(d.shade_inputs[1].writer->data());
  glm::vec4* direction = d.shade_inputs[2].writer->data();
  auto* uv = d.has_atlas ? reinterpret_cast<HitTexcoordTexel*>(d.shade_inputs[3].writer->data()) : nullptr;
  parallel_for_chunks(n, kShadeChunk, 0, [&](uint32_t c, uint32_t begin, uint32_t end) {
    if (q.first[c + 1] == q.first[c]) return;
    uint32_t k = q.first[c];
    for (uint32_t i = begin; i < end; ++i) {
      if (!hit[i]) continue;
      const SurfaceHit& h = hits[i];
      position[k] = HitPositionTexel{h.position, float(h.material)};
      normal[k] = HitNormalTexel{h.normal, float(h.mask)};
      direction[k] = rays.direction[i];
      if (uv) uv[k] = HitTexcoordTexel{h.texcoord, glm::vec2(0.0f)};
      ++k;
    }
  });
  d.shade_texels += q.hits;
  d.shade_miss = d.shade_miss || any_miss;
  timings.decode_ms += elapsed_ms(stage);
  d.shade_queue.push_back(std::move(q));
}

void Renderer::open_shade_inputs(uint32_t texels) {
  Data& d = *data_;
  const uint32_t width = d.ray_width;
  const uint32_t rows = uint32_t((uint64_t(texels) + width - 1) / width);
  Data::Texture* textures[] = {&d.hit_position, &d.hit_normal, &d.shade_direction, &d.hit_texcoord};
  const int used = d.has_atlas ? 4 : 3;
  uint32_t capacity_rows = UINT32_MAX;
  for (int i = 0; i < used; ++i) {
    ensure_texture(textures[i]->handle, textures[i]->rows, width, rows, TexelFormat::RGBA32F, data_kind_);
    capacity_rows = std::min(capacity_rows, textures[i]->rows);
  }
  d.shade_capacity = uint32_t(std::min<uint64_t>(uint64_t(capacity_rows) * width, UINT32_MAX));
  for (int i = 0; i < 4; ++i) {
    Data::ShadeInput& in = d.shade_inputs[size_t(i)];
    in.writer.reset();
    if (i < used) in.writer.emplace(backend_, textures[i]->handle, d.shade_capacity, &in.kept);
  }
  d.shade_inputs_open = true;
}

void Renderer::close_shade_inputs(uint32_t texels) {
  Data& d = *data_;
  if (!d.shade_inputs_open) return;
  d.shade_inputs_open = false;
  for (Data::ShadeInput& in : d.shade_inputs) {
    if (!in.writer) continue;
    // An upload where not written in place: the backend counts it in the pass's upload.
    in.writer->done(texels);
    in.writer.reset();
  }
}

void Renderer::shade_pending(const Scene& scene) {
  Data& d = *data_;
  settle_mirror_raster();  // no pass runs while a raster is in flight (Backend::start_raster)
  const uint32_t hit_count = d.shade_texels;
  const bool any_miss = d.shade_miss;
  const uint32_t shaded = hit_count + (any_miss ? 1u : 0u);  // the miss last
  if (any_miss) {
    reinterpret_cast<HitPositionTexel*>(d.shade_inputs[0].writer->data())[hit_count] = HitPositionTexel::miss();
    reinterpret_cast<HitNormalTexel*>(d.shade_inputs[1].writer->data())[hit_count] =
        HitNormalTexel{glm::vec3(0.0f), 0.0f};
    (*d.shade_inputs[2].writer)[hit_count] = glm::vec4(0.0f, 0.0f, -1.0f, 0.0f);  // not read for a miss
    if (d.has_atlas) {
      reinterpret_cast<HitTexcoordTexel*>(d.shade_inputs[3].writer->data())[hit_count] =
          HitTexcoordTexel{glm::vec2(0.0f), glm::vec2(0.0f)};
    }
  }
  close_shade_inputs(shaded);
  d.shade_texels = 0;
  d.shade_miss = false;
  if (shaded == 0) return;  // nothing queued but generations without rays

  const uint32_t width = d.ray_width;
  const bool textured = d.has_atlas;
  const TextureHandle texcoords = textured ? d.hit_texcoord.handle : d.hit_position.handle;
  // A general pass is sized for the most lights, textures and pages, not for this scene.
  const int texture_count = settings_.specialize ? int(d.atlas_data.tiles.size()) : MOBIRT_ATLAS_MAX_TEXTURES;
  const int pages = settings_.specialize ? d.atlas_data.page_count() : MOBIRT_ATLAS_MAX_PAGES;
  const int lights = pass_lights(int(scene.lights.size()));
  std::vector<float> uniforms = shade_uniforms(scene, lights);
  append_atlas_uniforms(d.atlas_data, lights, uniforms);
  const size_t uniform_floats = 4 * size_t(MOBIRT_SP_TEXTURES(lights) + MOBIRT_SP_VEC4S_PER_TEXTURE * texture_count);
  if (uniforms.size() < uniform_floats) uniforms.resize(uniform_floats, 0.0f);
  // A slot beyond the scene's pages gets its last page: bound, never read.
  const auto page = [&](size_t i) { return d.atlas_pages[std::min(i, d.atlas_pages.size() - 1)]; };
  const TextureHandle textures[] = {d.hit_position.handle, d.hit_normal.handle, d.materials.handle,
                                    d.shade_direction.handle, texcoords, page(0), page(1), page(2)};
  const bool wide = wide_indices({{d.hit_position.rows, width}, {d.hit_normal.rows, width},
                                  {d.materials.rows, kDataWidth}, {d.shade_direction.rows, width},
                                  {textured ? d.hit_texcoord.rows : 0u, width}});
  // 16-bit colour: the same shading twice, the high bytes, then the low bytes of each channel.
  const bool deep = settings_.colour == ColourDepth::Bits16;
  std::vector<uint32_t> texels[2];
  PassTiming total;
  for (int half = 0; half < (deep ? 2 : 1); ++half) {
    const int colour = !deep ? MOBIRT_COLOUR_8 : half == 0 ? MOBIRT_COLOUR_16_HIGH : MOBIRT_COLOUR_16_LOW;
    texels[half].resize(shaded);
    const PassTiming pass = backend_.run_pass(shade_pass(lights, texture_count, pages, colour, wide), textures, uniforms,
                                              width, shaded, texels[half]);
    total.upload_ms += pass.upload_ms;
    total.gpu_ms += pass.gpu_ms;
    total.readback_ms += pass.readback_ms;
    total.bytes_read += pass.bytes_read;
  }
  ++d.shading_passes;
  const auto decoded = [&](uint32_t k) {
    return deep ? decode_colour(texels[0][k], texels[1][k]) : decode_colour(texels[0][k]);
  };
  const glm::vec3 miss_colour = any_miss ? decoded(hit_count) : glm::vec3(0.0f);
  // The pass's cost shared among the generations it shaded by their shaded texels (the miss's
  // goes to the first with a miss).
  bool miss_counted = !any_miss;
  for (Data::QueuedShade& q : d.shade_queue) {
    if (q.shaded) continue;
    q.shaded = true;
    const uint32_t own = q.hits + (!miss_counted && q.hits < q.rays ? 1u : 0u);
    miss_counted = miss_counted || own > q.hits;
    const double share = double(own) / double(shaded);
    q.pass.upload_ms = total.upload_ms * share;
    q.pass.shade_ms = total.gpu_ms * share;
    q.pass.shade_readback_ms = total.readback_ms * share;
    q.pass.bytes_read = uint64_t(double(total.bytes_read) * share + 0.5);
    q.pass.shaded = own;
    const auto stage = Clock::now();
    q.colors.resize(q.rays);
    parallel_for_chunks(q.rays, kShadeChunk, 0, [&](uint32_t c, uint32_t begin, uint32_t end) {
      uint32_t k = q.first[c];
      for (uint32_t i = begin; i < end; ++i) q.colors[i] = q.hit[i] ? decoded(k++) : miss_colour;
    });
    q.pass.accumulate_ms = elapsed_ms(stage);
    std::vector<uint8_t>().swap(q.hit);
  }
}

std::vector<std::vector<glm::vec3>> Renderer::shade_queued(const Scene& scene, std::span<GenerationTimings> timings) {
  Data& d = *data_;
  if (timings.size() != d.shade_queue.size()) {
    throw Error(ErrorKind::Internal, "Renderer::shade_queued: " + std::to_string(timings.size()) +
                                         " generations' timings for " + std::to_string(d.shade_queue.size()) +
                                         " queued");
  }
  if (d.shade_inputs_open || std::any_of(d.shade_queue.begin(), d.shade_queue.end(),
                                         [](const Data::QueuedShade& q) { return !q.shaded; })) {
    shade_pending(scene);
  }
  uint32_t frame_texels = 1;  // the room the next frame opens with: this one's hits and a miss
  for (const Data::QueuedShade& q : d.shade_queue) frame_texels += q.hits;
  d.shade_texels_hint = frame_texels;
  std::vector<std::vector<glm::vec3>> colors;
  colors.reserve(d.shade_queue.size());
  for (size_t k = 0; k < d.shade_queue.size(); ++k) {
    Data::QueuedShade& q = d.shade_queue[k];
    GenerationTimings& g = timings[k];
    g.upload_ms += q.pass.upload_ms;
    g.shade_ms += q.pass.shade_ms;
    g.shade_readback_ms += q.pass.shade_readback_ms;
    g.bytes_read += q.pass.bytes_read;
    g.shaded += q.pass.shaded;
    g.accumulate_ms += q.pass.accumulate_ms;
    colors.push_back(std::move(q.colors));
  }
  d.shade_queue.clear();
  d.shade_queue_scene = nullptr;
  return colors;
}

void Renderer::drop_shade_queue() {
  Data& d = *data_;
  d.shade_texels = 0;
  d.shade_miss = false;
  d.shade_queue.clear();
  d.shade_queue_scene = nullptr;
  close_shade_inputs(0);  // last: the queue is empty even where closing throws
}

size_t Renderer::shading_passes() const { return data_->shading_passes; }

void Renderer::check_shades_like(const RenderSettings& frame, const char* who) const {
  if (settings_.colour != frame.colour || settings_.specialize != frame.specialize) {
    throw Error(ErrorKind::Internal, std::string(who) + ": the shading renderer was made with other settings "
                                                        "(colour depth or specialisation) than the frame's");
  }
}

std::vector<glm::vec3> Renderer::shade_traced_elsewhere(const Scene& scene, const RayBatch& rays,
                                                        const SurfaceHits& hits, GenerationTimings& timings) {
  // The shading pass reads the hits' directions, which shade() uploads itself: the traversal
  // pass's ray textures, which such an engine never used, are not uploaded (they were until the
  // shading pass shaded the hits only, and counted in the peers' upload stage).
  return shade(scene, rays, hits, timings);
}

Image Renderer::render(const Scene& scene, const Camera& camera, FrameTimings* timings) {
  data_->posed_prebuilt = false;  // a pose handed in with a frame that never started is not this one's
  data_->mirror_planes_prebuilt = false;
  return render_whitted(scene, camera, settings_, *engine_, timings);
}

Image Renderer::render(const Scene& scene, const Camera& camera, FlatKdTree& tree, double build_ms,
                       FrameTimings* timings, std::vector<LightBuffer>* light_buffers, PosedParts* posed,
                       MirrorPlanes* mirror_planes) {
  Data& d = *data_;
  std::swap(d.tree, tree);
  // Kept as the cache of the triangles the tree was built on, as a tree built here would be; valid
  // once begin_frame has uploaded it (a frame refused before that leaves no cache). Not where every
  // frame builds its own (always_rebuild: the cache is never looked at; the copy was 0.1 ms a frame).
  if (!settings_.always_rebuild) {
    d.tree_positions = scene.mesh.positions;
    d.tree_shapes = scene.shapes;
  }
  d.tree_valid = false;
  d.tree_prebuilt = true;
  d.prebuilt_ms = build_ms;
  d.light_buffers_prebuilt = light_buffers != nullptr;
  if (light_buffers) std::swap(d.prebuilt_light_buffers, *light_buffers);
  d.posed_prebuilt = posed && posed->of == scene.closed_parts.get() && posed->of != nullptr;
  if (d.posed_prebuilt) std::swap(d.posed, *posed);
  d.mirror_planes_prebuilt = mirror_planes != nullptr;
  if (mirror_planes) {
    std::swap(d.mirror_planes, *mirror_planes);
    d.mirror_positions.clear();  // the cache holds the handed planes now, not those of its keys
    d.mirror_normals.clear();
    d.mirror_material_ids.clear();
    d.mirror_materials.clear();
  }
  return render_whitted(scene, camera, settings_, *engine_, timings);
}

}  // namespace mobirt
