// The shading pass's output texel (glsl/layout.h, MOBIRT_COLOUR_*; decoded on the CPU by
// decode_colour() in src/raytree/packing.h). COLOUR is a specialization constant.
// 8 bits: the colour itself (the UNORM conversion rounds it to 8 bits). 16 bits: v = round(c x
// 65535) per channel, split into high and low bytes by two passes with the same shading; bytes b
// are written as b / 255, which the conversion returns exactly. c must lie in [0, 1].
vec4 encode_colour(vec3 c) {
  if (COLOUR == MOBIRT_COLOUR_8) return vec4(c, 1.0);
  vec3 v = floor(c * 65535.0 + 0.5);
  vec3 high = floor(v / 256.0);
  return vec4((COLOUR == MOBIRT_COLOUR_16_HIGH ? high : v - 256.0 * high) / 255.0, 1.0);
}
