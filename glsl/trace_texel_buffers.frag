#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_samplerless_texture_functions : require
// The traversal pass (Vulkan) reading nodes, leaf entries and triangles from uniform texel
// buffers (--data texel-buffers): trace.frag with the prelude's texel-buffer DATA_TEXEL. A second
// SPIR-V module rather than a specialisation constant, since a binding's type cannot be specialised.
// The rays are texel buffers too, shared with shade_texel_buffers.frag.
#define MOBIRT_DATA_TEXEL_BUFFERS
#include "prelude_vk.glsl"
#include "trace_main.glsl"
