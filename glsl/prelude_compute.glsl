// GLSL 450 compute dialect of mobirt's traversal (glsl/trace_compute.comp): prelude_vk.glsl's
// specialization constants, uniforms and numerics, with the scene data (nodes, primitive lists,
// triangles) in read-only storage buffers instead of textures, so that traverse.glsl and
// offset.glsl run unchanged. A compute shader has no fragment coordinate or colour output: its
// entry point reads its ray and writes its hit record itself.
#define MOBIRT_COMPUTE
#include "prelude_vk.glsl"

// Element i of a data array is element i of its buffer (indices are exact floats below 2^23);
// with MOBIRT_DATA_TEXEL_BUFFERS (trace_compute_texel_buffers.comp) prelude_vk.glsl's uniform
// texel buffers instead, as the fragment pass reads them.
#ifndef MOBIRT_DATA_TEXEL_BUFFERS
#define DATA_TEXEL(data, index) data[data_index(index)]
// Each array's element type, by the name traverse.glsl gives it.
#define MOBIRT_ELEMENT_u_nodes vec4
#define MOBIRT_ELEMENT_u_prim_list float
#define MOBIRT_ELEMENT_u_triangles vec4
#define DATA_SAMPLER(slot, name) \
  layout(std430, set = 0, binding = slot) readonly buffer name##_data { MOBIRT_ELEMENT_##name name[]; }
#endif
