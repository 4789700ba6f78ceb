// One triangle that covers the whole viewport, from gl_VertexIndex alone (no vertex input):
// vertices (-1,-1), (3,-1), (-1,3). Every pass of mobirt is a full-screen fragment pass over rays.
#version 450

void main() {
  const vec2 position = vec2(float((gl_VertexIndex << 1) & 2), float(gl_VertexIndex & 2));
  gl_Position = vec4(position * 2.0 - 1.0, 0.0, 1.0);
}
