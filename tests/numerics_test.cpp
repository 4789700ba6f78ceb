// The numeric primitives behind --precision mediump and --offset normal-ulp, and the traversal
// pass's output packing at the primitive limits: on the CPU against known answers, and in the
// shaders of both backends (glsl/numerics_test_main.glsl) against the CPU, bit for bit. GLSL ES
// 1.00 has no packHalf2x16 or floatBitsToInt, so the GLES path emulates both arithmetically
// (glsl/prelude_es.glsl); these tests are what shows the emulation gives the same bits.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "accel/light_buffer.h"
#include "backend/backend.h"
#include "layout.h"
#include "core/half.h"
#include "raytree/hits.h"
#include "raytree/packing.h"
#include "test_support.h"
#include "vulkan_fixture.h"
#include "test_shader_ids.h"  // the test-only shaders (TestShader)

namespace mobirt {
namespace {

float bits_to_float(uint32_t bits) { return std::bit_cast<float>(bits); }

TEST(Numerics, RoundToHalfKnownAnswers) {
  const float inf = std::numeric_limits<float>::infinity();
  EXPECT_EQ(round_to_half(1.0f), 1.0f);
  EXPECT_EQ(round_to_half(-2.5f), -2.5f);
  EXPECT_EQ(round_to_half(1.0f + 0x1p-11f), 1.0f);                  // a tie goes to even
  EXPECT_EQ(round_to_half(1.0f + 3 * 0x1p-11f), 1.0f + 0x1p-9f);    // ... up to even
  EXPECT_EQ(round_to_half(1.0f + 0x1p-11f + 0x1p-20f), 1.0f + 0x1p-10f);
  EXPECT_EQ(round_to_half(2047.5f), 2048.0f);
  EXPECT_EQ(round_to_half(0.1f), 0.0999755859375f);
  EXPECT_EQ(round_to_half(65504.0f), 65504.0f);
  EXPECT_EQ(round_to_half(65519.99f), 65504.0f);
  EXPECT_EQ(round_to_half(65520.0f), inf);
  EXPECT_EQ(round_to_half(-1e9f), -inf);
  EXPECT_EQ(round_to_half(0x1p-14f), 0x1p-14f);                     // the smallest normal
  EXPECT_EQ(round_to_half(0x1p-24f), 0x1p-24f);                     // the smallest subnormal
  EXPECT_EQ(round_to_half(0x1p-25f), 0.0f);                         // a tie, to even (zero)
  EXPECT_EQ(round_to_half(0x1.8p-25f), 0x1p-24f);
  EXPECT_EQ(round_to_half(3 * 0x1p-25f), 2 * 0x1p-24f);             // 1.5 subnormal steps: even
  EXPECT_EQ(round_to_half(inf), inf);
  EXPECT_TRUE(std::isnan(round_to_half(std::numeric_limits<float>::quiet_NaN())));
#ifdef __FLT16_MAX__
  // Against the compiler's own conversion (ties to even) on every 2^16th float bit pattern.
  for (uint64_t bits = 0; bits < 0x7F800000u; bits += 0x10000u + 7u) {
    const float x = bits_to_float(uint32_t(bits));
    EXPECT_EQ(round_to_half(x), float(static_cast<_Float16>(x))) << x;
    EXPECT_EQ(round_to_half(-x), float(static_cast<_Float16>(-x))) << -x;
  }
#endif
}

TEST(Numerics, NormalUlpOffsetKnownAnswers) {
  // Away from the origin: 256 x n ulps, in the direction of n, across powers of two.
  const glm::vec3 p = offset_normal_ulp({1.0f, -1.0f, 1000.0f}, {1.0f, 1.0f, -0.5f});
  EXPECT_EQ(p.x, 1.0f + 256 * 0x1p-23f);
  EXPECT_EQ(p.y, -(1.0f - 256 * 0x1p-24f));  // towards zero: below 1 the ulps are half as large
  EXPECT_EQ(p.z, 1000.0f - 128 * 0x1p-14f);
  // Within 1/32 of the origin: n / 65536.
  const glm::vec3 q = offset_normal_ulp({0.01f, 0.0f, -0.03f}, {0.0f, 1.0f, 0.0f});
  EXPECT_EQ(q.x, 0.01f);
  EXPECT_EQ(q.y, 0x1p-16f);
  EXPECT_EQ(q.z, -0.03f);
  // The truncation of 256 n: 0.999 / 256 of an ulp is none.
  EXPECT_EQ(offset_normal_ulp({4.0f, 4.0f, 4.0f}, {0.999f / 256.0f, 0.0f, 0.0f}).x, 4.0f);
}

using test::Api;

class NumericsOnGpu : public test::PerBackendTest {
 protected:

  // Runs the numerics shader with `function` over one ray per input texel; returns the texels.
  std::vector<uint32_t> run(float function, const std::vector<glm::vec4>& input, const std::vector<glm::vec4>& operand,
                            const std::vector<glm::vec4>& expected, Packing packing = Packing::Bits24_8,
                            bool wide_indices = false) {
    const uint32_t width = 256;
    const uint32_t count = uint32_t(input.size());
    const uint32_t rows = (count + width - 1) / width;
    auto texture = [&](std::vector<glm::vec4> texels) {
      texels.resize(size_t(width) * rows, glm::vec4(0.0f));
      const TextureHandle t = backend->create_texture(width, rows, TexelFormat::RGBA32F);
      backend->upload(t, texels.data(), texels.size() * sizeof(glm::vec4));
      return t;
    };
    const TextureHandle textures[3] = {texture(input), texture(operand), texture(expected)};
    PassDesc desc;
    desc.shader = test_shader(TestShader::Numerics);
    desc.specialization = {{MOBIRT_SPEC_PACKING, int(packing)}};
    if (wide_indices) desc.specialization.push_back({MOBIRT_SPEC_WIDE_INDICES, 1});
    desc.uniform_vec4s = 1;
    desc.texture_bindings = {1, 2, 3};
    const PassHandle pass = backend->create_pass(desc);
    const float uniforms[4] = {function, 0.0f, 0.0f, 0.0f};
    std::vector<uint32_t> out(count);
    backend->run_pass(pass, textures, uniforms, width, count, out);
    backend->destroy(pass);
    for (TextureHandle t : textures) backend->destroy(t);
    return out;
  }

  // Counts the channels (of the first `channels`) the shader flagged as differing from the CPU;
  // names the first few with describe(texel, channel).
  template <class Describe>
  static size_t mismatches(const std::vector<uint32_t>& flags, int channels, Describe describe) {
    size_t bad = 0;
    for (size_t i = 0; i < flags.size(); ++i) {
      for (int c = 0; c < channels; ++c) {
        if (((flags[i] >> (8 * c)) & 0xFFu) == 255u) continue;
        if (++bad <= 10) ADD_FAILURE() << describe(i, c) << " differs from the CPU's";
      }
    }
    return bad;
  }
};

// Values of every magnitude fp16 has (subnormals to the overflow threshold), exact ties, the
// neighbours of ties and of powers of two, random floats.
std::vector<float> half_cases() {
  std::vector<float> v;
  for (int e = -26; e <= 16; ++e) {
    const float p = std::ldexp(1.0f, e);
    for (float x : {p, std::nextafter(p, 0.0f), std::nextafter(p, 1e30f), p * (1.0f + 0x1p-11f),
                    p * (1.0f + 3 * 0x1p-11f), std::nextafter(p * (1.0f + 0x1p-11f), 0.0f)}) {
      v.push_back(x);
      v.push_back(-x);
    }
  }
  for (float x : {65504.0f, 65519.0f, 65519.996f, 0.0f, 0x1p-25f, 0x1.8p-25f}) v.push_back(x);
  std::mt19937 rng(16);
  std::uniform_real_distribution<float> exponent(-28.0f, 16.0f), unit(-1.0f, 1.0f);
  while (v.size() % 4 != 0 || v.size() < 40000) v.push_back(unit(rng) * std::exp2(exponent(rng)));
  return v;
}

TEST_P(NumericsOnGpu, HalfRoundingMatchesTheCpuBitForBit) {
  const std::vector<float> cases = half_cases();
  std::vector<glm::vec4> input, expected;
  for (size_t i = 0; i < cases.size(); i += 4) {
    const glm::vec4 x(cases[i], cases[i + 1], cases[i + 2], cases[i + 3]);
    input.push_back(x);
    expected.emplace_back(round_to_half(x.x), round_to_half(x.y), round_to_half(x.z), round_to_half(x.w));
  }
  const size_t bad = mismatches(run(0.0f, input, input, expected), 4, [&](size_t i, int c) {
    return "f16_round(" + std::to_string(input[i][c]) + ")";
  });
  EXPECT_EQ(bad, 0u) << "of " << cases.size() << " values";
}

TEST_P(NumericsOnGpu, NormalUlpOffsetMatchesTheCpuBitForBit) {
  std::mt19937 rng(19);
  std::uniform_real_distribution<float> exponent(-7.0f, 20.0f), unit(0.0f, 1.0f);
  std::vector<glm::vec4> input, operand, expected;
  for (int i = 0; i < 20000; ++i) {
    glm::vec3 p;
    for (int a = 0; a < 3; ++a) {
      p[a] = (unit(rng) < 0.5f ? -1.0f : 1.0f) * std::exp2(exponent(rng));
      // Every fourth component just above or below a power of two: the move crosses it.
      if (i % 4 == a) p[a] = std::ldexp(1.0f + (unit(rng) - 0.5f) * 0x1p-16f, int(exponent(rng)));
    }
    const glm::vec3 n = test::random_direction(rng);
    input.emplace_back(p, 0.0f);
    operand.emplace_back(n, 0.0f);
    expected.emplace_back(offset_normal_ulp(p, n), 0.0f);
  }
  const size_t bad = mismatches(run(1.0f, input, operand, expected), 3, [&](size_t i, int c) {
    return "offset_normal_ulp(" + std::to_string(input[i][c]) + ", " + std::to_string(operand[i][c]) + ")";
  });
  EXPECT_EQ(bad, 0u);
}

// The traversal pass's packing of hit index + 1 and the shadow mask, at the limits of both
// variants: 2^24 - 1 primitives (24/8) and 2^16 - 1 (16/16), as float arithmetic in the shader.
TEST_P(NumericsOnGpu, TraceTexelPackingAtThePrimitiveLimits) {
  struct Case {
    Packing packing;
    std::vector<uint32_t> indices, masks;
  };
  const Case cases[] = {
      {Packing::Bits24_8, {0, 1, 255, 256, 65535, 65536, MOBIRT_MAX_PRIMS_24_8 - 1, MOBIRT_MAX_PRIMS_24_8}, {0, 1, 0x80, 0xFF}},
      {Packing::Bits16_16, {0, 1, 255, 256, MOBIRT_MAX_PRIMS_16_16 - 1, MOBIRT_MAX_PRIMS_16_16}, {0, 1, 0x8000, 0xFFFF}}};
  for (const Case& c : cases) {
    std::vector<glm::vec4> input;
    std::vector<uint32_t> want;
    for (uint32_t index : c.indices) {
      for (uint32_t mask : c.masks) {
        if (index == 0 && mask != 0) continue;  // a miss carries no shadow bits
        input.emplace_back(float(index), float(mask), 0.0f, 0.0f);
        want.push_back(pack_trace(c.packing, index, mask));
      }
    }
    const std::vector<uint32_t> out = run(2.0f, input, input, input, c.packing);
    for (size_t i = 0; i < out.size(); ++i) {
      EXPECT_EQ(out[i], want[i]) << "index + 1 = " << input[i].x << ", mask " << input[i].y;
      const TraceTexel t = unpack_trace(c.packing, out[i]);
      EXPECT_EQ(t.prim_plus_one, uint32_t(input[i].x));
      EXPECT_EQ(t.mask, uint32_t(input[i].y));
    }
  }
}

// The Vulkan buffers' index conversion (prelude_vk.glsl's data_index): every exact integer float
// below 2^23 by one add, and up to 2^24 - 1 (the last a float holds exactly) under WIDE_INDICES,
// which a pass binding a buffer of more than 2^23 texels gets; the narrow form on [0, 2^23) gives
// the same ints. Around both powers of two, the first and last of every 2^16, and random ones.
TEST_P(NumericsOnGpu, BufferIndicesConvertExactlyBelow2To24) {
  if (GetParam() == Api::Gles) GTEST_SKIP() << "GLSL ES reads 2D textures by coordinates: no data_index()";
  std::vector<uint32_t> indices;
  for (uint32_t base : {0u, uint32_t(MOBIRT_NARROW_INDEX_TEXELS), uint32_t(MOBIRT_MAX_INDEX_TEXELS)}) {
    for (int d = -300; d <= 300; ++d) {
      if (int64_t(base) + d >= 0 && int64_t(base) + d < MOBIRT_MAX_INDEX_TEXELS) indices.push_back(uint32_t(int64_t(base) + d));
    }
  }
  for (uint32_t i = 0; i < MOBIRT_MAX_INDEX_TEXELS; i += 1u << 16) {
    indices.push_back(i);
    indices.push_back(i + (1u << 16) - 1);
  }
  std::mt19937 rng(24);
  std::uniform_int_distribution<uint32_t> any(0, MOBIRT_MAX_INDEX_TEXELS - 1);
  for (int k = 0; k < 20000; ++k) indices.push_back(any(rng));
  std::vector<glm::vec4> input;
  for (uint32_t i : indices) input.emplace_back(float(i), 0.0f, 0.0f, 0.0f);
  for (bool wide : {true, false}) {
    SCOPED_TRACE(wide ? "WIDE_INDICES" : "narrow");
    const std::vector<uint32_t> out = run(3.0f, input, input, input, Packing::Bits24_8, wide);
    size_t bad = 0;
    for (size_t k = 0; k < out.size(); ++k) {
      if (!wide && indices[k] >= MOBIRT_NARROW_INDEX_TEXELS) continue;  // beyond the narrow form's range
      if (out[k] == indices[k]) continue;  // all 32 bits: an index off by 2^24 is wrong too
      if (++bad <= 10) ADD_FAILURE() << "data_index(" << indices[k] << ") = " << int32_t(out[k]);
    }
    EXPECT_EQ(bad, 0u) << "of " << out.size() << " indices";
  }
}

// A light-buffer entry's part of its cell decoded in the shader (glsl/light_buffer.glsl) as the CPU
// decodes it (light_buffer_sub_contains): parts whose edges are the first, second, middle and last
// two columns and rows, among them 2^24 - 1 (every field 63), one ulp below a multiple of 64^2,
// where a division that rounds up would read x1 = y1 = 0; and random parts; each against the
// columns and rows at and beside its edges.
TEST_P(NumericsOnGpu, LightBufferPartsDecodeAsOnTheCpu) {
  const uint32_t edges[] = {0, 1, 31, 62, 63};
  std::vector<std::array<uint32_t, 4>> parts;
  for (uint32_t x0 : edges) {
    for (uint32_t x1 : edges) {
      for (uint32_t y0 : edges) {
        for (uint32_t y1 : edges) {
          if (x0 <= x1 && y0 <= y1) parts.push_back({x0, y0, x1, y1});
        }
      }
    }
  }
  std::mt19937 rng(32);
  std::uniform_int_distribution<uint32_t> any(0, kLightBufferSubCells - 1);
  for (int k = 0; k < 2000; ++k) {
    const uint32_t a = any(rng), b = any(rng), c = any(rng), d = any(rng);
    parts.push_back({std::min(a, b), std::min(c, d), std::max(a, b), std::max(c, d)});
  }
  std::vector<glm::vec4> input;
  std::vector<bool> want;
  size_t inside = 0;
  for (const auto& p : parts) {
    const uint32_t part = light_buffer_sub(p[0], p[1], p[2], p[3]);
    ASSERT_LT(part, 1u << 24);
    for (uint32_t sx : {p[0] > 0 ? p[0] - 1 : p[0], p[0], p[2], std::min(p[2] + 1, kLightBufferSubCells - 1)}) {
      for (uint32_t sy : {p[1] > 0 ? p[1] - 1 : p[1], p[1], p[3], std::min(p[3] + 1, kLightBufferSubCells - 1)}) {
        input.emplace_back(float(part), float(sx), float(sy), 0.0f);
        want.push_back(light_buffer_sub_contains(part, sx, sy));
        inside += want.back() ? 1 : 0;
      }
    }
  }
  ASSERT_GT(inside, input.size() / 4);  // both answers well represented
  ASSERT_LT(inside, input.size());
  const std::vector<uint32_t> out = run(4.0f, input, input, input);
  size_t bad = 0;
  for (size_t i = 0; i < out.size(); ++i) {
    const bool got = (out[i] & 0xFFu) == 255u;
    if (got == want[i]) continue;
    if (++bad <= 10) {
      ADD_FAILURE() << "part " << uint32_t(input[i].x) << " column " << input[i].y << " row " << input[i].z << ": "
                    << (got ? "inside" : "outside") << " on the GPU";
    }
  }
  EXPECT_EQ(bad, 0u) << "of " << out.size() << " cases";
}

INSTANTIATE_TEST_SUITE_P(Backends, NumericsOnGpu, ::testing::Values(Api::Vulkan, Api::Gles), test::api_param_name);

}  // namespace
}  // namespace mobirt
