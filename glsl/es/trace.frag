#version 100
#include "prelude_es.glsl"
#include "trace_main.glsl"
