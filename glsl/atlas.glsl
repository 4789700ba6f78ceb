// Texture lookup in the atlas pages: the MobiRT paper's 2048 x 2048 RGBA8 atlas of up to 16
// textures, repeated on as many pages as the texture units allow. Common subset of GLSL 450 and
// GLSL ES 1.00: no bit operations, no %, no integer textures, uniforms indexed only by loop
// indices. Needs from the prelude: PARAM, ATLAS_FILTERED or ATLAS_TEXEL, TEXTURE_COUNT, ATLAS_PAGES,
// LIGHT_COUNT. The CPU mirror of the ATLAS_TEXEL path, step for step, is sample_atlas() in
// src/scene/atlas.cpp; packing, gutters and the design choices are written down in src/scene/atlas.h.
//
// Uniforms, per texture t at PARAM(MOBIRT_SP_TEXTURES(LIGHT_COUNT) + MOBIRT_SP_VEC4S_PER_TEXTURE * t):
//   [0] xy = the tile's first texel in its page (inside its gutter), zw = tile size in texels
//   [1] x = wrap s, y = wrap t (MOBIRT_WRAP_*), z = page
//
// The coordinate is wrapped into [0, 1] once; the tile's gutter (src/scene/atlas.h) holds the
// texels its wrap mode puts beyond each edge, so a bilinear footprint never leaves tile + gutter.
// Where the prelude offers ATLAS_FILTERED (Vulkan: an R8G8B8A8_SRGB page behind a LINEAR sampler),
// ONE hardware fetch filters, decoding sRGB per texel first. GLSL ES 1.00 has no sRGB textures
// (no GL_EXT_sRGB on Mesa's ES 2.0 context): 4 NEAREST fetches, each decoded, blended exactly.
// Under --colour 16 (COLOUR not MOBIRT_COLOUR_8: the image is the product) Vulkan does the same
// from RGBA8 pages (atlas_page_format's exact pages): llvmpipe's decode of sRGB texels alone held
// the 16-bit images at 64-66 dB against the reference, where the shader's decode reaches 85-90.

// Every page is declared (SPIR-V cannot drop a binding by a specialization constant); ATLAS_PAGES
// folds the reads of pages the scene does not have away.
SAMPLER(MOBIRT_BIND_ATLAS_PAGE_0, u_atlas_page0);
SAMPLER(MOBIRT_BIND_ATLAS_PAGE_1, u_atlas_page1);
SAMPLER(MOBIRT_BIND_ATLAS_PAGE_2, u_atlas_page2);

// A texture coordinate wrapped into [0, 1] by mode (as atlas_wrap_coord() on the CPU). The clamp
// keeps even a NaN coordinate inside the tile.
float atlas_wrap_coord(float u, float mode) {
  float r = u - floor(u);
  if (mode == MOBIRT_WRAP_MIRRORED_REPEAT) {
    r = 1.0 - abs(1.0 - (u - 2.0 * floor(0.5 * u)));
  } else if (mode == MOBIRT_WRAP_CLAMP) {
    r = u;
  }
  return clamp(r, 0.0, 1.0);
}

// sRGB-encoded [0, 1] to linear.
vec3 atlas_srgb_to_linear(vec3 c) {
  return mix(c / 12.92, pow((c + 0.055) / 1.055, vec3(2.4)), step(vec3(0.04045), c));
}

// What a lookup reads from a page: one filtered sample at normalised page coordinates where the
// prelude offers ATLAS_FILTERED (sRGB decoded by the sampler), else one texel at integer coordinates.
#ifdef ATLAS_FILTERED
#define ATLAS_READ(tex, xy) ATLAS_FILTERED(tex, xy)
#else
#define ATLAS_READ(tex, xy) ATLAS_TEXEL(tex, xy)
#endif

// Samplers cannot be chosen by a value in GLSL ES 1.00 (no dynamic indexing of samplers, no
// sampler variables), hence one branch per page.
vec4 atlas_page_read(float page, vec2 xy) {
  vec4 texel;
  if (ATLAS_PAGES > 2 && page == 2.0) {
    texel = ATLAS_READ(u_atlas_page2, xy);
  } else if (ATLAS_PAGES > 1 && page == 1.0) {
    texel = ATLAS_READ(u_atlas_page1, xy);
  } else {
    texel = ATLAS_READ(u_atlas_page0, xy);
  }
  return texel;
}

#ifdef ATLAS_FILTERED
// Linear RGB filtered by the sampler at xy, normalised page coordinates.
vec3 atlas_filtered(float page, vec2 xy) {
  return atlas_page_read(page, xy).rgb;
}
// Under --colour 16: one texel of an RGBA8 page at integer coordinates, decoded here.
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
#else
vec3 atlas_texel_linear(float page, float x, float y) {
  return atlas_srgb_to_linear(atlas_page_read(page, vec2(x, y)).rgb);
}
#endif

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
  vec2 w = vec2(atlas_wrap_coord(uv.x, wrap.x), atlas_wrap_coord(uv.y, wrap.y));
#ifdef ATLAS_FILTERED
  if (COLOUR == MOBIRT_COLOUR_8) return atlas_filtered(wrap.z, (tile.xy + w * tile.zw) * (1.0 / float(MOBIRT_ATLAS_SIZE)));
#endif
  // Texels floor(p) and floor(p) + 1 lie in [-1, size]: the tile or its gutter.
  vec2 p = w * tile.zw - 0.5;
  vec2 p0 = floor(p);
  vec2 f = p - p0;
  vec2 xy0 = tile.xy + p0;
  vec2 xy1 = xy0 + 1.0;
  vec3 top = mix(atlas_texel_linear(wrap.z, xy0.x, xy0.y), atlas_texel_linear(wrap.z, xy1.x, xy0.y), f.x);
  vec3 bottom = mix(atlas_texel_linear(wrap.z, xy0.x, xy1.y), atlas_texel_linear(wrap.z, xy1.x, xy1.y), f.x);
  return mix(top, bottom, f.y);
}
