// main() of the shading pass, shared by glsl/shade.frag (Vulkan) and glsl/es/shade.frag (GLES).
// One fragment per ray, Phong with the traversal pass's shadow mask; writes ONE RGBA8 texel: the
// colour, or the high or low bytes of its 16-bit version (colour.glsl).
#include "shade.glsl"
#include "colour.glsl"

// Per-ray data, read as the scene data is: 2D textures, or buffers where the prelude says so.
DATA_SAMPLER(MOBIRT_BIND_HIT_POSITION, u_hit_position);      // xyz, material (-1 = miss)
DATA_SAMPLER(MOBIRT_BIND_HIT_NORMAL, u_hit_normal);          // xyz, shadow mask
DATA_SAMPLER(MOBIRT_BIND_SHADE_RAY_DIRECTION, u_ray_direction);
DATA_SAMPLER(MOBIRT_BIND_HIT_TEXCOORD, u_hit_texcoord);      // xy

void main() {
  vec4 position = RAY_TEXEL(u_hit_position);
  if (position.w < 0.0) {
    OUTPUT(encode_colour(clamp(PARAM(MOBIRT_SP_BACKGROUND).rgb, 0.0, 1.0)));
    return;
  }
  vec4 normal = RAY_TEXEL(u_hit_normal);
  vec3 v = -normalize(RAY_TEXEL(u_ray_direction).xyz);
  vec2 uv = vec2(0.0);
  if (TEXTURE_COUNT > 0) uv = RAY_TEXEL(u_hit_texcoord).xy;
  OUTPUT(encode_colour(clamp(shade_hit(position.xyz, normal.xyz, v, position.w, normal.w, uv), 0.0, 1.0)));
}
