// Test shader: the numeric primitives of the traversal pass against the CPU (numerics_test_main.glsl).
#version 450
#extension GL_GOOGLE_include_directive : require
#include "prelude_vk.glsl"
#include "numerics_test_main.glsl"
