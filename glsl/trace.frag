#version 450
#extension GL_GOOGLE_include_directive : require
// The traversal pass (Vulkan): the GLSL 450 prelude and the shared body in trace_main.glsl.
#include "prelude_vk.glsl"
#include "trace_main.glsl"
