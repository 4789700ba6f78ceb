// The OpenGL ES 2.0 backend on its own: the context (ES 2.0 through EGL without a window), the
// extensions it checks, the plumbing (textures of every format, uniforms, the ray layout, partial
// uploads, RGBA8 read-back) and the ES 2.0 constraints refused at pass creation. A KHR_debug
// context is on in every test; any message fails it.
#include <gtest/gtest.h>

#include <cstdio>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "backend/backend.h"
#include "copy_pass.h"
#include "core/error.h"
#include "vulkan_fixture.h"
#include "test_shader_ids.h"  // the test-only shaders (TestShader)

namespace mobirt {
namespace {

using test::pack_rgba8;

class GlesBackendTest : public ::testing::Test {
 protected:
  void SetUp() override { backend = create_gles_backend(test::validated_options()); }
  void TearDown() override {
    if (!backend) return;
    const std::vector<std::string> messages = backend->take_debug_messages();
    EXPECT_TRUE(messages.empty()) << "KHR_debug messages:\n" << test::join(messages);
  }

  void expect_refused(const ShaderSource& shader, const std::string& part, size_t textures = 0) {
    PassDesc desc;
    desc.shader = shader;
    for (uint32_t i = 1; i <= textures; ++i) desc.texture_bindings.push_back(i);
    try {
      backend->create_pass(desc);
      ADD_FAILURE() << shader.name << " was not refused";
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::Constraint) << e.what();
      EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(shader.name), std::string::npos) << e.what();
    }
  }

  std::unique_ptr<Backend> backend;
};

TEST_F(GlesBackendTest, ContextIsOpenGlEsOnLlvmpipe) {
  const DeviceInfo info = backend->device_info();
  std::printf("api: %s\ndevice: %s\ndriver: %s\n", info.api.c_str(), info.device.c_str(), info.driver.c_str());
  for (const std::string& line : info.limits) std::printf("  %s\n", line.c_str());
  EXPECT_EQ(info.api.rfind("OpenGL ES ", 0), 0u) << info.api;
  EXPECT_NE(info.device.find("llvmpipe"), std::string::npos) << info.device;
  EXPECT_TRUE(info.is_software);
  EXPECT_EQ(info.driver_version.rfind("Mesa ", 0), 0u) << info.driver_version;
  EXPECT_FALSE(info.ray_query);  // OpenGL ES has no ray tracing
  auto has = [&](const std::string& prefix) {
    for (const std::string& line : info.limits) {
      if (line.rfind(prefix, 0) == 0) return true;
    }
    return false;
  };
  EXPECT_TRUE(has("GL_MAX_TEXTURE_IMAGE_UNITS: "));
  EXPECT_TRUE(has("GL_SHADING_LANGUAGE_VERSION: "));
  EXPECT_TRUE(has("extensions used: GL_OES_texture_float"));
  EXPECT_TRUE(has("GL_MAX_FRAGMENT_UNIFORM_VECTORS: "));
}

TEST_F(GlesBackendTest, TwoOutputsAreRefused) {
  expect_refused(test_shader(TestShader::TwoOutputs), "colour outputs");
}

TEST_F(GlesBackendTest, StorageWritesAreRefused) {
  expect_refused(test_shader(TestShader::StorageWrite), "storage");
}

TEST_F(GlesBackendTest, NineTexturesAreRefused) {
  expect_refused(test_shader(TestShader::NineTextures), "GL_MAX_TEXTURE_IMAGE_UNITS", 8);
  expect_refused(test_shader(TestShader::NineTextures), "GL_MAX_TEXTURE_IMAGE_UNITS", 9);
}

// OpenGL ES 2.0 has no buffer textures: the renderer reads 2D images there whatever --data says.
TEST_F(GlesBackendTest, HasNoTexelBuffers) {
  EXPECT_FALSE(backend->device_info().texel_buffers);
  try {
    backend->create_texel_buffer(16, TexelFormat::RGBA32F);
    ADD_FAILURE() << "expected Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Unsupported) << e.what();
  }
}

// OpenGL ES textures are never written in place: the renderer's texels go through upload().
TEST_F(GlesBackendTest, TexturesAreUploadedNotWrittenInPlace) {
  const TextureHandle texture = backend->create_texture(4, 2, TexelFormat::RGBA32F);
  EXPECT_EQ(backend->begin_write(texture, 8 * 16), nullptr);
  backend->destroy(texture);
}

TEST_F(GlesBackendTest, SpinShaderIsVulkanOnly) {
  PassDesc desc;
  desc.shader = test_shader(TestShader::Spin);
  try {
    backend->create_pass(desc);
    ADD_FAILURE() << "expected Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Unsupported) << e.what();
  }
}

// Every texel format through the copy shader, rows narrower than the texture, odd sizes.
TEST_F(GlesBackendTest, CopyInputRoundTripsEveryFormat) {
  const uint32_t width = 7, count = 7 * 5 - 3;
  for (TexelFormat format : {TexelFormat::RGBA32F, TexelFormat::R32F, TexelFormat::RGBA8}) {
    const TextureHandle input = backend->create_texture(width, 9, format);
    std::vector<uint32_t> expected(count);
    std::vector<float> floats;
    std::vector<uint32_t> bytes;
    for (uint32_t i = 0; i < count; ++i) {
      const uint32_t r = (i * 37) % 256, g = (i * 11 + 3) % 256, b = (255 - i) % 256, a = (i * 5) % 256;
      if (format == TexelFormat::RGBA32F) {
        floats.insert(floats.end(), {r / 255.0f, g / 255.0f, b / 255.0f, a / 255.0f});
        expected[i] = pack_rgba8(r, g, b, a);
      } else if (format == TexelFormat::R32F) {
        floats.push_back(r / 255.0f);
        expected[i] = pack_rgba8(r, r, r, 255);  // LUMINANCE: (L, L, L, 1)
      } else {
        bytes.push_back(pack_rgba8(r, g, b, a));
        expected[i] = bytes.back();
      }
    }
    if (format == TexelFormat::RGBA8) {
      backend->upload(input, bytes.data(), bytes.size() * 4);
    } else {
      backend->upload(input, floats.data(), floats.size() * sizeof(float));
    }
    std::vector<uint32_t> out(count + 3, 0xdeadbeefu);
    const PassTiming timing = test::run_copy_pass(*backend, input, width, count, out);
    EXPECT_EQ(timing.bytes_read, uint64_t(count) * 4);
    EXPECT_GT(timing.wall_ms, 0.0);
    for (uint32_t i = 0; i < count; ++i) {
      if (format == TexelFormat::R32F) {
        EXPECT_EQ(out[i] & 0xFFu, expected[i] & 0xFFu) << "ray " << i;
      } else {
        EXPECT_EQ(out[i], expected[i]) << "ray " << i << " format " << int(format);
      }
    }
    for (uint32_t i = count; i < out.size(); ++i) EXPECT_EQ(out[i], 0xdeadbeefu) << "written past count";
    backend->destroy(input);
  }
}

// Uniforms change between runs, and unused ones read as zero.
TEST_F(GlesBackendTest, UniformsChangeBetweenRuns) { test::expect_uniforms_reach_the_shader(*backend, 4, 12); }

// Two GLES backends alive at once each keep their own context.
TEST_F(GlesBackendTest, TwoBackendsCoexist) {
  auto other = create_gles_backend(test::validated_options());
  const TextureHandle a = backend->create_texture(2, 1, TexelFormat::RGBA8);
  const TextureHandle b = other->create_texture(2, 1, TexelFormat::RGBA8);
  const uint32_t pa[2] = {pack_rgba8(1, 2, 3, 4), pack_rgba8(5, 6, 7, 8)};
  const uint32_t pb[2] = {pack_rgba8(9, 9, 9, 9), pack_rgba8(7, 7, 7, 7)};
  backend->upload(a, pa, sizeof(pa));
  other->upload(b, pb, sizeof(pb));
  const PassHandle pass_a = test::create_copy_pass(*backend);
  const PassHandle pass_b = test::create_copy_pass(*other);
  const float scale[4] = {1.0f, 1.0f, 1.0f, 1.0f};
  std::vector<uint32_t> out(2);
  backend->run_pass(pass_a, std::span(&a, 1), scale, 2, 2, out);
  EXPECT_EQ(out[0], pa[0]);
  EXPECT_EQ(out[1], pa[1]);
  other->run_pass(pass_b, std::span(&b, 1), scale, 2, 2, out);
  EXPECT_EQ(out[0], pb[0]);
  EXPECT_EQ(out[1], pb[1]);
  EXPECT_TRUE(other->take_debug_messages().empty());
}

}  // namespace
}  // namespace mobirt
