#version 100
// Test shader (GLES): the numeric primitives against the CPU (numerics_test_main.glsl).
#include "prelude_es.glsl"
#include "numerics_test_main.glsl"
