#version 100
// glsl/raster.vert for OpenGL ES 2.0: the same placement, the view as uniforms, depth from near
// (-1) to far (1) for a 24-bit fixed-point buffer. GLSL ES 1.00 has no flat varyings: the index is
// interpolated from three equal values, which rounding moves off the integer by an ulp or so; an
// ulp of an index past 2^22 is 0.5 or more, so it travels as two 12-bit halves, each far from that
// (raster.frag rounds them and writes the bytes; raster_primary_test, LargestIndicesComeBackExact).
uniform highp vec4 u_eye;
uniform highp vec4 u_right;
uniform highp vec4 u_up;
uniform highp vec4 u_forward;
uniform highp vec4 u_projection;  // x: 1 / (tan_half aspect), y: 1 / tan_half, z: near, w: far
attribute highp vec4 a_vertex;    // xyz: position; w: the triangle's index + 1
varying highp float v_index_high;  // floor((index + 1) / 4096)
varying highp float v_index_low;   // (index + 1) mod 4096

void main() {
  highp vec3 v = a_vertex.xyz - u_eye.xyz;
  highp float z = dot(v, u_forward.xyz);
  highp float n = u_projection.z;
  highp float f = u_projection.w;
  // Clip space y runs down (window row 0 is the image's top row, as ray row 0 is).
  gl_Position = vec4(dot(v, u_right.xyz) * u_projection.x, -dot(v, u_up.xyz) * u_projection.y,
                     z * ((f + n) / (f - n)) - 2.0 * f * n / (f - n), z);
  // Exact: w is an integer below 2^24, and a division by a power of two only moves the exponent.
  v_index_high = floor(a_vertex.w / 4096.0);
  v_index_low = a_vertex.w - 4096.0 * v_index_high;
}
