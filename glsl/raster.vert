#version 450
// The primary rays' closest triangles rasterized (--primary raster, Backend::run_raster): each
// vertex is placed where the primary ray through it crosses the image, as CameraBasis makes the
// rays (pixel centre (x, y) at x + 0.5, row 0 at the top), so that each fragment at a pixel centre
// is the triangle the ray through that centre meets first. Depth reversed: near / z, 1 at the
// near plane falling towards 0 with distance and never clipped far away, which a 32-bit float depth
// buffer resolves to the same relative precision at every distance (the raster pass tests GREATER).
// The GLSL ES 1.00 twin is glsl/es/raster.vert.

layout(push_constant) uniform RasterView {
  vec4 eye;
  vec4 right;
  vec4 up;
  vec4 forward;
  vec4 projection;  // x: 1 / (tan_half aspect), y: 1 / tan_half, z: near, w: far (unused here)
} u_view;

layout(location = 0) in vec4 a_vertex;  // xyz: position; w: the triangle's index + 1
layout(location = 0) flat out float v_index;

void main() {
  vec3 v = a_vertex.xyz - u_view.eye.xyz;
  float z = dot(v, u_view.forward.xyz);
  // Clip space y runs down here (framebuffer row 0 is the image's top row, as ray row 0 is).
  gl_Position = vec4(dot(v, u_view.right.xyz) * u_view.projection.x, -dot(v, u_view.up.xyz) * u_view.projection.y,
                     u_view.projection.z, z);
  v_index = a_vertex.w;
}
