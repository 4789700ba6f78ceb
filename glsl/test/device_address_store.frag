// Test shader: writes memory through a buffer reference (GL_EXT_buffer_reference), a storage write
// that OpenGL ES 2.0 cannot do. Must be refused whatever the pass declares, as a storage-buffer
// write is; --data device-addresses only reads that way.
#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_buffer_reference_uvec2 : require
#include "prelude_vk.glsl"

layout(buffer_reference, std430, buffer_reference_align = 16) buffer Out { vec4 e[]; };
layout(push_constant) uniform Constants {
  int u_width;
  layout(offset = MOBIRT_PASS_ADDRESSES) uvec2 u_out;
};

void main() {
  Out(u_out).e[0] = vec4(1.0);
  OUTPUT(vec4(0.0));
}
