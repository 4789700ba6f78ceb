// Eight floats to a register (AVX2) for the ray tree's per-hit CPU stages: hit decoding
// (hits.cpp) and the next generation (secondary.cpp). The arithmetic helpers are glm's operations
// on eight lanes, in glm's order (std_max is std::max's; load_rows, Offsets, lanes_to_vec4 and
// transpose8 move data), so that a lane gives the scalar code's floats bit for bit: these
// functions are target("avx2") alone and their callers compile with -ffp-contract=off
// (CMakeLists.txt), so no product is fused into a sum on either side; additions,
// multiplications, divisions and square roots round the same in both. The callers choose these
// paths at run time (__builtin_cpu_supports("avx2")).
#pragma once

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define MOBIRT_SIMD8 1
#include <immintrin.h>

#include <cstdint>

namespace mobirt::simd8 {

constexpr int kLanes = 8;

struct V3 {
  __m256 x, y, z;
};

// Four consecutive floats from base + offset[k] for each lane k, transposed: row r holds float r
// of every lane. Loads and shuffles, not vgatherdps: AMD's gathers cost more than the arithmetic.
struct Rows {
  __m256 r[4];
  __attribute__((target("avx2"))) V3 xyz(int first) const { return {r[first], r[first + 1], r[first + 2]}; }
};
__attribute__((target("avx2"))) inline __m256 lane_pair(const float* base, const uint32_t* offset, int k) {
  return _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(base + offset[k])), _mm_loadu_ps(base + offset[k + 4]),
                              1);
}
__attribute__((target("avx2"))) inline Rows load_rows(const float* base, const uint32_t* offset) {
  const __m256 t0 = lane_pair(base, offset, 0), t1 = lane_pair(base, offset, 1);
  const __m256 t2 = lane_pair(base, offset, 2), t3 = lane_pair(base, offset, 3);
  const __m256 u0 = _mm256_unpacklo_ps(t0, t1), u1 = _mm256_unpackhi_ps(t0, t1);
  const __m256 u2 = _mm256_unpacklo_ps(t2, t3), u3 = _mm256_unpackhi_ps(t2, t3);
  return {{_mm256_shuffle_ps(u0, u2, 0x44), _mm256_shuffle_ps(u0, u2, 0xEE), _mm256_shuffle_ps(u1, u3, 0x44),
           _mm256_shuffle_ps(u1, u3, 0xEE)}};
}
// The lanes' offsets of one field: scale x index[k] + add, in floats.
struct Offsets {
  uint32_t at[kLanes];
  Offsets(const uint32_t* index, uint32_t scale, uint32_t add) {
    for (int k = 0; k < kLanes; ++k) at[k] = index[k] * scale + add;
  }
};
__attribute__((target("avx2"))) inline V3 sub(const V3& a, const V3& b) {
  return {_mm256_sub_ps(a.x, b.x), _mm256_sub_ps(a.y, b.y), _mm256_sub_ps(a.z, b.z)};
}
__attribute__((target("avx2"))) inline V3 add(const V3& a, const V3& b) {
  return {_mm256_add_ps(a.x, b.x), _mm256_add_ps(a.y, b.y), _mm256_add_ps(a.z, b.z)};
}
__attribute__((target("avx2"))) inline V3 scale(__m256 s, const V3& a) {
  return {_mm256_mul_ps(s, a.x), _mm256_mul_ps(s, a.y), _mm256_mul_ps(s, a.z)};
}
__attribute__((target("avx2"))) inline V3 divide(const V3& a, __m256 s) {
  return {_mm256_div_ps(a.x, s), _mm256_div_ps(a.y, s), _mm256_div_ps(a.z, s)};
}
// glm::dot: (x + y) + z of the products.
__attribute__((target("avx2"))) inline __m256 dot(const V3& a, const V3& b) {
  return _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(a.x, b.x), _mm256_mul_ps(a.y, b.y)), _mm256_mul_ps(a.z, b.z));
}
// glm::cross, its products in glm's order.
__attribute__((target("avx2"))) inline V3 cross(const V3& a, const V3& b) {
  return {_mm256_sub_ps(_mm256_mul_ps(a.y, b.z), _mm256_mul_ps(b.y, a.z)),
          _mm256_sub_ps(_mm256_mul_ps(a.z, b.x), _mm256_mul_ps(b.z, a.x)),
          _mm256_sub_ps(_mm256_mul_ps(a.x, b.y), _mm256_mul_ps(b.x, a.y))};
}
__attribute__((target("avx2"))) inline __m256 negate(__m256 a) { return _mm256_xor_ps(a, _mm256_set1_ps(-0.0f)); }
__attribute__((target("avx2"))) inline V3 negate_where(const V3& a, __m256 where) {
  const __m256 sign = _mm256_and_ps(where, _mm256_set1_ps(-0.0f));
  return {_mm256_xor_ps(a.x, sign), _mm256_xor_ps(a.y, sign), _mm256_xor_ps(a.z, sign)};
}
__attribute__((target("avx2"))) inline V3 select(__m256 where, const V3& a, const V3& b) {
  return {_mm256_blendv_ps(b.x, a.x, where), _mm256_blendv_ps(b.y, a.y, where), _mm256_blendv_ps(b.z, a.z, where)};
}

// std::max(a, b) lane by lane: b where a < b, else a (NaN keeps a, as std::max does).
__attribute__((target("avx2"))) inline __m256 std_max(__m256 a, __m256 b) {
  return _mm256_blendv_ps(a, b, _mm256_cmp_ps(a, b, _CMP_LT_OQ));
}

// (v.x, v.y, v.z, w) of each lane k as four floats at out + 4 k: eight vec4 (or texels of four
// floats) in a row.
__attribute__((target("avx2"))) inline void lanes_to_vec4(const V3& v, __m256 w, float* out) {
  const __m256 t0 = _mm256_unpacklo_ps(v.x, v.y), t1 = _mm256_unpackhi_ps(v.x, v.y);
  const __m256 t2 = _mm256_unpacklo_ps(v.z, w), t3 = _mm256_unpackhi_ps(v.z, w);
  const __m256 r[4] = {_mm256_shuffle_ps(t0, t2, 0x44), _mm256_shuffle_ps(t0, t2, 0xEE),
                       _mm256_shuffle_ps(t1, t3, 0x44), _mm256_shuffle_ps(t1, t3, 0xEE)};
  for (int k = 0; k < 4; ++k) {
    _mm_storeu_ps(out + 4 * k, _mm256_castps256_ps128(r[k]));
    _mm_storeu_ps(out + 4 * (k + 4), _mm256_extractf128_ps(r[k], 1));
  }
}

// Eight registers of eight lanes to eight registers of one lane each: out[k] holds lane k of
// in[0], ..., in[7], in that order (eight floats of one record, stored with one instruction).
__attribute__((target("avx2"))) inline void transpose8(const __m256 in[8], __m256 out[8]) {
  const __m256 t0 = _mm256_unpacklo_ps(in[0], in[1]), t1 = _mm256_unpackhi_ps(in[0], in[1]);
  const __m256 t2 = _mm256_unpacklo_ps(in[2], in[3]), t3 = _mm256_unpackhi_ps(in[2], in[3]);
  const __m256 t4 = _mm256_unpacklo_ps(in[4], in[5]), t5 = _mm256_unpackhi_ps(in[4], in[5]);
  const __m256 t6 = _mm256_unpacklo_ps(in[6], in[7]), t7 = _mm256_unpackhi_ps(in[6], in[7]);
  // s_j: lanes j and j + 4 of in[0..3] (low half) and in[4..7] (the s_{j+4}).
  const __m256 s0 = _mm256_shuffle_ps(t0, t2, 0x44), s1 = _mm256_shuffle_ps(t0, t2, 0xEE);
  const __m256 s2 = _mm256_shuffle_ps(t1, t3, 0x44), s3 = _mm256_shuffle_ps(t1, t3, 0xEE);
  const __m256 s4 = _mm256_shuffle_ps(t4, t6, 0x44), s5 = _mm256_shuffle_ps(t4, t6, 0xEE);
  const __m256 s6 = _mm256_shuffle_ps(t5, t7, 0x44), s7 = _mm256_shuffle_ps(t5, t7, 0xEE);
  out[0] = _mm256_permute2f128_ps(s0, s4, 0x20);
  out[1] = _mm256_permute2f128_ps(s1, s5, 0x20);
  out[2] = _mm256_permute2f128_ps(s2, s6, 0x20);
  out[3] = _mm256_permute2f128_ps(s3, s7, 0x20);
  out[4] = _mm256_permute2f128_ps(s0, s4, 0x31);
  out[5] = _mm256_permute2f128_ps(s1, s5, 0x31);
  out[6] = _mm256_permute2f128_ps(s2, s6, 0x31);
  out[7] = _mm256_permute2f128_ps(s3, s7, 0x31);
}

}  // namespace mobirt::simd8

#endif
