// The OpenGL ES 2.0 constraints that mobirt mirrors, checked on a compiled fragment shader's
// SPIR-V rather than trusted by convention: exactly one vec4 colour output, no storage-buffer or
// storage-image writes (no storage resources or atomics at all), at most 8 sampled textures, and
// the scene in textures: no acceleration structures, no ray queries; and fragment passes only, no
// compute shaders.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace mobirt {

struct ShaderInterface {
  int color_outputs = 0;        // Output variables with a Location
  int sampled_textures = 0;     // combined image samplers and sampled images, arrays counted whole
  int storage_resources = 0;    // storage buffers, storage images, pointer types into memory by device address
  int storage_writes = 0;       // OpImageWrite, OpAtomic*, stores through StorageBuffer pointers
  int acceleration_structures = 0;  // VK_KHR_acceleration_structure variables
  bool ray_queries = false;     // the module declares a ray query object (SPV_KHR_ray_query)
  bool compute = false;         // a GLCompute entry point
  bool valid = false;           // the words parsed as a SPIR-V module
};

ShaderInterface reflect_spirv(std::span<const uint32_t> words);

// Every OpenGL ES 2.0 constraint the module breaks, one phrase each ("reads an acceleration
// structure ..."); empty when it keeps them all. The peers of mobirt (src/baseline/) break some on
// purpose and print this list rather than skip the check.
std::vector<std::string> es2_constraints_broken(std::span<const uint32_t> words);

// The rule a pass that only reads storage buffers breaks (the --data storage-buffers measurement
// variant of the traversal pass): OpenGL ES 2.0 has no storage buffers at all.
inline constexpr const char* kEs2StorageReads =
    "reads storage buffers; OpenGL ES 2.0 has none, the scene reaches a pass as textures";

// Throws Error(Constraint) naming the shader and the first broken rule. allow_storage_reads: a
// pass whose description binds storage buffers may read them (kEs2StorageReads), never write.
void check_es2_constraints(const std::string& shader, std::span<const uint32_t> words,
                           bool allow_storage_reads = false);

}  // namespace mobirt
