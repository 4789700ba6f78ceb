// Test shader: writes a storage texel buffer (imageBuffer + imageStore), a storage write that
// OpenGL ES 2.0 cannot do. Must be refused like any storage image.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "prelude_vk.glsl"

layout(set = 0, binding = 1, rgba32f) uniform writeonly imageBuffer u_out;

void main() {
  imageStore(u_out, 0, vec4(1.0));
  OUTPUT(vec4(0.0));
}
