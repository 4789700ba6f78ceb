#version 100
#include "prelude_es.glsl"
#include "shade_main.glsl"
