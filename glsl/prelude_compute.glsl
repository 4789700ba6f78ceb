// GLSL 450 compute dialect of mobirt's traversal (glsl/trace_compute.comp): prelude_vk.glsl's
// specialization constants, uniforms and numerics, with the scene data (nodes, leaf entries,
// triangles) in read-only storage buffers instead of textures, so that traverse.glsl and
// offset.glsl run unchanged. A compute shader has no fragment coordinate or colour output: its
// entry point reads its ray and writes its hit record itself.
#define MOBIRT_COMPUTE
// Storage buffers unless the includer asked for texel buffers.
#ifndef MOBIRT_DATA_TEXEL_BUFFERS
#define MOBIRT_DATA_STORAGE_BUFFERS
#endif
#include "prelude_vk.glsl"
