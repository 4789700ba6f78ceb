#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_buffer_reference_uvec2 : require
// The traversal pass (Vulkan) reading nodes, leaf entries, triangles and rays through buffer
// references (--data device-addresses): trace.frag with the prelude's device-address DATA_TEXEL.
// llvmpipe compiles such a read to an inline masked gather, where a texel fetch is a call into the
// descriptor's texture function and a storage-buffer read a loop over the lanes; the measurement
// of what the ES 2.0 model's textures cost on lavapipe. OpenGL ES 2.0 has no such memory: the
// constraint checker names what this pass breaks, and only a pass that declares it may break it.
#define MOBIRT_DATA_DEVICE_ADDRESSES
#include "prelude_vk.glsl"
#include "trace_main.glsl"
