// Packing of the traversal output into one RGBA8 texel by float arithmetic (GLSL ES 1.00 has no
// bit operations). Unpacked on the CPU by src/raytree/packing.h. Values v in 0..255 are written as
// v / 255, which the UNORM conversion rounds back to exactly v.

// prim_plus_one: 0 = miss, else primitive index + 1; mask: shadow bits as a float integer.
vec4 pack_trace(float prim_plus_one, float mask) {
  if (PACKING == MOBIRT_PACKING_24_8) {
    float lo = mod(prim_plus_one, 256.0);
    float mid = mod(floor(prim_plus_one / 256.0), 256.0);
    float hi = floor(prim_plus_one / 65536.0);
    return vec4(lo, mid, hi, mask) / 255.0;
  }
  float lo16 = mod(prim_plus_one, 256.0);
  float hi16 = floor(prim_plus_one / 256.0);
  return vec4(lo16, hi16, mod(mask, 256.0), floor(mask / 256.0)) / 255.0;
}

// "The loop cap stopped this ray": index 0 with every mask bit set. A miss never has shadow bits.
vec4 pack_capped() {
  return PACKING == MOBIRT_PACKING_24_8 ? vec4(0.0, 0.0, 0.0, 1.0) : vec4(0.0, 0.0, 1.0, 1.0);
}
