#version 310 es
// Test shader (GLES): writes a storage buffer, which OpenGL ES 2.0 does not have. Not valid
// GLSL ES 1.00 on purpose (so not validated at build time): the backend's source check must
// refuse it before any compiler sees it.
precision highp float;

layout(std430, binding = 7) writeonly buffer Sink {
  vec4 sink[];
};

layout(location = 0) out vec4 o_color;

void main() {
  sink[int(gl_FragCoord.y) * 4096 + int(gl_FragCoord.x)] = gl_FragCoord;
  o_color = vec4(0.0);
}
