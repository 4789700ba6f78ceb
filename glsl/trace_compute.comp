#version 450
#extension GL_GOOGLE_include_directive : require
// The compute engine's traversal pass (src/baseline/compute_engine.h), the paper's named future
// work: mobirt's own kd-tree walk (traverse.glsl) and shadow rays (offset.glsl), the same tree,
// rays, stack and loop cap as glsl/trace.frag, as a compute shader over storage buffers. One
// invocation per ray; instead of one RGBA8 texel it writes a wide hit record (glsl/layout.h):
// t, barycentrics, primitive, shadow mask and shadow-ray count, so the CPU need not intersect again.
// It breaks the OpenGL ES 2.0 constraints on purpose (shader_constraints.h names them).
#include "prelude_compute.glsl"
#include "trace_compute_main.glsl"
