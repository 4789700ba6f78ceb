// The OpenGL ES 2.0 constraints that mobirt mirrors, checked on a compiled fragment shader's
// SPIR-V rather than trusted by convention: exactly one vec4 colour output, no storage-buffer or
// storage-image writes (no storage resources or atomics at all), at most 8 sampled textures.
#pragma once

#include <cstdint>
#include <span>
#include <string>

namespace mobirt {

struct ShaderInterface {
  int color_outputs = 0;        // Output variables with a Location
  int sampled_textures = 0;     // combined image samplers and sampled images, arrays counted whole
  int storage_resources = 0;    // storage buffers and storage images
  int storage_writes = 0;       // OpImageWrite, OpAtomic*, stores through StorageBuffer pointers
  bool valid = false;           // the words parsed as a SPIR-V module
};

ShaderInterface reflect_spirv(std::span<const uint32_t> words);

// Throws Error(Constraint) naming the shader and the broken rule.
void check_es2_constraints(const std::string& shader, std::span<const uint32_t> words);

}  // namespace mobirt
