#include "accel/kdtree_clip.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace mobirt::kdclip {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// The neighbours of a finite float towards -inf and +inf (std::nextafter without the libm call).
float next_down(float f) {
  if (f == 0.0f) return -std::numeric_limits<float>::denorm_min();
  const uint32_t bits = std::bit_cast<uint32_t>(f);
  return std::bit_cast<float>(f > 0.0f ? bits - 1 : bits + 1);
}
float next_up(float f) { return -next_down(-f); }

float round_down(double x) {
  const float f = static_cast<float>(x);
  return static_cast<double>(f) > x ? next_down(f) : f;
}

float round_up(double x) {
  const float f = static_cast<float>(x);
  return static_cast<double>(f) < x ? next_up(f) : f;
}

// The bounds of the parts of the convex polygon poly[0..n) below (<= split) and above (>= split)
// the plane x[axis] = split: the vertices on each side and the edge crossings (on both), rounded
// outwards to float. Returns bit 1 when the below part is not empty, bit 2 for above.
int split_polygon(const double (*poly)[3], int n, int axis, float split, Box& below, Box& above) {
  const double s = split;
  double lo[2][3];
  double hi[2][3];
  for (int k = 0; k < 2; ++k) {
    for (int a = 0; a < 3; ++a) {
      lo[k][a] = kInf;
      hi[k][a] = -kInf;
    }
  }
  const auto extend = [&](int k, const double* p) {
    for (int a = 0; a < 3; ++a) {
      lo[k][a] = std::min(lo[k][a], p[a]);
      hi[k][a] = std::max(hi[k][a], p[a]);
    }
  };
  for (int i = 0; i < n; ++i) {
    const double* p = poly[i];
    const double* q = poly[i + 1 == n ? 0 : i + 1];
    const double dp = p[axis] - s;
    const double dq = q[axis] - s;
    if (dp <= 0.0) extend(0, p);
    if (dp >= 0.0) extend(1, p);
    if ((dp < 0.0 && dq > 0.0) || (dp > 0.0 && dq < 0.0)) {
      const double t = dp / (dp - dq);
      double x[3];
      for (int a = 0; a < 3; ++a) x[a] = p[a] + t * (q[a] - p[a]);
      x[axis] = s;
      extend(0, x);
      extend(1, x);
    }
  }
  int result = 0;
  Box* out[2] = {&below, &above};
  for (int k = 0; k < 2; ++k) {
    if (!(lo[k][0] <= hi[k][0])) continue;
    result |= 1 << k;
    for (int a = 0; a < 3; ++a) {
      out[k]->lo[a] = round_down(lo[k][a]);
      out[k]->hi[a] = round_up(hi[k][a]);
    }
  }
  return result;
}

}  // namespace

namespace {

#if defined(__SSE2__)
// A vertex in lanes x, y, z (w = 0) without reading past its 12 bytes (the last vertex of the
// positions array may end the allocation). x and y by _mm_loadl_epi64, whose 8-byte read has no
// alignment requirement (a `double` load from a float's address is misaligned: UBSan stops there).
__m128 load_vertex(const glm::vec3& p) {
  const __m128 xy = _mm_castsi128_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(&p.x)));
  return _mm_movelh_ps(xy, _mm_load_ss(&p.z));
}

// next_down (above) on the lanes of f that mask selects: the neighbour towards -inf.
__m128 next_down_where(__m128 f, __m128 mask) {
  const __m128i bits = _mm_castps_si128(f);
  const __m128i sign = _mm_srai_epi32(bits, 31);  // 0 or -1
  // Positive: bits - 1; negative and -0: bits + 1 (-0 becomes -denorm_min); +0 would become a
  // NaN and is set to -denorm_min apart.
  __m128i down = _mm_sub_epi32(_mm_sub_epi32(bits, _mm_set1_epi32(1)), _mm_add_epi32(sign, sign));
  const __m128i plus_zero = _mm_cmpeq_epi32(bits, _mm_setzero_si128());
  down = _mm_or_si128(_mm_andnot_si128(plus_zero, down),
                      _mm_and_si128(plus_zero, _mm_set1_epi32(static_cast<int32_t>(0x80000001u))));
  return _mm_or_ps(_mm_andnot_ps(mask, f), _mm_and_ps(mask, _mm_castsi128_ps(down)));
}

// The lanes of a double comparison (two 64-bit masks in each of lo, hi) as four 32-bit masks.
__m128 narrow_masks(__m128d lo, __m128d hi) {
  return _mm_shuffle_ps(_mm_castpd_ps(lo), _mm_castpd_ps(hi), _MM_SHUFFLE(2, 0, 2, 0));
}

#endif

// The bounds of the triangle's parts on each side of the plane: its vertices on each side, and
// the two edge crossings on both, whose bounds crossing(a, b, lo, hi) gives on the axes other than
// the plane's (the crossing's coordinate on that axis is the plane itself). An edge crosses when
// its ends lie strictly on either side (the float comparisons say what the exact differences do).
template <class Crossing>
int split_triangle_with(const glm::vec3* v, int split_axis, float split, Box& below, Box& above, Crossing crossing) {
  float p[3][3];
  for (int i = 0; i < 3; ++i) {
    p[i][0] = v[i].x;
    p[i][1] = v[i].y;
    p[i][2] = v[i].z;
  }
  constexpr float kInfF = std::numeric_limits<float>::infinity();
  Box* out[2] = {&below, &above};
  for (Box* b : out) {
    for (int a = 0; a < 3; ++a) {
      b->lo[a] = kInfF;
      b->hi[a] = -kInfF;
    }
  }
  const auto extend = [&](Box& b, const float* x) {
    for (int a = 0; a < 3; ++a) {
      b.lo[a] = std::min(b.lo[a], x[a]);
      b.hi[a] = std::max(b.hi[a], x[a]);
    }
  };
  for (int i = 0; i < 3; ++i) {
    const float* a = p[i];
    const float* b = p[i == 2 ? 0 : i + 1];
    if (a[split_axis] <= split) extend(below, a);
    if (a[split_axis] >= split) extend(above, a);
    if ((a[split_axis] < split && b[split_axis] > split) || (a[split_axis] > split && b[split_axis] < split)) {
      float lo[3];
      float hi[3];
      crossing(a, b, lo, hi);
      lo[split_axis] = split;
      hi[split_axis] = split;
      for (Box* side : out) {
        for (int k = 0; k < 3; ++k) {
          side->lo[k] = std::min(side->lo[k], lo[k]);
          side->hi[k] = std::max(side->hi[k], hi[k]);
        }
      }
    }
  }
  return (below.lo[0] <= below.hi[0] ? 1 : 0) | (above.lo[0] <= above.hi[0] ? 2 : 0);
}

#if defined(__SSE2__)
// split_triangle_with, the three coordinates of a point in the lanes of one register: crossing(i,
// j) gives the (lo, hi) lanes of edge (v[i], v[j])'s crossing. min and max take their operands in
// std::min's and std::max's order, so even the signs of zeros are the same.
template <class Crossing>
int split_triangle_lanes(const glm::vec3* v, int split_axis, float split, Box& below, Box& above, Crossing crossing) {
  const __m128 p[3] = {load_vertex(v[0]), load_vertex(v[1]), load_vertex(v[2])};
  const float c[3] = {v[0][split_axis], v[1][split_axis], v[2][split_axis]};
  const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
  const __m128 minus_inf = _mm_set1_ps(-std::numeric_limits<float>::infinity());
  __m128 below_lo = inf, below_hi = minus_inf, above_lo = inf, above_hi = minus_inf;
  alignas(16) int32_t axis_lane[4] = {0, 0, 0, 0};
  axis_lane[split_axis] = -1;
  const __m128 on_axis = _mm_load_ps(reinterpret_cast<const float*>(axis_lane));
  const __m128 plane = _mm_set1_ps(split);
  for (int i = 0; i < 3; ++i) {
    const int j = i == 2 ? 0 : i + 1;
    if (c[i] <= split) {
      below_lo = _mm_min_ps(p[i], below_lo);
      below_hi = _mm_max_ps(p[i], below_hi);
    }
    if (c[i] >= split) {
      above_lo = _mm_min_ps(p[i], above_lo);
      above_hi = _mm_max_ps(p[i], above_hi);
    }
    if ((c[i] < split && c[j] > split) || (c[i] > split && c[j] < split)) {
      auto [lo, hi] = crossing(p[i], p[j], c[i], c[j]);
      // The crossing's coordinate on the split axis is the plane itself.
      lo = _mm_or_ps(_mm_andnot_ps(on_axis, lo), _mm_and_ps(on_axis, plane));
      hi = _mm_or_ps(_mm_andnot_ps(on_axis, hi), _mm_and_ps(on_axis, plane));
      below_lo = _mm_min_ps(lo, below_lo);
      below_hi = _mm_max_ps(hi, below_hi);
      above_lo = _mm_min_ps(lo, above_lo);
      above_hi = _mm_max_ps(hi, above_hi);
    }
  }
  alignas(16) float out[4][4];
  _mm_store_ps(out[0], below_lo);
  _mm_store_ps(out[1], below_hi);
  _mm_store_ps(out[2], above_lo);
  _mm_store_ps(out[3], above_hi);
  for (int a = 0; a < 3; ++a) {
    below.lo[a] = out[0][a];
    below.hi[a] = out[1][a];
    above.lo[a] = out[2][a];
    above.hi[a] = out[3][a];
  }
  return (below.lo[0] <= below.hi[0] ? 1 : 0) | (above.lo[0] <= above.hi[0] ? 2 : 0);
}
#endif

// The crossing of edge (a, b) with a plane, computed in float: t = da / (da - db) from the
// split-axis differences (da and db of opposite signs, so no cancellation: t within about 4 units
// of 2^-24 of itself, t in [0, 1]), then x = a_k + t (b_k - a_k) on axis k, within about 13 units
// of 2^-24 of m = max(|a_k|, |b_k|) of the exact point (|t (b_k - a_k)| <= 2 m, |x| <= m).
// kCrossingPad pads it by 32 such units, kCrossingFloor covers underflow, so that [x - pad, x + pad]
// holds the exact point. Coordinates of 2^126 or more could overflow a difference: such a triangle
// takes the exact split (kCrossingLimit). Padding a float crossing costs a few ulps of looseness
// where the exact one in double cost its conversions and rounding (13 % of a toaster build,
// session 42).
constexpr float kCrossingPad = 0x1p-19f;
constexpr float kCrossingFloor = std::numeric_limits<float>::min();
constexpr float kCrossingLimit = 0x1p126f;

}  // namespace

// split_polygon on the triangle itself, with the same result: its vertices are floats already
// (no rounding), only the two edge crossings are computed in double and rounded outwards (round
// down and up are monotone, so rounding each point equals rounding the bounds).
int split_triangle_exact_scalar(const glm::vec3* v, int split_axis, float split, Box& below, Box& above) {
  const double s = split;
  return split_triangle_with(v, split_axis, split, below, above, [&](const float* a, const float* b, float* lo, float* hi) {
    const double da = double(a[split_axis]) - s;
    const double db = double(b[split_axis]) - s;
    const double t = da / (da - db);
    for (int k = 0; k < 3; ++k) {
      const double x = double(a[k]) + t * (double(b[k]) - double(a[k]));
      lo[k] = round_down(x);
      hi[k] = round_up(x);
    }
  });
}

// split_triangle_exact_scalar in lanes: the two crossings computed in double as there (the same
// operations, no FMA), rounded to nearest float and moved one ulp outwards where that rounding
// went inwards (round_down, round_up).
int split_triangle_exact(const glm::vec3* v, int split_axis, float split, Box& below, Box& above) {
#if defined(__SSE2__)
  const double s = split;
  return split_triangle_lanes(v, split_axis, split, below, above, [&](__m128 pi, __m128 pj, float ci, float cj) {
    const double da = double(ci) - s;
    const double db = double(cj) - s;
    const __m128d t = _mm_set1_pd(da / (da - db));
    const __m128d a01 = _mm_cvtps_pd(pi);
    const __m128d a23 = _mm_cvtps_pd(_mm_movehl_ps(pi, pi));
    const __m128d b01 = _mm_cvtps_pd(pj);
    const __m128d b23 = _mm_cvtps_pd(_mm_movehl_ps(pj, pj));
    const __m128d x01 = _mm_add_pd(a01, _mm_mul_pd(t, _mm_sub_pd(b01, a01)));
    const __m128d x23 = _mm_add_pd(a23, _mm_mul_pd(t, _mm_sub_pd(b23, a23)));
    const __m128 f = _mm_movelh_ps(_mm_cvtpd_ps(x01), _mm_cvtpd_ps(x23));
    const __m128d f01 = _mm_cvtps_pd(f);
    const __m128d f23 = _mm_cvtps_pd(_mm_movehl_ps(f, f));
    const __m128 lo = next_down_where(f, narrow_masks(_mm_cmpgt_pd(f01, x01), _mm_cmpgt_pd(f23, x23)));
    // round_up(x) = next_up where the float is below: -next_down(-f).
    const __m128 sign = _mm_set1_ps(-0.0f);
    const __m128 hi = _mm_xor_ps(
        next_down_where(_mm_xor_ps(f, sign), narrow_masks(_mm_cmplt_pd(f01, x01), _mm_cmplt_pd(f23, x23))), sign);
    return std::pair{lo, hi};
  });
#else
  return split_triangle_exact_scalar(v, split_axis, split, below, above);
#endif
}

// The fast build's split: the crossings in float, padded outwards (kCrossingPad). Conservative:
// the bounds hold split_triangle_exact's (KdClip tests). A triangle with a coordinate of
// kCrossingLimit or more takes the exact split.
int split_triangle_scalar(const glm::vec3* v, int split_axis, float split, Box& below, Box& above) {
  for (int i = 0; i < 3; ++i) {
    for (int k = 0; k < 3; ++k) {
      if (!(std::fabs(v[i][k]) < kCrossingLimit)) return split_triangle_exact_scalar(v, split_axis, split, below, above);
    }
  }
  return split_triangle_with(v, split_axis, split, below, above, [&](const float* a, const float* b, float* lo, float* hi) {
    const float da = a[split_axis] - split;
    const float db = b[split_axis] - split;
    const float t = da / (da - db);
    for (int k = 0; k < 3; ++k) {
      const float x = a[k] + t * (b[k] - a[k]);
      const float pad = std::max(std::fabs(a[k]), std::fabs(b[k])) * kCrossingPad + kCrossingFloor;
      lo[k] = x - pad;
      hi[k] = x + pad;
    }
  });
}

// split_triangle_scalar in lanes, the same operations in the same order (no FMA).
int split_triangle(const glm::vec3* v, int split_axis, float split, Box& below, Box& above) {
#if defined(__SSE2__)
  const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  const __m128 largest = _mm_max_ps(_mm_max_ps(_mm_and_ps(load_vertex(v[0]), abs_mask), _mm_and_ps(load_vertex(v[1]), abs_mask)),
                                    _mm_and_ps(load_vertex(v[2]), abs_mask));
  if (_mm_movemask_ps(_mm_cmplt_ps(largest, _mm_set1_ps(kCrossingLimit))) != 0xF) {  // lane w is 0
    return split_triangle_exact(v, split_axis, split, below, above);
  }
  return split_triangle_lanes(v, split_axis, split, below, above, [&](__m128 pi, __m128 pj, float ci, float cj) {
    const float da = ci - split;
    const float db = cj - split;
    const __m128 t = _mm_set1_ps(da / (da - db));
    const __m128 x = _mm_add_ps(pi, _mm_mul_ps(t, _mm_sub_ps(pj, pi)));
    const __m128 m = _mm_max_ps(_mm_and_ps(pi, abs_mask), _mm_and_ps(pj, abs_mask));
    const __m128 pad = _mm_add_ps(_mm_mul_ps(m, _mm_set1_ps(kCrossingPad)), _mm_set1_ps(kCrossingFloor));
    return std::pair{_mm_sub_ps(x, pad), _mm_add_ps(x, pad)};
  });
#else
  return split_triangle_scalar(v, split_axis, split, below, above);
#endif
}

int clip_and_split(const glm::vec3* v, const Box& box, int split_axis, float split, Box& below, Box& above) {
  constexpr int kMax = 16;  // 3 vertices + at most one per clipping plane
  double poly_a[kMax][3];
  double poly_b[kMax][3];
  double(*poly)[3] = poly_a;
  double(*next)[3] = poly_b;
  float tri_lo[3];
  float tri_hi[3];
  for (int i = 0; i < 3; ++i) {
    poly[i][0] = v[i].x;
    poly[i][1] = v[i].y;
    poly[i][2] = v[i].z;
  }
  for (int a = 0; a < 3; ++a) {
    tri_lo[a] = static_cast<float>(std::min(poly[0][a], std::min(poly[1][a], poly[2][a])));
    tri_hi[a] = static_cast<float>(std::max(poly[0][a], std::max(poly[1][a], poly[2][a])));
  }
  // Only the faces of the box the triangle crosses can cut it; for the others every polygon
  // vertex (on the triangle) is inside and clipping would keep the polygon as it is. Most
  // references not clipped before lie inside the box: their triangle is split directly.
  bool crossed[3][2];
  bool inside = true;
  for (int a = 0; a < 3; ++a) {
    crossed[a][0] = tri_lo[a] < box.lo[a];
    crossed[a][1] = tri_hi[a] > box.hi[a];
    inside = inside && !crossed[a][0] && !crossed[a][1];
  }
  if (inside) return split_triangle_exact(v, split_axis, split, below, above);
  int n = 3;
  for (int axis = 0; axis < 3; ++axis) {
    for (int side = 0; side < 2; ++side) {
      if (!crossed[axis][side]) continue;
      const double plane = side == 0 ? box.lo[axis] : box.hi[axis];
      const double sign = side == 0 ? 1.0 : -1.0;  // inside: sign * (x - plane) >= 0
      int m = 0;
      for (int i = 0; i < n; ++i) {
        const double* p = poly[i];
        const double* q = poly[i + 1 == n ? 0 : i + 1];
        const double dp = sign * (p[axis] - plane);
        const double dq = sign * (q[axis] - plane);
        if (dp >= 0.0) {
          std::copy(p, p + 3, next[m]);
          ++m;
        }
        if ((dp >= 0.0) != (dq >= 0.0)) {
          const double t = dp / (dp - dq);
          for (int a = 0; a < 3; ++a) next[m][a] = p[a] + t * (q[a] - p[a]);
          next[m][axis] = plane;  // exactly on the plane
          ++m;
        }
      }
      std::swap(poly, next);
      n = m;
      if (n == 0) return 0;
    }
  }
  return split_polygon(poly, n, split_axis, split, below, above);
}

}  // namespace mobirt::kdclip
