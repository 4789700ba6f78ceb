#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_samplerless_texture_functions : require
// trace_compute.comp reading the nodes, leaf entries and triangles from uniform texel buffers,
// as the fragment pass does by default: the two compute passes tell the cost of the stage (compute
// against fragment) from the cost of the reads (storage buffers against texel buffers).
#define MOBIRT_DATA_TEXEL_BUFFERS
#include "prelude_compute.glsl"
#include "trace_compute_main.glsl"
