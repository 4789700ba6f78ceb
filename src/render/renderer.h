// One frame through the paper's passes: CPU kd-tree build and primary rays, the GPU traversal pass
// (closest hit + shadow rays), CPU hit decoding, the GPU shading pass. The backend is only seen
// through src/backend/backend.h, so the same renderer drives Vulkan and OpenGL ES. The passes are a
// WhittedEngine (render/engine.h); the frame around them is render_whitted() (render/whitted.h).
#pragma once

#include <cstdint>
#include <initializer_list>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "accel/closed_parts.h"
#include "accel/kdtree.h"
#include "accel/light_buffer.h"
#include "backend/backend.h"
#include "core/camera.h"
#include "raytree/mirror_planes.h"
#include "core/image.h"
#include "raytree/hits.h"
#include "raytree/packing.h"
#include "raytree/rays.h"
#include "raytree/secondary.h"
#include "render/engine.h"
#include "scene/scene.h"

namespace mobirt {

// How the traversal pass reads the scene data (nodes, leaf entries, triangles): uniform texel
// buffers where the backend has them (Vulkan), else 2D images; images always on OpenGL ES 2.0.
// StorageBuffers (Vulkan; else images): read-only storage buffers, a measurement variant that
// breaks the ES 2.0 model by name (shader_constraints.h: kEs2StorageReads). DeviceAddresses (Vulkan
// with VK_KHR_buffer_device_address; else images): the same buffers read through their addresses,
// the same kind of measurement variant (what llvmpipe's texture-function calls cost).
enum class DataReads { TexelBuffers, Images, StorageBuffers, DeviceAddresses };

// How the primary rays' closest hits are found. Trace: through the kd-tree, as every other
// generation (the paper's pipeline). Raster: the triangles drawn with a depth test
// (Backend::run_raster), each pixel centre's closest triangle found by the rasterizer where the
// primary ray through it would find it by a walk, a hybrid renderer's G-buffer step; the shadow
// rays then start from that triangle's hit (glsl/trace_main.glsl, PRIMARY_HITS), and a frame
// without secondary rays whose shadow rays all test light buffers builds no kd-tree at all
// (frame_walks_tree). Pixels whose centre lies on an edge between two triangles may take the other
// one (README, *Primary hits rasterized*). A scene with analytic shapes (spheres, cones) has its primaries traced. Auto (the
// default): rasterized where that is measured to be faster (raster_pays), traced elsewhere.
enum class PrimaryHits { Trace, Raster, Auto };
const char* primary_hits_name(PrimaryHits primary);

// How the first secondary generation's mirror rays off a flat mirror find their closest hits
// (src/raytree/mirror_planes.h): Trace, through the kd-tree like every ray (the paper's pipeline);
// Raster, drawn by a raster pass of the scene mirrored in the mirror's plane and clipped to its
// front side, seen from the camera, for the rays off the mirror plane that sends the most (of the
// 8 largest; each the mirror image of its pixel's primary ray), their shadow rays then traced from
// those hits as the rasterized primaries' are; the other rays walk. Auto (the default): Raster
// where one plane sends mirror rays from at least a quarter of the pixels (kMirrorRasterMinShare)
// and the mesh has at most kRasterTrianglesPerPixel triangles a pixel, else Trace (also where the
// raster pass is over the device's limits): measured, the toaster's floor (54 % of the pixels),
// the marbles' (84 %), and since session 37 (--tree walks, the rest pass in coherent tiles) also
// the Utah toasters' (35 %) and the fish's table (34 %) made their frames faster (README, *Flat
// mirrors rasterized*).
enum class MirrorHits { Trace, Raster, Auto };
// Whether --data device-addresses is refused on this device: llvmpipe (a software device) on a CPU
// with AVX-512, where its reads through buffer references faulted at random (a masked gather whose
// inactive lanes held non-canonical addresses: seen on a Zen 4, 2026-12-06, in every kind of frame).
bool device_address_reads_fault(const DeviceInfo& info);
const char* mirror_hits_name(MirrorHits mirrors);
inline constexpr double kMirrorRasterMinShare = 0.25;

// What an animation's per-frame kd-tree is built for (--tree). Walks (the default): for the walks
// of the kd-tree two frames before it (GenerationTimings::walks, handed to KdBuildOptions::rays by
// the FramePipeline), so that a frame whose rays are mostly drawn (--primary raster, --mirrors) or
// test light buffers gets the shallow tree those few walks pay for; Full: every tree for
// unboundedly many rays, the SAH's own termination alone (the paper's). The first two frames of a
// pipeline, and every tree built outside one, are full trees.
enum class TreeFit { Full, Walks };
const char* tree_fit_name(TreeFit fit);

// How a frame's hits are shaded: Frame, one shading pass over every generation's hits after the
// last generation (two for 16-bit colour; more where the inputs' textures opened for the frame fill
// up, Renderer::queue_shade), the pass's fixed cost paid once a frame (WhittedEngine::shades_at_end);
// Generation, one pass per generation as it is decoded. The same colours and image either way.
enum class ShadingPasses { Frame, Generation };
const char* shading_passes_name(ShadingPasses passes);

// The pipelined frame loop's worker (FramePipeline: posing frame N + 1 and building its kd-tree
// while frame N renders). Idle: at Linux's SCHED_IDLE (core/thread_priority.h), so that it only
// fills CPU time nothing else wants; lavapipe's rasterizer threads are pinned one per CPU
// (--pin-threads) and, with the worker at the normal class, waited up to a scheduler slice (about
// 1 ms, perf sched) for the CPU it held before a pass could finish. Normal: the default class.
enum class WorkerPriority { Idle, Normal };
const char* worker_priority_name(WorkerPriority priority);

// --cpu-walks's default (RenderSettings::cpu_walks; README, *Small generations on the CPU*).
inline constexpr int kAutoCpuWalks = 8192;

struct RenderSettings {
  int width = 400;
  int height = 240;
  int depth = 2;            // bounces: 0 = ray casting, N = up to N generations of secondary rays
  bool shadows = true;      // false: no shadow rays, every light lights every surface facing it
  // Short-stack entries in the traversal shader, 0 = pure kd-restart. 6: on Mesa 25.0.7 with fast's
  // leaves of 3, 2.7-4.3 % fewer JIT instructions than 4 and the passes 1-8 % faster (README,
  // *Shader profiling*); 8 is no better than 6.
  int stack_depth = 6;
  int max_steps = 2048;     // loop cap of one traversal in the shader (see README: "Loop cap")
  // --cpu-walks N: a secondary generation of at most N rays (not drawn by the mirror raster) is
  // walked on the CPU (traverse_fast, its shadow rays through the same light buffers or walks as
  // the pass's) instead of a traversal pass: a few incoherent rays fill few of a pass's 8 lanes and
  // do not pay for its fixed cost. The same hits and masks, so the same image; 0 = always a pass.
  int cpu_walks = kAutoCpuWalks;
  // Passes specialised to the scene (light and texture counts, packing) or general ones sized for
  // the most a pass supports; both give the same image (tests/specialisation_test.cpp).
  bool specialize = true;
  // Rebuild the kd-tree every frame even when the triangles did not move (the paper's model, and
  // the benchmarks'); by default a static scene keeps its tree.
  bool always_rebuild = false;
  // Set by the caller where each frame it renders poses the triangles anew (an animation played
  // frame by frame), so that each frame builds a tree: --primary auto's choice counts it as
  // always_rebuild does (raster_pays). A still scene keeps its tree from frame to frame.
  bool tree_per_frame = false;
  // The shading pass's colour: 8 bits per channel, or 16 from two passes (high and low bytes).
  ColourDepth colour = ColourDepth::Bits8;
  DataReads data = DataReads::TexelBuffers;  // faster on lavapipe (README: "Data reads")
  PrimaryHits primary = PrimaryHits::Auto;
  MirrorHits mirrors = MirrorHits::Auto;
  TreeFit tree = TreeFit::Walks;
  ShadingPasses shading = ShadingPasses::Frame;
  // The pipelined loop's worker (FramePipeline). Normal here, so that a program or a test running
  // beside other load never waits on a starved worker; the CLI (render --frames, bench) defaults
  // to Idle (src/app/options.cpp), the faster on a machine of its own.
  WorkerPriority worker = WorkerPriority::Normal;
  // --shadow-cells N: point and spot lights' shadow rays test the triangles of one cell of a light
  // buffer of N x N cells per cube face (src/accel/light_buffer.h) instead of walking the kd-tree;
  // 0: they walk it; -1 (auto, the default): kAutoShadowCells up to kAutoShadowCellsTriangles
  // triangles under highp, else 0. Scenes of triangles only; directional lights always walk, and so do lights
  // whose lists run long (kLightBufferMaxMeanList).
  int shadow_cells = -1;
  KdBuildOptions kd;
  ShadowSettings shadow_rays;  // also the ray/triangle test and precision of every traced ray
  SecondarySettings secondary;
};

// The read-back result of one traversal pass.
struct TraceResult {
  std::vector<uint32_t> texels;  // one packed texel per ray
  Packing packing = Packing::Bits24_8;
  PassTiming timing;
  uint64_t walks = 0;  // GenerationTimings::walks of the pass
};

class Renderer {
 public:
  Renderer(Backend& backend, const RenderSettings& settings);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // One frame: ray casting, shadows and up to settings.depth bounces; width x height.
  Image render(const Scene& scene, const Camera& camera, FrameTimings* timings = nullptr);
  // The same frame with a kd-tree built elsewhere over scene.mesh.positions as they are now (the
  // frame pipeline's worker, render/frame_pipeline.h), uploaded instead of built; timings->build_ms
  // is `build_ms`, the build's own wall clock. The tree is swapped in: `tree` comes back holding
  // the renderer's previous one, whose arrays the caller's next rebuild_kdtree reuses.
  // light_buffers: the frame's, built with the tree (frame_light_buffers; swapped in as the tree
  // is), or null: the renderer builds them. posed: the closed parts as posed for them (swapped in
  // when it has any), spared the raster passes' own pose of the frame (faces_away_from).
  // mirror_planes: the frame's flat mirrors (find_mirror_planes over scene as it is now; swapped
  // in), or null: the renderer finds them where a frame may draw them (frame_may_draw_mirrors).
  Image render(const Scene& scene, const Camera& camera, FlatKdTree& tree, double build_ms,
               FrameTimings* timings = nullptr, std::vector<LightBuffer>* light_buffers = nullptr,
               PosedParts* posed = nullptr, MirrorPlanes* mirror_planes = nullptr);

  // The traversal pass alone over the given rays (for tests and benchmarks). The tree must have
  // been built from scene.mesh.
  TraceResult trace(const Scene& scene, const FlatKdTree& tree, const RayBatch& rays);
  // The primary generation's texels as a frame finds them (settings().primary: traced, or
  // rasterized with the shadow pass from its hits), over `rays` = primary_rays(camera, width,
  // height): what `mobirt accuracy` compares with the reference. The tree as for trace().
  TraceResult trace_primary(const Scene& scene, const Camera& camera, const FlatKdTree& tree, const RayBatch& rays);

  // The shading pass alone over decoded hits (two passes for 16-bit colour); one colour per ray,
  // as read back from the RGBA8 texels. Lights the hits by their masks as they are (the frame sets
  // every light's bit without shadows).
  std::vector<glm::vec3> shade(const Scene& scene, const RayBatch& rays, const SurfaceHits& hits,
                               GenerationTimings& timings);

  // For an engine that traces elsewhere and shades with this renderer's pass (the ray-query and
  // compute peers, src/baseline/*_whitted.h): what shade() reads besides the hits and the rays'
  // directions (which it uploads itself, for the hits only), which mobirt's own frame uploads in
  // begin_frame: the scene's materials (once per frame).
  void upload_materials(const Scene& scene);
  // The traversal pass's ray textures (mobirt's own frame, each generation).
  void upload_rays(const RayBatch& rays);
  // shade() for such an engine: one generation shaded.
  std::vector<glm::vec3> shade_traced_elsewhere(const Scene& scene, const RayBatch& rays,
                                                const SurfaceHits& hits, GenerationTimings& timings);

  // The frame's shading at its end (settings().shading == ShadingPasses::Frame; for the engines
  // that shade with this renderer, WhittedEngine::shades_at_end). queue_shade writes a generation's
  // inputs where the pass reads them, after those queued before; where the textures cannot hold
  // them too, the generations queued so far are shaded first, by a pass of their own, and their
  // colours kept. shade_queued shades the rest in one pass and returns every queued generation's
  // colours in order, each as shade() would return it (WhittedEngine::shade_queued);
  // drop_shade_queue forgets the queue (a frame that ended early). shade() is a queue of one.
  bool shades_at_end() const { return settings_.shading == ShadingPasses::Frame; }
  void queue_shade(const Scene& scene, const RayBatch& rays, const SurfaceHits& hits, GenerationTimings& timings);
  std::vector<std::vector<glm::vec3>> shade_queued(const Scene& scene, std::span<GenerationTimings> timings);
  void drop_shade_queue();
  // Shading passes run since the renderer was made (16-bit colour's two halves counted as one).
  size_t shading_passes() const;

  const RenderSettings& settings() const { return settings_; }
  // For an engine that shades with this renderer: throws Error(Internal) naming `who` unless the
  // frame's colour depth and specialisation are the ones this renderer's passes were made for.
  void check_shades_like(const RenderSettings& frame, const char* who) const;
  // How the traversal pass reads the scene data (settings.data and what the backend has).
  TextureKind data_kind() const { return data_kind_; }
  bool texel_buffers() const { return data_kind_ == TextureKind::TexelBuffer; }

 private:
  struct Data;  // textures and passes, kept across frames and resized when they are too small
  class Engine;  // the passes as the frame loop drives them
  TextureHandle ensure_texture(TextureHandle& handle, uint32_t& capacity_rows, uint32_t width,
                               uint32_t rows, TexelFormat format, TextureKind kind = TextureKind::Image2D);
  // Whether a pass that binds buffers of these rows x widths (the capacities: a buffer's texels)
  // must be specialised to WIDE_INDICES: one of more than 2^23 texels (glsl/layout.h).
  bool wide_indices(std::initializer_list<std::pair<uint32_t, uint32_t>> rows_and_widths) const;
  // wide: the pass binds such a buffer. primary_hits: specialised to PRIMARY_HITS (--primary raster).
  PassHandle trace_pass(int lights, Packing packing, bool analytic, bool wide, int primary_hits = 0,
                        bool light_buffers = false);
  PassHandle shade_pass(int lights, int textures, int pages, int colour, bool wide);
  void prepare_atlas(const Scene& scene);
  // With --shadow-cells the shadow lights' light buffers (over `tree`'s triangles) go with `tree`,
  // past its nodes and leaf entries (glsl/layout.h, MOBIRT_TP_LIGHT_BUFFERS). buffers_prebuilt: the
  // buffers held (built with the tree, or by the last upload of these triangles) serve where they
  // are these lights' at this resolution. Returns the milliseconds spent building and packing them.
  double upload_tree(const FlatKdTree& tree, const Scene& scene, bool buffers_prebuilt);
  // Builds (or takes) the buffers and places them (Data::light_buffer_places); upload_tree writes
  // their nodes (windows and cells) and entries with these.
  void build_light_buffers(const FlatKdTree& tree, const Scene& scene, bool prebuilt);
  void write_light_buffer_nodes(glm::vec4* nodes) const;
  void write_light_buffer_entries(glm::vec4* entries, const FlatKdTree& tree) const;

 public:
  // The lights whose shadow rays test a light buffer in the passes now (--shadow-cells), of the
  // tree uploaded last.
  int light_buffers_used() const;
  // Of those buffers, the triangles they leave out (faces of closed parts turned away from their
  // light: src/accel/closed_parts.h), summed over the lights.
  size_t light_buffer_faces_left_out() const;
  // Whether the last frame had a kd-tree (false: only the primitives' texels, frame_walks_tree).
  bool frame_had_kd_tree() const;
  // The light buffers this renderer built itself since it was made, on the rendering thread: none
  // for frames handed their buffers with their tree (the frame pipeline's worker builds them).
  size_t light_buffers_built() const;
  // The times this renderer looked for a frame's flat mirrors itself (find_mirror_planes), on the
  // rendering thread: never for frames handed their planes (the pipelined loop's worker finds them).
  // A frame that may draw mirrors looks once its primary hits are shaded (to start the raster
  // ahead), also where no mirror ray follows.
  size_t mirror_plane_searches() const;
  // Mirror rasters started ahead (once the primary hits were shaded, for the plane they predict)
  // and, of them, those whose plane the mirror rays then chose (the others were dropped), since the
  // renderer was made.
  struct MirrorRastersAhead {
    size_t started = 0;
    size_t taken = 0;
  };
  MirrorRastersAhead mirror_rasters_ahead() const;

 private:
  // The textures laid out in rows of the rays' width (rays and shading inputs), made again when
  // the width changes.
  void fit_ray_layout(uint32_t width);
  // The shading inputs' textures opened for writing with room for at least `texels` (queue_shade);
  // closed, their first `texels` made visible to the pass (written in place, or uploaded).
  void open_shade_inputs(uint32_t texels);
  void close_shade_inputs(uint32_t texels);
  // The shading pass over the queued generations not shaded yet: their colours kept in the queue.
  void shade_pending(const Scene& scene);
  // The lights the traversal pass casts shadow rays to: the scene's, or none without shadows.
  std::span<const Light> shadow_lights(const Scene& scene) const;
  // The walks of the kd-tree a traversal pass over `rays` rays counts (GenerationTimings::walks):
  // the closest hits where it walks them, and the shadow rays of each light without a buffer.
  uint64_t pass_walks(const Scene& scene, uint32_t rays, bool closest_hits) const;
  // A secondary generation walked on the CPU (RenderSettings::cpu_walks): hits and shadow masks.
  TracedGeneration trace_on_cpu(const Scene& scene, const RayBatch& rays, GenerationTimings& g);
  // The light count a pass is built for: the scene's, or the packing's maximum when general.
  int pass_lights(int scene_lights) const;
  // primary_hits: the pass specialised to PRIMARY_HITS (each ray's rasterized index + 1 in its
  // direction's w), MOBIRT_PRIMARY_HITS_WALK or _PLANE; 0: not.
  TraceResult trace_uploaded(const Scene& scene, const FlatKdTree& tree, const RayBatch& rays,
                             int primary_hits = 0);
  // The primary generation with its hits rasterized (--primary raster) and, with shadows, the trace
  // pass specialised to PRIMARY_HITS casting the shadow rays from them, over the hits alone.
  // `tree`: the one uploaded, whose triangles and box the shadow pass reads. walk_edge_misses: a ray
  // whose rasterized triangle's test misses walks `tree` (a kd-tree), else keeps that triangle.
  // started: the raster pass of these primaries was started already (start_raster, by the frame's
  // Engine::start_frame), else it is started here.
  TracedGeneration trace_rasterized(const Scene& scene, const Camera& camera, const FlatKdTree& tree,
                                    const RayBatch& rays, GenerationTimings& g, bool walk_edge_misses,
                                    bool started = false);
  // The first secondary generation `rays` (the primaries through `camera` being one per pixel) with
  // the mirror rays off the mirror plane that sends the most found by a raster pass of the mirrored
  // scene (--mirrors), the others traced; false (and `out` untouched) where --mirrors or the rays
  // say to trace them all. Edge misses of the raster walk `tree`.
  bool trace_mirrored(const Scene& scene, const Camera& camera, const FlatKdTree& tree, const RayBatch& rays,
                      GenerationTimings& g, TracedGeneration& out);
  // The frame's flat mirrors: handed in with it, else the last frame's while its triangles,
  // normals and materials are the same, else found now (find_mirror_planes); checked once a frame.
  const MirrorPlanes& frame_mirror_planes(const Scene& scene);
  // Of frame_mirror_planes' planes, those facing the eye through `camera` (up to the 8 largest; the
  // eye within on_plane of one sees it edge-on), each turned to face it; candidate_of (when given):
  // per plane its index among them, or -1.
  std::vector<MirrorPlane> mirror_candidates(const Camera& camera, double on_plane,
                                             std::vector<int>* candidate_of) const;
  // How far from a plane a mirror ray's origin may lie and count as on it.
  double mirror_on_plane(const FlatKdTree& tree) const;
  // The raster pass of the scene mirrored in `plane`, seen through `camera`, started
  // (Backend::start_raster into raster_vertices, a raster started ahead dropped first); false where --mirrors auto declines a raster
  // over the device's limits (--mirrors raster throws). prepare_ms: its CPU time up to the
  // backend's start (the backend counts its own copy of the vertices in the pass's upload).
  bool start_mirror_raster(const Scene& scene, const Camera& camera, const MirrorPlane& plane, double& prepare_ms);
  // Once the primary hits are shaded, before their mirror rays are made: the raster of the plane
  // whose reflective triangles the most primary hits lie on, started ahead (where --mirrors and the
  // hits say a raster will be drawn), so that the driver sets it up while this thread makes the
  // next generation; trace_mirrored finishes it where the rays choose the same plane.
  void start_mirror_raster_ahead(const Scene& scene, const Camera& camera, const RayBatch& rays,
                                 const SurfaceHits& hits, GenerationTimings& g);
  // A raster started ahead and not taken dropped unread (Backend::drop_raster): before any pass,
  // raster or frame.
  void settle_mirror_raster();
  // One pass over `part`, a part of a generation whose rays each hold in `pixel` the index of the
  // ray they stand for (trace_uploaded with primary_hits), its texels written there in out.texels
  // (sized to the generation, out.packing set).
  void trace_part(const Scene& scene, const FlatKdTree& tree, const RayBatch& part, int primary_hits,
                  GenerationTimings& g, TracedGeneration& out);
  // The raster pass of the primary hits through `camera` at width x height started
  // (Backend::start_raster): the posed triangles' vertices written, the draw submitted; its time
  // on the CPU goes to the generation's upload stage when trace_rasterized finishes it.
  void start_raster(const Scene& scene, const Camera& camera, uint32_t width, uint32_t height);
  // Per triangle: whether a raster pass from `eye` leaves it out (faces_turned_away over the scene's
  // closed parts as posed this frame; `rays_from` and `reach` as there); empty where the scene has
  // no closed parts analysed. Valid until the next call.
  const std::vector<uint8_t>& faces_away_from(const Scene& scene, glm::vec3 eye, const glm::vec3* rays_from,
                                              float reach);

  Backend& backend_;
  RenderSettings settings_;
  // Of the nodes, leaf entries and triangles, and of the rays, the shading pass's inputs and the
  // materials (a 2D texelFetch per input costs llvmpipe an indirect call with mip-level work).
  TextureKind data_kind_ = TextureKind::Image2D;
  std::unique_ptr<Data> data_;
  std::unique_ptr<Engine> engine_;
};

// The shading of an engine that traces elsewhere and shades with a Renderer's passes (the
// ray-query and compute peers, src/baseline/*_whitted.h): shade() and the frame's shading at its
// end (Renderer::shades_at_end, as mobirt's own frames) forwarded to `shading`, not owned.
class ShadedByRenderer : public WhittedEngine {
 public:
  explicit ShadedByRenderer(Renderer& shading) : shading_(shading) {}
  std::vector<glm::vec3> shade(const Scene& scene, const RayBatch& rays, const SurfaceHits& hits,
                               GenerationTimings& g) override {
    return shading_.shade_traced_elsewhere(scene, rays, hits, g);
  }
  bool shades_at_end() const override { return shading_.shades_at_end(); }
  void queue_shade(const Scene& scene, const RayBatch& rays, const SurfaceHits& hits, GenerationTimings& g) override {
    shading_.queue_shade(scene, rays, hits, g);
  }
  std::vector<std::vector<glm::vec3>> shade_queued(const Scene& scene, std::span<GenerationTimings> g) override {
    return shading_.shade_queued(scene, g);
  }
  // A queue a frame that ended early left behind is forgotten.
  void end_frame() override { shading_.drop_shade_queue(); }

 protected:
  Renderer& shading_;
};

// Whether a frame of `scene` with `settings` walks a kd-tree: every frame does, but one whose
// primary hits are rasterized, that casts no secondary ray and whose shadow rays (if any) all have
// light buffers (shadow_rays_buffered). That one gets only the primitives' texels
// (flatten_primitives), with the light buffers after them: decoding reads the triangles, the shadow
// rays their lights' cells, nothing walks a tree. Where a light's buffer then turns out not worth
// using (kLightBufferMaxMeanList, a texture limit) or a ray hits the loop cap, the frame builds its
// tree after all (Renderer::Engine).
bool frame_walks_tree(const Scene& scene, const RenderSettings& settings);
// --shadow-cells for a scene of `triangles` under `settings`: its cells per face edge, 0 = none.
int shadow_cells(size_t triangles, const RenderSettings& settings);
// Whether every shadow ray of a frame is to test a light buffer's cell rather than walk: shadows on,
// a scene of triangles only, shadow_cells > 0 and every light a point or spot light. True too when
// the frame casts no shadow ray.
bool shadow_rays_buffered(const Scene& scene, const RenderSettings& settings);
// The light buffers of a frame of `scene` under `settings`, one per shadow light (none without
// shadows), built on all cores: resolution 0 where the light gets none (a directional light,
// shadow_cells 0, analytic shapes). The renderer packs them into the passes' data, and still
// leaves out a light whose lists run long (kLightBufferMaxMeanList) or past a texture's reach.
// posed (optional): the scene's closed parts as posed for the buffers (pose_closed_parts), handed on
// to the renderer's raster passes (Renderer::render); none (`of` null) where no buffer posed them.
void frame_light_buffers(const Scene& scene, const RenderSettings& settings, std::vector<LightBuffer>& out,
                         PosedParts* posed = nullptr);
// Whether a frame of `scene` may draw its first bounce's mirror rays (--mirrors raster, or auto up
// to kRasterTrianglesPerPixel triangles a pixel): bounces, a scene of triangles only, a material
// that reflects without refracting. Such a frame looks for its flat mirrors (find_mirror_planes);
// in the pipelined frame loop its worker finds them with the kd-tree, off the rendering thread.
bool frame_may_draw_mirrors(const Scene& scene, const RenderSettings& settings);
// Whether a frame rasterizes its primary hits: --primary raster, or auto where raster_pays, and a
// scene of triangles only (analytic shapes have none to draw: their scenes' primaries are traced).
bool primaries_rasterized(const Scene& scene, const RenderSettings& settings);
// --primary auto's choice for a scene of `triangles` at width x height. The raster pass costs per
// triangle (llvmpipe sets up each one, however small), the primary walk per pixel: rasterized up
// to kRasterTrianglesPerPixel triangles per pixel, where the two passes cost about the same
// (README, *Primary hits rasterized*: where it loses); past it too when rasterizing spares the
// frame its kd-tree (walks_tree false: no ray walks one) and the tree would be built for
// every frame (tree_per_frame: --always-rebuild, the paper's model and the bench's, or an
// animation played frame by frame).
inline constexpr double kRasterTrianglesPerPixel = 0.5;
// --shadow-cells auto (README, *Shadow rays through light buffers*): 64 x 64 cells a face made the
// bench's shadow frames of 1.4K-11K triangles 1.1-1.5x faster; on 361K (the tessellated
// sphereflake) the lists ran 50-100x longer and each build took 0.1 s a light.
inline constexpr int kAutoShadowCells = 64;
inline constexpr size_t kAutoShadowCellsTriangles = 32768;
bool raster_pays(size_t triangles, int width, int height, bool tree_per_frame, bool walks_tree);

// The view of Backend::run_raster for the primary rays of `camera` at width x height: near just
// before the nearest point a primary ray can see (the nearest vertex of a triangle wholly in front
// of the eye, or the nearest point inside the view pyramid of one that reaches behind it), never
// before znear cos(corner), the nearest a ray starts along the view axis; far just past the
// farthest vertex. False when no triangle reaches into the view pyramid: none can be seen.
bool raster_view(const Camera& camera, int width, int height, std::span<const glm::vec3> positions,
                 RasterView& view);

// The traversal and shading uniforms (vec4 arrays, indices in glsl/layout.h).
// pass_lights: the light count the pass was built for (>= lights.size(); the rest are unused).
std::vector<float> trace_uniforms(const FlatKdTree& tree, std::span<const Light> lights,
                                  const ShadowSettings& s, int pass_lights);
std::vector<float> shade_uniforms(const Scene& scene, int pass_lights);

}  // namespace mobirt
