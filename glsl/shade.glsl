// Phong shading with the shadow mask from the traversal pass and KHR_lights_punctual falloff; the
// diffuse colour is modulated by the material's texture from the atlas. Common subset of GLSL 450
// and GLSL ES 1.00. Needs from the prelude: DATA_TEXEL, PARAM, LIGHT_COUNT, TEXTURE_COUNT.
#include "atlas.glsl"

// Materials: a 2D texture, or a texel buffer where the prelude says so (DATA_SAMPLER).
#ifndef DATA_SAMPLER
#define DATA_SAMPLER(slot, name) SAMPLER(slot, name)
#endif
DATA_SAMPLER(MOBIRT_BIND_MATERIALS, u_materials);

// Bit `index` of a float-encoded mask, without integer bit operations.
bool mask_bit(float mask, int index) {
  return mod(floor(mask / exp2(float(index))), 2.0) >= 1.0;
}

// KHR_lights_punctual: inverse-square falloff windowed to the range, and the spot's smooth cone.
float light_attenuation(float distance2, float range) {
  float window = 1.0;
  if (range > 0.0) {
    float r = distance2 / (range * range);
    window = clamp(1.0 - r * r, 0.0, 1.0);
    window = window * window;
  }
  return window / max(distance2, 1e-8);
}

// p: hit point, n: unit shading normal facing the viewer, v: unit direction towards the viewer,
// uv: the hit's texture coordinate (used only in scenes with textures).
vec3 shade_hit(vec3 p, vec3 n, vec3 v, float material, float mask, vec2 uv) {
  float base = material * float(MOBIRT_TEXELS_PER_MATERIAL);
  vec4 m0 = DATA_TEXEL(u_materials, base);        // diffuse, texture
  vec4 m1 = DATA_TEXEL(u_materials, base + 1.0);  // specular, shininess
  vec4 m2 = DATA_TEXEL(u_materials, base + 2.0);  // reflectance, transmittance, ior, ambient
  vec3 diffuse = m0.rgb;
  // TEXTURE_COUNT is a specialization constant: scenes without textures get no atlas code.
  if (TEXTURE_COUNT > 0 && m0.a >= 0.0) diffuse = diffuse * sample_atlas(m0.a, uv);
  vec3 color = m2.w * diffuse;
  for (int l = 0; l < LIGHT_COUNT; ++l) {
    if (!mask_bit(mask, l)) continue;
    int at = MOBIRT_SP_LIGHTS + MOBIRT_SP_VEC4S_PER_LIGHT * l;
    vec4 where = PARAM(at);
    vec4 radiance = PARAM(at + 1);
    vec3 to_light = where.xyz;
    float falloff = 1.0;
    if (where.w != MOBIRT_LIGHT_DIRECTIONAL) {
      to_light = where.xyz - p;
      falloff = light_attenuation(dot(to_light, to_light), radiance.w);
    }
    vec3 l_dir = normalize(to_light);
    if (where.w == MOBIRT_LIGHT_SPOT) {
      vec4 spot = PARAM(at + 2);
      float cos_outer = PARAM(at + 3).x;
      float cone = clamp((dot(-l_dir, spot.xyz) - cos_outer) / max(spot.w - cos_outer, 1e-4), 0.0, 1.0);
      falloff = falloff * cone * cone;
    }
    float n_dot_l = dot(n, l_dir);
    if (n_dot_l <= 0.0) continue;
    vec3 r = 2.0 * n_dot_l * n - l_dir;
    float spec = m1.a > 0.0 ? pow(max(dot(r, v), 0.0), m1.a) : 0.0;
    color = color + falloff * radiance.rgb * (diffuse * n_dot_l + m1.rgb * spec);
  }
  return color;
}
