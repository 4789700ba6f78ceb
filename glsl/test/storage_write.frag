// Test shader: writes a storage buffer. Must be refused at pass creation.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "prelude_vk.glsl"

layout(set = 0, binding = 7, std430) writeonly buffer Sink {
  vec4 sink[];
};

void main() {
  const int index = int(gl_FragCoord.y) * 4096 + int(gl_FragCoord.x);
  sink[index] = gl_FragCoord;
  OUTPUT(vec4(0.0));
}
