#version 100
// Test shader (GLES): writes two colour outputs (gl_FragData[0] and [1]). Must be refused.
#include "prelude_es.glsl"

void main() {
  gl_FragData[0] = vec4(1.0, 0.0, 0.0, 1.0);
  gl_FragData[1] = vec4(0.0, 1.0, 0.0, 1.0);
}
