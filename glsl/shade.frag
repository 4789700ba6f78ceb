#version 450
#extension GL_GOOGLE_include_directive : require
// The shading pass (Vulkan): the GLSL 450 prelude and the shared body in shade_main.glsl.
#include "prelude_vk.glsl"
#include "shade_main.glsl"
