#include "backend/backend.h"

#include <regex>
#include <set>
#include <utility>

#include "core/error.h"
#include "layout.h"

namespace mobirt {

size_t texel_bytes(TexelFormat format) {
  switch (format) {
    case TexelFormat::RGBA32F: return 16;
    case TexelFormat::R32F: return 4;
    case TexelFormat::RGBA8: return 4;
    case TexelFormat::SRGBA8: return 4;
  }
  throw Error(ErrorKind::Internal, "texel_bytes: unknown texel format " + std::to_string(int(format)));
}

TexelFormat atlas_page_format(const DeviceInfo& info, bool exact) {
  return info.srgb_textures && !exact ? TexelFormat::SRGBA8 : TexelFormat::RGBA8;
}

std::vector<uint32_t> atlas_linear_bindings(const DeviceInfo& info) {
  if (!info.srgb_textures) return {};
  return {MOBIRT_BIND_ATLAS_PAGE_0, MOBIRT_BIND_ATLAS_PAGE_1, MOBIRT_BIND_ATLAS_PAGE_2};
}

void check_pass_desc(const PassDesc& desc) {
  const std::string name = desc.shader.name();
  if (desc.texture_bindings.size() > MOBIRT_MAX_SAMPLED_TEXTURES) {
    throw Error(ErrorKind::Constraint, "pass " + name + " binds " + std::to_string(desc.texture_bindings.size()) +
                                           " textures; at most " + std::to_string(MOBIRT_MAX_SAMPLED_TEXTURES) +
                                           " are allowed (GL_MAX_TEXTURE_IMAGE_UNITS)");
  }
  if (desc.uniform_vec4s > MOBIRT_MAX_PARAM_VEC4S) {
    throw Error(ErrorKind::Internal, "pass " + name + " asks for " + std::to_string(desc.uniform_vec4s) +
                                         " uniform vec4; at most " + std::to_string(MOBIRT_MAX_PARAM_VEC4S));
  }
  if (!desc.texture_kinds.empty() && desc.texture_kinds.size() != desc.texture_bindings.size()) {
    throw Error(ErrorKind::Internal, "pass " + name + ": " + std::to_string(desc.texture_kinds.size()) +
                                         " texture kinds for " + std::to_string(desc.texture_bindings.size()) + " bindings");
  }
  // Binding 0 is the uniforms' on both APIs (both preludes declare it), whether the pass fills it or not.
  std::set<uint32_t> used;
  for (const uint32_t binding : desc.texture_bindings) {
    if (binding == MOBIRT_BIND_TRACE_PARAMS || !used.insert(binding).second) {
      throw Error(ErrorKind::Internal, "pass " + name + ": binding " + std::to_string(binding) +
                                           " is used twice (binding 0 is the uniform block)");
    }
  }
  std::set<uint32_t> constant_ids;
  for (const Specialization& s : desc.specialization) {
    if (!constant_ids.insert(s.id).second) {
      throw Error(ErrorKind::Internal, "pass " + name + ": specialization constant " + std::to_string(s.id) +
                                           " is set twice");
    }
  }
}

const char* texture_kind_name(TextureKind kind) {
  switch (kind) {
    case TextureKind::Image2D: return "2D image";
    case TextureKind::TexelBuffer: return "texel buffer";
    case TextureKind::StorageBuffer: return "storage buffer";
    case TextureKind::DeviceAddress: return "device address";
  }
  return "texture";
}

TextureHandle Backend::create_texel_buffer(uint32_t, TexelFormat) {
  throw Error(ErrorKind::Unsupported, "this backend has no texel buffers (OpenGL ES 2.0): use --data images");
}

TextureHandle Backend::create_storage_buffer(uint32_t, TexelFormat) {
  throw Error(ErrorKind::Unsupported, "this backend has no storage buffers (OpenGL ES 2.0): use --data images");
}

void* Backend::begin_write(TextureHandle, size_t) { return nullptr; }

void Backend::end_write(TextureHandle) {}

PassTiming Backend::run_raster(std::span<const float>, const RasterView&, uint32_t, uint32_t, std::span<uint32_t>) {
  throw Error(ErrorKind::Unsupported, "this backend cannot rasterize the primary hits: use --primary trace");
}

void Backend::start_raster(std::span<const float> vertices, const RasterView& view, uint32_t width, uint32_t height) {
  pending_raster_ = {vertices, view, width, height, true};
}

void Backend::drop_raster() { pending_raster_ = PendingRaster{}; }

PassTiming Backend::finish_raster(std::span<uint32_t> out) {
  if (!pending_raster_.started) throw Error(ErrorKind::Internal, "finish_raster without start_raster");
  const PendingRaster r = std::exchange(pending_raster_, PendingRaster{});
  return run_raster(r.vertices, r.view, r.width, r.height, out);
}

void check_run_pass_arguments(const PassDesc& desc, size_t textures, size_t uniform_floats, uint32_t width,
                              uint32_t count, size_t out_texels) {
  const std::string name = desc.shader.name();
  if (textures != desc.texture_bindings.size()) {
    throw Error(ErrorKind::Internal, "pass " + name + " takes " + std::to_string(desc.texture_bindings.size()) +
                                         " textures, got " + std::to_string(textures));
  }
  if (uniform_floats > size_t(MOBIRT_MAX_PARAM_VEC4S) * 4 || uniform_floats > size_t(desc.uniform_vec4s) * 4) {
    throw Error(ErrorKind::Internal, "pass " + name + ": " + std::to_string(uniform_floats) +
                                         " uniform floats, more than the pass's " +
                                         std::to_string(desc.uniform_vec4s) + " vec4");
  }
  if (width == 0) throw Error(ErrorKind::Internal, "pass " + name + ": width 0");
  if (out_texels < count) {
    throw Error(ErrorKind::Internal, "pass " + name + ": output holds " + std::to_string(out_texels) +
                                         " texels, the pass writes " + std::to_string(count));
  }
}

uint32_t checked_target_height(const PassDesc& desc, uint32_t width, uint32_t count, uint32_t limit,
                               const char* limit_name) {
  const uint32_t height = (count + width - 1) / width;
  if (width > limit || height > limit) {
    throw Error(ErrorKind::BadInput, "pass " + std::string(desc.shader.name()) + ": " + std::to_string(count) +
                                         " rays in rows of " + std::to_string(width) + " need a " +
                                         std::to_string(width) + "x" + std::to_string(height) + " target, beyond " +
                                         limit_name + " (" + std::to_string(limit) + ")");
  }
  return height;
}

const char* gpu_timestamps_name(GpuTimestamps mode) {
  switch (mode) {
    case GpuTimestamps::On: return "on";
    case GpuTimestamps::Off: return "off";
    case GpuTimestamps::Auto: break;
  }
  return "auto";
}

bool takes_gpu_timestamps(GpuTimestamps mode, uint32_t timestamp_bits, bool cpu_device) {
  if (timestamp_bits == 0 || mode == GpuTimestamps::Off) return false;
  return mode == GpuTimestamps::On || !cpu_device;
}

PassTiming empty_pass_timing(double& pending_upload_ms, std::chrono::steady_clock::time_point wall_start) {
  PassTiming timing;
  timing.upload_ms = pending_upload_ms;
  pending_upload_ms = 0.0;
  timing.wall_ms = elapsed_ms(wall_start);
  return timing;
}

std::string mesa_version(const std::string& text) {
  // "Mesa" then a dotted version: "Mesa 25.0.7", "Mesa 22.3.6 (LLVM 15.0.6)", "Mesa 25.0.7-2~bpo12+1".
  static const std::regex pattern(R"(\bMesa ([0-9]+(\.[0-9]+)+))");
  std::smatch match;
  if (!std::regex_search(text, match, pattern)) return {};
  return "Mesa " + match[1].str();
}

}  // namespace mobirt
