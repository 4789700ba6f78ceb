#include "backend/shader_constraints.h"

#include <unordered_map>
#include <vector>
#include <unordered_set>

#include "core/error.h"
#include "layout.h"

namespace mobirt {

namespace {

// The few SPIR-V opcodes, storage classes and decorations the check needs (SPIR-V 1.0 spec).
enum Op : uint32_t {
  OpTypeImage = 25, OpTypeSampledImage = 27, OpTypeArray = 28, OpTypeStruct = 30,
  OpEntryPoint = 15, OpTypePointer = 32, OpConstant = 43, OpVariable = 59, OpStore = 62, OpAccessChain = 65,
  OpInBoundsAccessChain = 66, OpPtrAccessChain = 67, OpDecorate = 71, OpCopyObject = 83, OpImageWrite = 99,
  OpConvertUToPtr = 120, OpBitcast = 124,
  OpAtomicFirst = 227, OpAtomicLast = 242,  // OpAtomicLoad .. OpAtomicXor
  OpTypeRayQueryKHR = 4472, OpTypeAccelerationStructureKHR = 5341,  // SPV_KHR_ray_query, _ray_tracing
};
enum StorageClass : uint32_t {
  UniformConstant = 0, Input = 1, Uniform = 2, Output = 3, StorageBuffer = 12,
  PhysicalStorageBuffer = 5349,  // buffer references (GL_EXT_buffer_reference): memory by device address
};
enum ExecutionModel : uint32_t { GLCompute = 5 };
enum Decoration : uint32_t { BufferBlock = 3, BuiltIn = 11, Location = 30 };

}  // namespace

ShaderInterface reflect_spirv(std::span<const uint32_t> words) {
  ShaderInterface result;
  if (words.size() < 5 || words[0] != 0x07230203u) return result;

  std::unordered_map<uint32_t, std::pair<uint32_t, uint32_t>> pointers;  // id -> (class, type)
  std::unordered_map<uint32_t, uint32_t> image_sampled;                   // image type -> Sampled
  std::unordered_set<uint32_t> sampled_image_types, acceleration_structure_types;
  std::unordered_map<uint32_t, std::pair<uint32_t, uint32_t>> arrays;     // id -> (element, length id)
  std::unordered_map<uint32_t, uint32_t> constants;
  std::unordered_set<uint32_t> buffer_blocks, located, builtins;
  struct Variable { uint32_t id, pointer_type, storage; };
  std::vector<Variable> variables;
  std::unordered_set<uint32_t> storage_pointers;  // ids of pointers into storage buffers or by address
  std::unordered_set<uint32_t> address_pointer_types;  // pointer types into PhysicalStorageBuffer

  for (size_t i = 5; i < words.size();) {
    const uint32_t count = words[i] >> 16;
    const uint32_t op = words[i] & 0xffffu;
    if (count == 0 || i + count > words.size()) return result;
    const uint32_t* w = &words[i];
    switch (op) {
      case OpEntryPoint: result.compute = result.compute || w[1] == GLCompute; break;
      case OpTypeImage: image_sampled[w[1]] = w[7]; break;
      case OpTypeSampledImage: sampled_image_types.insert(w[1]); break;
      case OpTypeAccelerationStructureKHR: acceleration_structure_types.insert(w[1]); break;
      case OpTypeRayQueryKHR: result.ray_queries = true; break;
      case OpTypeArray: arrays[w[1]] = {w[2], w[3]}; break;
      case OpTypePointer:
        pointers[w[1]] = {w[2], w[3]};
        // Memory read by device address is a storage resource, read or written (--data device-addresses).
        if (w[2] == PhysicalStorageBuffer && address_pointer_types.insert(w[1]).second) ++result.storage_resources;
        break;
      case OpConstant: if (count >= 4) constants[w[2]] = w[3]; break;
      case OpDecorate:
        if (w[2] == BufferBlock) buffer_blocks.insert(w[1]);
        if (w[2] == Location) located.insert(w[1]);
        if (w[2] == BuiltIn) builtins.insert(w[1]);
        break;
      case OpVariable: variables.push_back({w[2], w[1], w[3]}); break;
      case OpAccessChain:
      case OpInBoundsAccessChain:
      case OpPtrAccessChain:
      case OpCopyObject:
      case OpBitcast:
      case OpConvertUToPtr:
        // A pointer into a storage buffer, or any pointer into memory by device address.
        if ((op != OpBitcast && op != OpConvertUToPtr && storage_pointers.count(w[3])) || address_pointer_types.count(w[1])) {
          storage_pointers.insert(w[2]);
        }
        break;
      case OpStore:
        if (storage_pointers.count(w[1])) ++result.storage_writes;
        break;
      case OpImageWrite: ++result.storage_writes; break;
      default:
        if (op >= OpAtomicFirst && op <= OpAtomicLast) ++result.storage_writes;
        break;
    }
    // Variables are declared before function bodies, so storage pointers are known by then.
    if (op == OpVariable) {
      const auto pointer = pointers.find(w[1]);
      if (pointer != pointers.end()) {
        const uint32_t storage = pointer->second.first;
        const uint32_t pointee = pointer->second.second;
        if (storage == StorageBuffer || (storage == Uniform && buffer_blocks.count(pointee))) {
          storage_pointers.insert(w[2]);
        }
      }
    }
    i += count;
  }

  for (const Variable& v : variables) {
    const auto pointer = pointers.find(v.pointer_type);
    if (pointer == pointers.end()) continue;
    uint32_t type = pointer->second.second;
    uint32_t multiplicity = 1;
    while (arrays.count(type)) {
      const auto [element, length_id] = arrays[type];
      multiplicity *= constants.count(length_id) ? constants[length_id] : 1;
      type = element;
    }
    if (v.storage == Output && located.count(v.id)) ++result.color_outputs;
    if (v.storage == StorageBuffer || (v.storage == Uniform && buffer_blocks.count(type))) {
      ++result.storage_resources;
    }
    if (v.storage == UniformConstant) {
      if (sampled_image_types.count(type)) result.sampled_textures += int(multiplicity);
      if (acceleration_structure_types.count(type)) result.acceleration_structures += int(multiplicity);
      const auto image = image_sampled.find(type);
      if (image != image_sampled.end()) {
        if (image->second == 2) ++result.storage_resources;
        else result.sampled_textures += int(multiplicity);
      }
    }
  }
  result.valid = true;
  return result;
}

std::vector<std::string> es2_constraints_broken(std::span<const uint32_t> words) {
  const ShaderInterface s = reflect_spirv(words);
  if (!s.valid) return {"is not a valid SPIR-V module"};
  std::vector<std::string> broken;
  if (s.compute) {
    broken.push_back("is a compute shader; OpenGL ES 2.0 has vertex and fragment shaders only");
  }
  if (s.color_outputs != 1) {
    broken.push_back("writes " + std::to_string(s.color_outputs) +
                     " colour attachments; a pass writes exactly one RGBA8 texel");
  }
  if (s.storage_writes > 0) {
    broken.push_back("uses storage buffers, storage images or atomics; passes may only write their colour attachment");
  } else if (s.storage_resources > 0) {
    broken.push_back(kEs2StorageReads);
  }
  if (s.sampled_textures > MOBIRT_MAX_SAMPLED_TEXTURES) {
    broken.push_back("samples " + std::to_string(s.sampled_textures) + " textures; at most " +
                     std::to_string(MOBIRT_MAX_SAMPLED_TEXTURES) + " are allowed (GL_MAX_TEXTURE_IMAGE_UNITS)");
  }
  if (s.acceleration_structures > 0) {
    broken.push_back("reads an acceleration structure (VK_KHR_acceleration_structure); the scene must reach a pass "
                     "as textures");
  }
  if (s.ray_queries) {
    broken.push_back("traces rays with ray queries (SPV_KHR_ray_query); OpenGL ES 2.0 has no ray tracing");
  }
  return broken;
}

void check_es2_constraints(const std::string& shader, std::span<const uint32_t> words, bool allow_storage_reads) {
  for (const std::string& rule : es2_constraints_broken(words)) {
    if (allow_storage_reads && rule == kEs2StorageReads) continue;
    throw Error(ErrorKind::Constraint, "shader " + shader + ": " + rule + " (OpenGL ES 2.0 constraint mirrored by mobirt)");
  }
}

}  // namespace mobirt
