// The TestCopyInput pass that the backend tests (Vulkan and GLES) run: a texel in, the same texel
// out as RGBA8, the texel scaled by the first uniform vec4.
#pragma once

#include <gtest/gtest.h>

#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "backend/backend.h"
#include "core/error.h"
#include "test_shader_ids.h"  // the test-only shaders (TestShader)

namespace mobirt::test {

inline uint32_t pack_rgba8(uint32_t r, uint32_t g, uint32_t b, uint32_t a) {
  return r | (g << 8) | (b << 16) | (a << 24);
}

// A copy pass on `backend` that reads texture binding 1 and declares `uniform_vec4s` uniforms.
inline PassHandle create_copy_pass(Backend& backend, uint32_t uniform_vec4s = 1) {
  PassDesc desc;
  desc.shader = test_shader(TestShader::CopyInput);
  desc.uniform_vec4s = uniform_vec4s;
  desc.texture_bindings = {1};
  return backend.create_pass(desc);
}

// One run of a copy pass with unit scale over `count` rays of `input` in rows of `width`.
inline PassTiming run_copy_pass(Backend& backend, TextureHandle input, uint32_t width, uint32_t count,
                                std::span<uint32_t> out) {
  const PassHandle pass = create_copy_pass(backend);
  const float scale[4] = {1.0f, 1.0f, 1.0f, 1.0f};
  const PassTiming timing = backend.run_pass(pass, std::span(&input, 1), scale, width, count, out);
  backend.destroy(pass);
  return timing;
}

// Uniforms reach the shader and change between runs (those the pass declares but is not given
// read as zero): `count` rays in rows of `width` over texels of 1.0, with one set of uniforms, then
// another. More uniforms than the pass declares are refused with an Error, of kind `refused` when
// given.
inline void expect_uniforms_reach_the_shader(Backend& backend, uint32_t width, uint32_t count,
                                             std::optional<ErrorKind> refused = std::nullopt) {
  const std::vector<float> ones(size_t(width) * 3 * 4, 1.0f);
  const TextureHandle input = backend.create_texture(width, 3, TexelFormat::RGBA32F);
  backend.upload(input, ones.data(), ones.size() * sizeof(float));
  const PassHandle pass = create_copy_pass(backend, 4);
  std::vector<uint32_t> out(count);

  const float first[4] = {51.0f / 255.0f, 102.0f / 255.0f, 1.0f, 0.0f};
  backend.run_pass(pass, std::span(&input, 1), first, width, count, out);
  for (uint32_t i = 0; i < count; ++i) ASSERT_EQ(out[i], pack_rgba8(51, 102, 255, 0)) << "ray " << i;

  const float second[8] = {3.0f / 255.0f, 0.0f, 200.0f / 255.0f, 17.0f / 255.0f, 9, 9, 9, 9};
  backend.run_pass(pass, std::span(&input, 1), second, width, count, out);
  for (uint32_t i = 0; i < count; ++i) ASSERT_EQ(out[i], pack_rgba8(3, 0, 200, 17)) << "ray " << i;

  const std::vector<float> too_many(4 * 5, 0.0f);
  try {
    backend.run_pass(pass, std::span(&input, 1), too_many, width, count, out);
    ADD_FAILURE() << "expected Error";
  } catch (const Error& e) {
    if (refused) {
      EXPECT_EQ(e.kind(), *refused) << e.what();
    }
  }
  backend.destroy(pass);
  backend.destroy(input);
}

}  // namespace mobirt::test
