// The small interface every backend implements: data textures in, one full-screen fragment pass
// out, one RGBA8 texel per ray read back. Core code talks to a GPU only through this; it never
// sees a VkImage or a GLuint, only typed handles.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace mobirt {

template <typename Tag>
struct Handle {
  uint32_t id = 0;
  explicit operator bool() const { return id != 0; }
  bool operator==(const Handle&) const = default;
};
using TextureHandle = Handle<struct TextureTag>;
using PassHandle = Handle<struct PassTag>;

enum class TexelFormat { RGBA32F, R32F, RGBA8 };
size_t texel_bytes(TexelFormat format);

// The fragment shaders a pass can run. Test-only shaders exist to prove that the OpenGL ES 2.0
// constraints are enforced when a pass is created.
enum class ShaderId {
  Traverse,
  Shade,
  TestTwoOutputs,     // writes two colour attachments: must be refused
  TestStorageWrite,   // writes a storage buffer: must be refused
  TestNineTextures,   // samples nine textures: must be refused
  TestCopyInput,      // copies texture 1 to the output: plumbing tests
  TestSpin,           // loops until the cap: watchdog tests
  TestAtlasLookup,    // atlas.glsl's lookup for (uv, texture) per ray: atlas tests
  TestNumerics,       // fp16 rounding, the ulp offset, the output packing against the CPU
};
const char* shader_name(ShaderId id);

// Specialisation of a shader to a scene: Vulkan specialization constants, #defines on GLES.
// Ids are listed in glsl/prelude_vk.glsl.
struct Specialization {
  uint32_t id;
  int32_t value;
};

struct PassDesc {
  ShaderId shader = ShaderId::Traverse;
  std::vector<Specialization> specialization;
  uint32_t uniform_vec4s = 0;              // size of the vec4 uniform array at binding 0
  std::vector<uint32_t> texture_bindings;  // binding slot of each sampled texture, in order
};

// One pass's cost, as measured by the backend.
struct PassTiming {
  double upload_ms = 0.0;     // texture uploads recorded before the pass (GPU time where measured)
  double gpu_ms = 0.0;        // the fragment pass on the GPU (timestamp queries)
  double readback_ms = 0.0;   // copying the RGBA8 result back into host memory
  double wall_ms = 0.0;       // whole run_pass call on the CPU clock
  uint64_t bytes_read = 0;    // bytes that left the GPU: 4 per ray
};

struct DeviceInfo {
  std::string api;            // "Vulkan 1.3.239"
  std::string device;         // "llvmpipe (LLVM 15.0.6, 256 bits)"
  std::string driver;         // "llvmpipe / Mesa 22.3.6"
  bool is_software = false;
  std::vector<std::string> limits;  // "name: value" lines that matter to mobirt
};

class Backend {
 public:
  virtual ~Backend() = default;

  virtual DeviceInfo device_info() const = 0;

  // Data textures. upload() replaces the first `bytes` of the texture's texels (row-major).
  virtual TextureHandle create_texture(uint32_t width, uint32_t height, TexelFormat format) = 0;
  virtual void upload(TextureHandle texture, const void* data, size_t bytes) = 0;
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

  // Every validation/debug message received since the last call (tests assert there are none).
  virtual std::vector<std::string> take_debug_messages() = 0;
};

// The arguments of Backend::run_pass checked against the pass, the same way by every backend:
// throws Error(Internal) naming the pass when the texture count, the uniform size (at most the
// pass's uniform_vec4s and MOBIRT_MAX_PARAM_VEC4S), the width or the output size is wrong.
void check_run_pass_arguments(const PassDesc& desc, size_t textures, size_t uniform_floats, uint32_t width,
                              uint32_t count, size_t out_texels);

struct BackendOptions {
  std::string device;        // Vulkan: index or a substring of the device name; empty = lavapipe
  bool validation = false;   // Khronos validation layer; messages make the backend throw
  bool sync_validation = false;  // with validation: also the layer's synchronization validation
  // Vulkan: a folder where the pipeline cache is kept between runs (one file per device and driver,
  // named by the cache UUID), so that a known scene's first frame does not compile again. Empty:
  // no cache on disk.
  std::string pipeline_cache_dir;
};

std::unique_ptr<Backend> create_vulkan_backend(const BackendOptions& options);
// OpenGL ES 2.0 through EGL without a window (Mesa's surfaceless platform or an EGL device);
// options.validation turns KHR_debug output on. Throws Error(Unsupported) naming what is missing.
std::unique_ptr<Backend> create_gles_backend(const BackendOptions& options);

// Milliseconds since `start`, for stage timings on the CPU clock.
inline double elapsed_ms(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace mobirt
