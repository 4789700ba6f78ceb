// Self-intersection offset of the shadow rays' origins, by OFFSET_MODE (glsl/layout.h,
// MOBIRT_OFFSET_*, a specialization constant). The CPU mirror, operation for operation, is
// offset_origin() in src/raytree/hits.cpp, which also offsets the mirror and refracted rays.
//
// What GLSL ES 1.00 can express: Wachter and Binder move the point by an integer added to its
// float's bits, and ES 1.00 has neither floatBitsToInt nor integer arithmetic on bits. For the
// components where the method uses it (|p| >= 1/32, normal floats) the same move is a step of k
// ulps inside the binade of p, carried into the binade above (ulps twice as large) or below (half
// as large) when it crosses a power of two; prelude_es.glsl's add_float_bits() does that with
// exp2/log2 and exact float arithmetic and gives the same bits (tested on both backends).
#ifndef MOBIRT_OFFSET_GLSL
#define MOBIRT_OFFSET_GLSL

// Wachter and Binder 2019 (Ray Tracing Gems, ch. 6, "A Fast and Robust Method for Avoiding
// Self-Intersection"): int(256 n) ulps per component, or n / 65536 within 1/32 of the origin.
float offset_normal_ulp(float p, float n) {
  float s = MOBIRT_WB_INT_SCALE * n;
  float ulps = sign(s) * floor(abs(s));  // truncated towards zero, as int() does
  if (abs(p) < MOBIRT_WB_ORIGIN) return p + MOBIRT_WB_FLOAT_SCALE * n;
  return add_float_bits(p, p < 0.0 ? -ulps : ulps);
}

// The hit point of the ray (o, d) on the triangle (v0, v0 + e1, v0 + e2), from its barycentric
// coordinates, as Wachter and Binder compute it: its error is then relative to the vertices, and
// small enough for an offset of a few hundred ulps, where o + t d carries an error relative to the
// ray's length (a floor at y = 0 seen from 1,000 units gets p.y wrong by 1e-4).
vec3 point_on_triangle(vec3 v0, vec3 e1, vec3 e2, vec3 o, vec3 d) {
  vec3 p = cross(d, e2);
  float inv_det = 1.0 / dot(e1, p);
  vec3 s = o - v0;
  float u = dot(s, p) * inv_det;
  float v = dot(d, cross(s, e1)) * inv_det;
  return v0 + u * e1 + v * e2;
}

// The origin of a ray leaving the surface at p on the side of the unit normal n. absolute: the
// uniform (epsilon, or epsilon x the scene's size; unused by NORMAL_ULP).
vec3 offset_origin(vec3 p, vec3 n, float absolute) {
  if (OFFSET_MODE == MOBIRT_OFFSET_NORMAL_ULP) {
    return vec3(offset_normal_ulp(p.x, n.x), offset_normal_ulp(p.y, n.y), offset_normal_ulp(p.z, n.z));
  }
  float offset = absolute;
  if (OFFSET_MODE == MOBIRT_OFFSET_SCALED) {
    // Never below 2 ulps of the point, in the precision the pass computes in.
    vec3 ap = abs(p);
    float ulps = PRECISION == MOBIRT_PRECISION_MEDIUM ? MOBIRT_OFFSET_HALF_ULPS : MOBIRT_OFFSET_ULPS;
    offset = max(offset, max(ap.x, max(ap.y, ap.z)) * ulps);
  }
  return p + offset * n;
}

#endif  // MOBIRT_OFFSET_GLSL
