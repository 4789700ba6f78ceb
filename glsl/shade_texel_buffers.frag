#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_samplerless_texture_functions : require
// The shading pass (Vulkan) under --data texel-buffers: its per-ray inputs (hit position, normal,
// texture coordinate, ray direction) and the materials are uniform texel buffers, like the
// traversal pass's data (shade.frag with the prelude's texel-buffer RAY_TEXEL and DATA_TEXEL).
// The atlas pages stay 2D images.
#define MOBIRT_DATA_TEXEL_BUFFERS
#include "prelude_vk.glsl"
#include "shade_main.glsl"
