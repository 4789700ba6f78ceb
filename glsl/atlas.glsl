// Texture lookup in the atlas pages: the MobiRT paper's 2048 x 2048 RGBA8 atlas of up to 16
// textures, repeated on as many pages as the texture units allow. Common subset of GLSL 450 and
// GLSL ES 1.00: no bit operations, no %, no integer textures, uniforms indexed only by loop
// indices. Needs from the prelude: PARAM, ATLAS_TEXEL, TEXTURE_COUNT, ATLAS_PAGES, LIGHT_COUNT.
// The CPU mirror, step for step, is sample_atlas() in src/scene/atlas.cpp; packing and the
// design choices are written down in src/scene/atlas.h.
//
// Uniforms, per texture t at PARAM(MOBIRT_SP_TEXTURES(LIGHT_COUNT) + MOBIRT_SP_VEC4S_PER_TEXTURE * t):
//   [0] xy = tile origin in its page's texels, zw = tile size in texels
//   [1] x = wrap s, y = wrap t (MOBIRT_WRAP_*), z = page
//
// Filtering is bilinear and done by hand: 4 fetches at texel centres, each texel index wrapped or
// clamped inside its own tile, so tiles need no gutter and never bleed into each other. The atlas
// holds sRGB-encoded values; each fetched texel is converted to linear before the blend.

// Every page is declared (SPIR-V cannot drop a binding by a specialization constant); ATLAS_PAGES
// folds the reads of pages the scene does not have away.
SAMPLER(MOBIRT_BIND_ATLAS_PAGE_0, u_atlas_page0);
SAMPLER(MOBIRT_BIND_ATLAS_PAGE_1, u_atlas_page1);
SAMPLER(MOBIRT_BIND_ATLAS_PAGE_2, u_atlas_page2);

// One texel index (an integer as a float) wrapped into [0, size) by mode, as OpenGL wraps the
// texels of a GL_LINEAR lookup. (i + 0.5) / size is never within 0.5 / size of an integer, so
// floor() of it is exact even with a division that is not correctly rounded. The final clamp keeps
// the index inside the tile even where float precision runs out (huge coordinates).
float atlas_wrap(float i, float size, float mode) {
  float r = i;
  if (mode == MOBIRT_WRAP_MIRRORED_REPEAT) {
    float period = 2.0 * size;
    r = i - period * floor((i + 0.5) / period);
    if (r >= size) r = period - 1.0 - r;
  } else if (mode != MOBIRT_WRAP_CLAMP) {
    r = i - size * floor((i + 0.5) / size);
  }
  return clamp(r, 0.0, size - 1.0);
}

// sRGB-encoded [0, 1] to linear.
vec3 atlas_srgb_to_linear(vec3 c) {
  return mix(c / 12.92, pow((c + 0.055) / 1.055, vec3(2.4)), step(vec3(0.04045), c));
}

// Samplers cannot be chosen by a value in GLSL ES 1.00 (no dynamic indexing of samplers, no
// sampler variables), hence one branch per page.
vec3 atlas_texel_linear(float page, float x, float y) {
  vec2 xy = vec2(x, y);
  vec4 texel;
  if (ATLAS_PAGES > 2 && page == 2.0) {
    texel = ATLAS_TEXEL(u_atlas_page2, xy);
  } else if (ATLAS_PAGES > 1 && page == 1.0) {
    texel = ATLAS_TEXEL(u_atlas_page1, xy);
  } else {
    texel = ATLAS_TEXEL(u_atlas_page0, xy);
  }
  return atlas_srgb_to_linear(texel.rgb);
}

// Linear RGB of texture `texture_index` (an index into the scene's textures, as a float) at
// texture coordinate uv (glTF convention: (0, 0) is the top-left corner of the image).
vec3 sample_atlas(float texture_index, vec2 uv) {
  vec4 tile = vec4(0.0, 0.0, 1.0, 1.0);
  vec4 wrap = vec4(0.0);
  for (int t = 0; t < TEXTURE_COUNT; ++t) {
    if (float(t) == texture_index) {
      tile = PARAM(MOBIRT_SP_TEXTURES(LIGHT_COUNT) + MOBIRT_SP_VEC4S_PER_TEXTURE * t);
      wrap = PARAM(MOBIRT_SP_TEXTURES(LIGHT_COUNT) + MOBIRT_SP_VEC4S_PER_TEXTURE * t + 1);
    }
  }
  vec2 p = uv * tile.zw - 0.5;
  vec2 p0 = floor(p);
  vec2 f = p - p0;
  float x0 = tile.x + atlas_wrap(p0.x, tile.z, wrap.x);
  float x1 = tile.x + atlas_wrap(p0.x + 1.0, tile.z, wrap.x);
  float y0 = tile.y + atlas_wrap(p0.y, tile.w, wrap.y);
  float y1 = tile.y + atlas_wrap(p0.y + 1.0, tile.w, wrap.y);
  vec3 top = mix(atlas_texel_linear(wrap.z, x0, y0), atlas_texel_linear(wrap.z, x1, y0), f.x);
  vec3 bottom = mix(atlas_texel_linear(wrap.z, x0, y1), atlas_texel_linear(wrap.z, x1, y1), f.x);
  return mix(top, bottom, f.y);
}
