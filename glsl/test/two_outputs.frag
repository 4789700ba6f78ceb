// Test shader: writes two colour attachments. Must be refused at pass creation.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "prelude_vk.glsl"

layout(location = 1) out vec4 o_second;

void main() {
  OUTPUT(vec4(1.0, 0.0, 0.0, 1.0));
  o_second = vec4(0.0, 1.0, 0.0, 1.0);
}
