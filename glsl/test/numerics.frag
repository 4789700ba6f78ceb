// Test shader: the numeric primitives of the traversal pass against the CPU (numerics_test_main.glsl).
#version 450
#extension GL_GOOGLE_include_directive : require
#include "prelude_vk.glsl"
#define NUMERICS_DATA_INDEX  // data_index(): the buffers' index conversion, which GLSL ES has no need of
#include "numerics_test_main.glsl"
