#version 450
#extension GL_GOOGLE_include_directive : require
// The traversal pass (Vulkan) reading nodes, leaf entries and triangles from read-only storage
// buffers (--data storage-buffers): trace.frag with the prelude's storage-buffer DATA_TEXEL, to
// measure against texel buffers and images. OpenGL ES 2.0 has no storage buffers: the constraint
// checker names what this pass breaks, and only this pass is allowed to break it.
// The rays are storage buffers too, shared with shade_storage_buffers.frag.
#define MOBIRT_DATA_STORAGE_BUFFERS
#include "prelude_vk.glsl"
#include "trace_main.glsl"
