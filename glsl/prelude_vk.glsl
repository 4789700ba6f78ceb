// GLSL 450 (Vulkan, SPIR-V) dialect of mobirt's shaders. Every .frag for Vulkan is
//   #version 450
//   #extension GL_GOOGLE_include_directive : require
//   #include "prelude_vk.glsl"
// followed by the shared bodies. The GLSL ES 1.00 prelude provides the same names.
#extension GL_EXT_control_flow_attributes : require
#include "layout.h"

// Scene specialisation: specialization constants, so that one SPIR-V module serves every scene
// and the driver folds the constants when it builds the pipeline.
layout(constant_id = MOBIRT_SPEC_LIGHT_COUNT) const int LIGHT_COUNT = 0;
layout(constant_id = MOBIRT_SPEC_STACK_DEPTH) const int STACK_DEPTH = 6;
layout(constant_id = MOBIRT_SPEC_MAX_STEPS) const int MAX_STEPS = 4096;
layout(constant_id = MOBIRT_SPEC_PACKING) const int PACKING = MOBIRT_PACKING_24_8;
layout(constant_id = MOBIRT_SPEC_TEXTURE_COUNT) const int TEXTURE_COUNT = 0;
layout(constant_id = MOBIRT_SPEC_INTERSECT) const int INTERSECT = MOBIRT_INTERSECT_MT;
layout(constant_id = MOBIRT_SPEC_PRECISION) const int PRECISION = MOBIRT_PRECISION_HIGH;
layout(constant_id = MOBIRT_SPEC_OFFSET) const int OFFSET_MODE = MOBIRT_OFFSET_SCALED;
layout(constant_id = MOBIRT_SPEC_COLOUR) const int COLOUR = MOBIRT_COLOUR_8;
layout(constant_id = MOBIRT_SPEC_ATLAS_PAGES) const int ATLAS_PAGES = 0;
layout(constant_id = MOBIRT_SPEC_ANALYTIC) const int ANALYTIC = 0;
layout(constant_id = MOBIRT_SPEC_WIDE_INDICES) const int WIDE_INDICES = 0;
layout(constant_id = MOBIRT_SPEC_PRIMARY_HITS) const int PRIMARY_HITS = 0;
layout(constant_id = MOBIRT_SPEC_LIGHT_BUFFERS) const int LIGHT_BUFFERS = 0;

// A loop that only its body ends (a break, a return or the step cap MAX_STEPS checked inside):
// GLSL 450 needs no index, and llvmpipe adds a counter of its own to every loop anyway.
#define UNBOUNDED_LOOP(i, limit) for (;;)
// traverse()'s short stack without a count of its entries (see there).
#define STACK_COUNTED 0
// traverse() marks a leaf to close with a node index of -1 (see there).
#define LEAF_CLOSE_IN_NODE 1
// An `if` kept a branch (GL_EXT_control_flow_attributes' dont_flatten, which Mesa's NIR honours)
// rather than turned into selects: llvmpipe skips a branch that no lane of a SIMD group takes.
#define KEEP_BRANCH [[dont_flatten]]
// ES keeps a branch by the size of its body (prelude_es.glsl); here x as it is.
#define KEEP_BRANCH_PAD(x) (x)

// No contraction into fused multiply-adds where an expression must round as the CPU's does
// (precision.glsl) or the same way in every triangle that computes it (the watertight test).
#define PRECISE precise
#include "precision.glsl"

// The numeric primitive that GLSL ES 1.00 lacks (prelude_es.glsl emulates it arithmetically, to
// the same bits).
// The float whose bits, read as a signed integer, are x's plus k (an integer value): x moved by k
// units in the last place, away from zero for k > 0. Wachter and Binder's offset (offset.glsl), and
// traverse()'s kd-restart (k = 1: the next float up).
float add_float_bits(float x, float k) {
  return intBitsToFloat(floatBitsToInt(x) + int(k));
}

// The pass's uniforms: one vec4 array (indices in layout.h).
layout(set = 0, binding = 0, std140) uniform Params {
  vec4 u_params[MOBIRT_MAX_PARAM_VEC4S];
};
#define PARAM(i) u_params[i]

// Exact integer floats 0 <= v < 2^23 as ints without a float-to-int conversion: v + 2^23 is the
// float whose bits are 0x4B000000 + v. Mesa 25's llvmpipe converts with saturating semantics that
// LLVM 15 turns into eight scalar conversions with clamps per vector (about 60 instructions for an
// ivec2); this is one add and one subtract.
ivec2 small_floats_to_ints(vec2 v) {
  precise vec2 biased = v + 8388608.0;
  return floatBitsToInt(biased) - 0x4B000000;
}

// Data textures: element i at texel (i mod W, i div W). Indices arrive as exact floats below 2^24;
// W is a power of two, so the row (a division by W and a floor) and the column are exact.
ivec2 data_coord(float index) {
  precise float row = floor(index * (1.0 / float(MOBIRT_DATA_WIDTH)));
  precise float column = index - row * float(MOBIRT_DATA_WIDTH);
  return small_floats_to_ints(vec2(column, row));
}
// Data as one-dimensional arrays (texel buffers here, storage buffers in prelude_compute.glsl):
// element i is texel i. Indices are exact floats below 2^24 (the backend refuses larger buffers).
// Below 2^23 the same bit trick makes them ints. A pass that binds a buffer of more than 2^23 texels
// is specialised to WIDE_INDICES (the Vulkan backend refuses it otherwise): from 2^23 on, an exact
// integer float's own bits are 0x4B000000 + (index - 2^23) (exponent 23, spacing 1), so index is
// its bits - 0x4A800000. Selects, not a branch: NIR would turn so small an `if` into selects
// anyway.
int data_index(float index) {
  if (WIDE_INDICES == 0) {
    precise float biased = index + 8388608.0;
    return floatBitsToInt(biased) - 0x4B000000;
  }
  bool high = index >= 8388608.0;
  precise float biased = high ? index : index + 8388608.0;
  return floatBitsToInt(biased) - (high ? 0x4A800000 : 0x4B000000);
}
#ifdef MOBIRT_DATA_TEXEL_BUFFERS
// Data textures as uniform texel buffers (trace_texel_buffers.frag, and the compute pass's
// trace_compute_texel_buffers.comp), with no mip-level work or 2D bounds checks in llvmpipe's fetch.
#define DATA_TEXEL(tex, index) texelFetch(tex, data_index(index))
// A textureBuffer, not a samplerBuffer: SPIR-V forbids a sampled image of a buffer (Mesa warns),
// so the includer enables GL_EXT_samplerless_texture_functions for texelFetch on it.
#define DATA_SAMPLER(slot, name) layout(set = 0, binding = slot) uniform textureBuffer name
#elif defined(MOBIRT_DATA_STORAGE_BUFFERS) || defined(MOBIRT_DATA_DEVICE_ADDRESSES)
// Each array's element type, by the name traverse.glsl gives it.
#define MOBIRT_ELEMENT_u_nodes vec4
#define MOBIRT_ELEMENT_u_leaf_prims vec4
#define MOBIRT_ELEMENT_u_triangles vec4
#define MOBIRT_ELEMENT_u_ray_origin vec4
#define MOBIRT_ELEMENT_u_ray_direction vec4
#define MOBIRT_ELEMENT_u_hit_position vec4
#define MOBIRT_ELEMENT_u_hit_normal vec4
#define MOBIRT_ELEMENT_u_hit_texcoord vec4
#define MOBIRT_ELEMENT_u_materials vec4
#if defined(MOBIRT_DATA_STORAGE_BUFFERS)
// Data arrays as read-only storage buffers (the compute pass's default, trace_compute.comp, and
// the fragment pass's --data storage-buffers, trace_storage_buffers.frag): element i of the array
// is element i of its buffer, laid out (std430) byte for byte as the texel buffers are.
#define DATA_TEXEL(data, index) data[data_index(index)]
#define DATA_SAMPLER(slot, name) \
  layout(std430, set = 0, binding = slot) readonly buffer name##_data { MOBIRT_ELEMENT_##name name[]; }
#else
// Data arrays read through buffer references (--data device-addresses): the same buffers, laid
// out as the storage buffers are, each reached by the address the backend pushes for its binding
// (layout.h, MOBIRT_PASS_ADDRESSES). A name declares its slot; a read makes the reference.
// The index is kept below 2^24 (every array's bound, kKdIndexLimit) by a mask: llvmpipe forms the
// address of every lane of a SIMD group, a lane that is done too, whose index may be any float
// (NaN, huge) and data_index() of it any int; on an AVX-512 CPU its masked gather then faulted
// (#GP) on a non-canonical address past the buffer's by 2^31 elements (a Zen 4, 2026-12-06).
// The mask ends that kind, not all: other gathers there faulted on addresses with no index in
// them, so the renderer refuses this mode on such CPUs (device_address_reads_fault).
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer MobirtData_vec4 { vec4 e[]; };
#define MOBIRT_REFERENCE_TYPE2(element) MobirtData_##element
#define MOBIRT_REFERENCE_TYPE(element) MOBIRT_REFERENCE_TYPE2(element)
#define DATA_SAMPLER(slot, name) const int mobirt_slot_##name = slot
#define DATA_TEXEL(data, index) \
  MOBIRT_REFERENCE_TYPE(MOBIRT_ELEMENT_##data)(u_address[mobirt_slot_##data]).e[data_index(index) & 0xFFFFFF]
#endif
#else
#define DATA_TEXEL(tex, index) texelFetch(tex, data_coord(index), 0)
#endif
// prelude_es.glsl's fetch with the row scale read before a loop; buffers and texelFetch need none.
#define DATA_ROWS(s) 0.0
#define DATA_TEXEL_ROWS(s, rows, index) DATA_TEXEL(s, index)

#ifndef MOBIRT_COMPUTE  // a compute shader reads its ray and writes its result itself
#if defined(MOBIRT_DATA_TEXEL_BUFFERS) || defined(MOBIRT_DATA_STORAGE_BUFFERS) || defined(MOBIRT_DATA_DEVICE_ADDRESSES)
// Per-ray data (rays, the shading pass's inputs) in buffers like the scene data, in the pass's
// layout: this fragment's ray is element y * width + x (an exact float below 2^24), the width
// pushed by the backend with every pass. llvmpipe's 2D texelFetch is an indirect call with
// mip-level work per fetch; a buffer's fetch is not.
layout(push_constant) uniform PassConstants {
  int u_ray_width;
#if defined(MOBIRT_DATA_DEVICE_ADDRESSES)
  layout(offset = MOBIRT_PASS_ADDRESSES) uvec2 u_address[MOBIRT_PASS_ADDRESS_SLOTS];  // per binding slot
#endif
};
float ray_index() {
  vec2 p = floor(gl_FragCoord.xy);
  return p.y * float(u_ray_width) + p.x;
}
#define RAY_TEXEL(tex) DATA_TEXEL(tex, ray_index())
#else
// Per-ray textures share the pass's layout: this fragment's own ray.
#define RAY_TEXEL(tex) texelFetch(tex, small_floats_to_ints(floor(gl_FragCoord.xy)), 0)
#endif
// Texture atlas page (RGBA8, NEAREST): the texel at integer coordinates xy (exact floats), no filtering.
// The GLES prelude reads it with texture2D at the texel centre (xy + 0.5) / MOBIRT_ATLAS_SIZE.
// The clamp keeps a NaN coordinate (which the bit trick turns into a huge index) inside the atlas.
#define ATLAS_TEXEL(tex, xy) texelFetch(tex, clamp(small_floats_to_ints(xy), 0, MOBIRT_ATLAS_SIZE - 1), 0)
// Texture atlas page (R8G8B8A8_SRGB behind the LINEAR sampler of PassDesc::linear_bindings): one
// bilinear fetch at normalised page coordinates uv, decoded from sRGB per texel before the filter.
// Its presence selects atlas.glsl's one-fetch lookup.
#define ATLAS_FILTERED(tex, uv) textureLod(tex, uv, 0.0)

#define SAMPLER(slot, name) layout(set = 0, binding = slot) uniform sampler2D name

layout(location = 0) out vec4 o_color;
#define OUTPUT(value) o_color = (value)
#endif  // MOBIRT_COMPUTE
