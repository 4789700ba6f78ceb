#version 100
// One triangle that covers the whole viewport: vertices (-1,-1), (3,-1), (-1,3) from a vertex
// buffer (GLSL ES 1.00 has no gl_VertexID). Every pass of mobirt is a full-screen fragment pass.
attribute vec2 a_position;

void main() {
  gl_Position = vec4(a_position, 0.0, 1.0);
}
