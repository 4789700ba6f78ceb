// The small interface every backend implements: data textures in, one full-screen fragment pass
// out, one RGBA8 texel per ray read back. Core code talks to a GPU only through this; it never
// sees a VkImage or a GLuint, only typed handles.
#pragma once

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "shader_ids.h"  // enum class ShaderId { Traverse, Shade }: generated from the shader list

namespace mobirt {

template <typename Tag>
struct Handle {
  uint32_t id = 0;
  explicit operator bool() const { return id != 0; }
  bool operator==(const Handle&) const = default;
};
using TextureHandle = Handle<struct TextureTag>;
using PassHandle = Handle<struct PassTag>;

// SRGBA8: 8-bit sRGB-encoded RGBA that the sampler decodes to linear per texel, before it filters
// (Vulkan's R8G8B8A8_SRGB; OpenGL ES 2.0 only with GL_EXT_sRGB: DeviceInfo::srgb_textures).
enum class TexelFormat { RGBA32F, R32F, RGBA8, SRGBA8 };
size_t texel_bytes(TexelFormat format);

// How a pass reads a data texture: a 2D image (texelFetch / texture2D, both APIs) or a uniform
// texel buffer (Vulkan only: samplerBuffer, no mip-level path in llvmpipe's fetch). Either one is
// still one of the 8 sampled-texture slots of the ES 2.0 model. Or a read-only storage buffer
// (Vulkan only, the traversal pass's --data storage-buffers): a measurement variant that breaks the
// model (OpenGL ES 2.0 has no storage buffers) and is allowed to only because its pass declares it.
// Or a storage buffer read through its device address (Vulkan with VK_KHR_buffer_device_address,
// the passes' --data device-addresses): no descriptor, the address in the pass's push constants
// (layout.h, MOBIRT_PASS_ADDRESSES); llvmpipe reads through a pointer with an inline gather where
// every texel or storage-buffer fetch is a call or a per-lane loop. Outside the model as storage
// buffers are, and allowed the same way. Its texture is a storage buffer (create_storage_buffer).
enum class TextureKind { Image2D, TexelBuffer, StorageBuffer, DeviceAddress };
// "2D image", "texel buffer", "storage buffer", "device address"
const char* texture_kind_name(TextureKind kind);

// A fragment shader as built into the binary: SPIR-V for Vulkan and GLSL ES 1.00 for OpenGL ES 2.0,
// both generated from glsl/ at build time. Every shader is one line of the shader list in
// CMakeLists.txt, which generates the registries: the production one (ShaderId, shader_source) and
// the tests' own (tests only link it), so that test shaders never reach the renderer's enum.
struct ShaderSource {
  const char* name;                  // "trace.frag": errors name it
  std::span<const uint32_t> spirv;   // glsl/<name> compiled for Vulkan 1.1
  const char* es;                    // glsl/es/<name> with its includes expanded; nullptr: Vulkan only
};

// shader_ids.h declares the production registry's lookup, generated with it:
//   const ShaderSource& shader_source(ShaderId id);

// The shader a pass runs: a production shader by id, or any other registered source (tests').
class ShaderRef {
 public:
  // Implicit, so that `desc.shader = ShaderId::Shade` and `desc.shader = some_source` both read.
  ShaderRef(ShaderId id) : source_(&shader_source(id)) {}
  ShaderRef(const ShaderSource& source) : source_(&source) {}
  const ShaderSource& source() const { return *source_; }
  const char* name() const { return source_->name; }

 private:
  const ShaderSource* source_;
};

// Specialisation of a shader to a scene: Vulkan specialization constants, #defines on GLES.
// Ids are listed in glsl/prelude_vk.glsl.
struct Specialization {
  uint32_t id;
  int32_t value;
};

struct PassDesc {
  ShaderRef shader = ShaderId::Traverse;
  std::vector<Specialization> specialization;
  uint32_t uniform_vec4s = 0;              // size of the vec4 uniform array at binding 0
  std::vector<uint32_t> texture_bindings;  // binding slot of each sampled texture, in order
  // The kind of each of texture_bindings, in the same order; empty = every one a 2D image.
  std::vector<TextureKind> texture_kinds;
  TextureKind kind(size_t i) const { return i < texture_kinds.size() ? texture_kinds[i] : TextureKind::Image2D; }
  // Bindings (2D images) read through a bilinear sampler (LINEAR, no mipmaps, clamp to edge)
  // instead of NEAREST: the atlas pages' one filtered fetch (src/scene/atlas.h).
  std::vector<uint32_t> linear_bindings;
  bool linear(uint32_t binding) const {
    return std::find(linear_bindings.begin(), linear_bindings.end(), binding) != linear_bindings.end();
  }
};

// One pass's cost, as measured by the backend.
struct PassTiming {
  double upload_ms = 0.0;     // texture uploads recorded before the pass (GPU time where measured)
  double gpu_ms = 0.0;        // the fragment pass on the GPU (timestamp queries)
  double readback_ms = 0.0;   // copying the RGBA8 result back into host memory
  double wall_ms = 0.0;       // whole run_pass call on the CPU clock
  uint64_t bytes_read = 0;    // bytes that left the GPU: 4 per ray
};

// The camera of Backend::run_raster, as CameraBasis (core/camera.h) makes the primary rays: a
// vertex v lands on pixel centre (x, y) when the ray through that centre passes through v. Nothing
// nearer than `near` (> 0) along the view axis is drawn; a backend with fixed-point depth spreads
// its resolution from near to far (OpenGL ES 2.0), one with float depth reverses it (near / z) and
// needs no far (Vulkan).
struct RasterView {
  float eye[4];      // xyz
  float right[4];    // xyz: the image's x axis
  float up[4];       // xyz: the image's y axis (upwards; row 0 is the top)
  float forward[4];  // xyz: the view direction
  // x: 1 / (tan_half aspect), y: 1 / tan_half, z: near, w: far distance along forward.
  float projection[4];
};

struct DeviceInfo {
  std::string api;            // "Vulkan 1.3.239"
  std::string device;         // "llvmpipe (LLVM 15.0.6, 256 bits)"
  std::string driver;         // "llvmpipe / Mesa 22.3.6"
  std::string driver_version; // "Mesa 25.0.7" (Mesa drivers), else the driver's own version string
  bool is_software = false;
  // The driver's own ray tracing for a ray-query engine: VK_KHR_ray_query with
  // VK_KHR_acceleration_structure (lavapipe from Mesa 25; never on OpenGL ES 2.0).
  bool ray_query = false;
  // Uniform texel buffers (Backend::create_texel_buffer): Vulkan, never OpenGL ES 2.0.
  bool texel_buffers = false;
  // Read-only storage buffers (Backend::create_storage_buffer): Vulkan, never OpenGL ES 2.0.
  bool storage_buffers = false;
  // Storage buffers read through their device addresses (TextureKind::DeviceAddress): Vulkan with
  // VK_KHR_buffer_device_address.
  bool device_addresses = false;
  // TexelFormat::SRGBA8 textures, filtered in linear light: Vulkan always; OpenGL ES 2.0 needs
  // GL_EXT_sRGB, which Mesa does not offer to an ES 2.0 context. Without them the atlas pages are
  // RGBA8 read texel by texel (atlas_page_format()).
  bool srgb_textures = false;
  // Passes timed on the device's clock (timestamp queries; BackendOptions::timestamps), else on
  // the CPU's.
  bool gpu_timestamps = false;
  std::vector<std::string> limits;  // "name: value" lines that matter to mobirt
};

class Backend {
 public:
  virtual ~Backend() = default;

  virtual DeviceInfo device_info() const = 0;

  // Data textures. upload() replaces the first `bytes` of the texture's texels (row-major).
  virtual TextureHandle create_texture(uint32_t width, uint32_t height, TexelFormat format) = 0;
  // A uniform texel buffer of `texels` texels, read by a pass whose binding is TextureKind::TexelBuffer
  // (DeviceInfo::texel_buffers); upload() and destroy() take it like a texture. Error(Unsupported) by
  // default, Error(BadInput) above the device's maxTexelBufferElements.
  virtual TextureHandle create_texel_buffer(uint32_t texels, TexelFormat format);
  // A read-only storage buffer of `texels` texels (std430 arrays of the format's element), read by a
  // pass whose binding is TextureKind::StorageBuffer; otherwise as create_texel_buffer().
  virtual TextureHandle create_storage_buffer(uint32_t texels, TexelFormat format);
  virtual void upload(TextureHandle texture, const void* data, size_t bytes) = 0;
  // The first `bytes` of a texture's texels (row-major, as upload() takes them) for the caller to
  // write in place of an upload, where the backend keeps them in memory the host writes (Vulkan's
  // texel and storage buffers, linear images whose rows are not padded); nullptr where it does not
  // (OpenGL ES textures, optimal images): then write them elsewhere and upload(). What the texels
  // held before is unspecified. Valid until end_write(), which must come before the next pass or
  // upload that touches the texture. No pass reads it meanwhile: run_pass waits for its pass, and
  // a raster in flight reads no texture. Spares the copy an upload makes of arrays that exist only
  // to be uploaded. By default nullptr.
  virtual void* begin_write(TextureHandle texture, size_t bytes);
  // Makes the writes since a begin_write() that returned memory visible to the device's passes
  // (nothing to end where it returned nullptr).
  virtual void end_write(TextureHandle texture);
  virtual void destroy(TextureHandle texture) = 0;

  // Creating a pass checks the OpenGL ES 2.0 constraints (one RGBA8 output, no storage writes, at
  // most 8 sampled textures) on the shader itself and throws Error(Constraint) when one is broken.
  virtual PassHandle create_pass(const PassDesc& desc) = 0;
  virtual void destroy(PassHandle pass) = 0;

  // Runs the pass over `count` rays laid out in rows of `width` (ray i at (i mod width, i div
  // width)) and reads back one RGBA8 texel per ray into out[0, count). Textures bind in the order of
  // PassDesc::texture_bindings.
  virtual PassTiming run_pass(PassHandle pass, std::span<const TextureHandle> textures,
                              std::span<const float> uniforms, uint32_t width, uint32_t count,
                              std::span<uint32_t> out) = 0;

  // The primary rays' closest triangles rasterized instead of traced (RenderSettings::primary,
  // --primary raster): `vertices` (4 floats each, three per triangle, no sharing: the position and
  // the triangle's index + 1) drawn with a depth test into a width x height RGBA8 target, each
  // fragment writing its index + 1 as the traversal pass packs a hit (24 bits, mask bits 0), and
  // read back into out[0, width x height), row 0 at the top as the rays' rows; 0 where no triangle
  // covers the pixel's centre. The same ES 2.0 model as every pass: one RGBA8 output, no storage
  // writes, no texture at all. Error(Unsupported) by default.
  virtual PassTiming run_raster(std::span<const float> vertices, const RasterView& view, uint32_t width,
                                uint32_t height, std::span<uint32_t> out);
  // run_raster in two halves, so that the caller's work overlaps the draw: start_raster submits it
  // and returns (the driver sets up every triangle on a thread of its own while the rest of the
  // frame waits otherwise); finish_raster waits for it and reads it back as run_raster does, into
  // out[0, width x height) of the start's size. `vertices` must stay alive and unchanged until
  // finish_raster. Between the two the caller may create, upload and destroy textures, but run no
  // other pass; a second start_raster first waits for the one in flight and drops it. By default
  // start_raster keeps the arguments and finish_raster runs run_raster (no overlap).
  virtual void start_raster(std::span<const float> vertices, const RasterView& view, uint32_t width, uint32_t height);
  virtual PassTiming finish_raster(std::span<uint32_t> out);
  // The raster in flight (start_raster) dropped unread: waited for where it runs already, never
  // drawn where it does not (the default keeps only the arguments). Nothing where none is.
  virtual void drop_raster();

  // Every validation/debug message received since the last call (tests assert there are none).
  virtual std::vector<std::string> take_debug_messages() = 0;

 private:
  // The default start_raster's arguments, until finish_raster.
  struct PendingRaster {
    std::span<const float> vertices;
    RasterView view{};
    uint32_t width = 0, height = 0;
    bool started = false;
  } pending_raster_;
};

// The atlas pages' format on this device, and the page bindings its shading pass reads through a
// bilinear sampler: SRGBA8 and all pages with DeviceInfo::srgb_textures (glsl/atlas.glsl's one
// filtered fetch), else RGBA8 and none (4 NEAREST fetches).
// exact (--colour 16): RGBA8 pages whatever the device, read texel by texel and decoded in the
// shader (glsl/atlas.glsl: llvmpipe's sRGB decode is coarser than a 16-bit image).
TexelFormat atlas_page_format(const DeviceInfo& info, bool exact = false);
std::vector<uint32_t> atlas_linear_bindings(const DeviceInfo& info);

// A pass description checked the same way by every backend before it builds anything: at most
// MOBIRT_MAX_SAMPLED_TEXTURES textures (Error(Constraint)), at most MOBIRT_MAX_PARAM_VEC4S uniform
// vec4, no binding used twice and none at binding 0 (the uniforms' slot, on both APIs), no
// specialization constant set twice (Error(Internal)). Errors name the shader.
void check_pass_desc(const PassDesc& desc);

// The arguments of Backend::run_pass checked against the pass, the same way by every backend:
// throws Error(Internal) naming the pass when the texture count, the uniform size (at most the
// pass's uniform_vec4s and MOBIRT_MAX_PARAM_VEC4S), the width or the output size is wrong.
void check_run_pass_arguments(const PassDesc& desc, size_t textures, size_t uniform_floats, uint32_t width,
                              uint32_t count, size_t out_texels);

// The target's height for `count` (> 0) rays in rows of `width`; Error(BadInput) naming the pass
// when a side exceeds the device's `limit` texels (`limit_name`: "maxImageDimension2D", ...).
uint32_t checked_target_height(const PassDesc& desc, uint32_t width, uint32_t count, uint32_t limit,
                               const char* limit_name);

// The start of Backend::run_pass, the same on every backend: the arguments checked
// (check_run_pass_arguments), each texture handle looked up into `bound` (an unknown one throws,
// even for an empty pass), and the target's height (checked_target_height); 0 for an empty pass.
template <typename Texture, typename Lookup>
uint32_t start_run_pass(const PassDesc& desc, std::span<const TextureHandle> textures, size_t uniform_floats,
                        uint32_t width, uint32_t count, size_t out_texels, uint32_t limit, const char* limit_name,
                        Lookup&& lookup, std::vector<Texture*>& bound) {
  check_run_pass_arguments(desc, textures.size(), uniform_floats, width, count, out_texels);
  bound.clear();
  for (const TextureHandle t : textures) bound.push_back(&lookup(t));
  return count == 0 ? 0 : checked_target_height(desc, width, count, limit, limit_name);
}

// An empty pass's timing: the uploads since the last pass, now taken, and the call's wall time.
PassTiming empty_pass_timing(double& pending_upload_ms, std::chrono::steady_clock::time_point wall_start);

// Where a Vulkan pass's time comes from (--gpu-timestamps): the device's clock, timestamp queries
// around the pass's commands, or the CPU's, the submission until its fence (a raster pass started
// ahead: its submission until the fence was seen signalled, the caller's work meanwhile
// included). On lavapipe a timestamp written after work waits for llvmpipe to finish that work
// and wakes its threads again, about 0.15 ms a pass of three timestamps (an 8x8 frame of two
// passes 0.64-0.75 -> 0.34-0.36 ms without them): a frame of 3 to 6 passes paid 2-11 % of itself
// to be timed. Auto: the device's clock on a GPU, the CPU's on a
// CPU device (lavapipe). GLES times every pass on the CPU's clock.
enum class GpuTimestamps { Auto, On, Off };
const char* gpu_timestamps_name(GpuTimestamps mode);
// Whether a device with `timestamp_bits` valid bits (0: none) takes timestamps under `mode`.
bool takes_gpu_timestamps(GpuTimestamps mode, uint32_t timestamp_bits, bool cpu_device);

// What every backend takes. Vulkan-only settings are VulkanOptions (backend/vulkan/vulkan_backend.h).
struct BackendOptions {
  std::string device;        // Vulkan: index or a substring of the device name; empty = lavapipe
  bool validation = false;   // Vulkan: Khronos validation layer (messages make it throw); GLES: KHR_debug
  // Mesa's rasterizer threads pinned one per CPU once the device or context exists
  // (backend/driver_threads.h); the app does it, after every device it makes.
  bool pin_threads = true;
  GpuTimestamps timestamps = GpuTimestamps::Auto;  // Vulkan (and the Vulkan peers): see above
};

// Vulkan with the default Vulkan-only settings (VulkanOptions for the others).
std::unique_ptr<Backend> create_vulkan_backend(const BackendOptions& options);
// OpenGL ES 2.0 through EGL without a window (Mesa's surfaceless platform or an EGL device);
// options.validation turns KHR_debug output on. Throws Error(Unsupported) naming what is missing.
std::unique_ptr<Backend> create_gles_backend(const BackendOptions& options);

// "Mesa 25.0.7" from a driver string that names Mesa ("OpenGL ES 3.2 Mesa 25.0.7", "Mesa 22.3.6
// (LLVM 15.0.6)"); empty when it names none.
std::string mesa_version(const std::string& text);

// Milliseconds since `start`, for stage timings on the CPU clock.
inline double elapsed_ms(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace mobirt
