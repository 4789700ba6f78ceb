#include "accel/kdtree_clip.h"

#include <algorithm>
#include <bit>
#include <cstdint>
#include <limits>
#include <utility>

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

// split_polygon on the triangle itself, with the same result: its vertices are floats already
// (no rounding), only the two edge crossings are computed in double and rounded outwards (round
// down and up are monotone, so rounding each point equals rounding the bounds), and the crossing's
// coordinate on the split axis is the plane itself.
int split_triangle(const glm::vec3* v, int split_axis, float split, Box& below, Box& above) {
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
  const double s = split;
  for (int i = 0; i < 3; ++i) {
    const float* a = p[i];
    const float* b = p[i == 2 ? 0 : i + 1];
    if (a[split_axis] <= split) extend(below, a);
    if (a[split_axis] >= split) extend(above, a);
    const double da = double(a[split_axis]) - s;
    const double db = double(b[split_axis]) - s;
    if ((da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0)) {
      const double t = da / (da - db);
      for (int k = 0; k < 3; ++k) {
        float lo = split;
        float hi = split;
        if (k != split_axis) {
          const double x = double(a[k]) + t * (double(b[k]) - double(a[k]));
          lo = round_down(x);
          hi = round_up(x);
        }
        for (Box* side : out) {
          side->lo[k] = std::min(side->lo[k], lo);
          side->hi[k] = std::max(side->hi[k], hi);
        }
      }
    }
  }
  return (below.lo[0] <= below.hi[0] ? 1 : 0) | (above.lo[0] <= above.hi[0] ? 2 : 0);
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
  if (inside) return split_triangle(v, split_axis, split, below, above);
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
