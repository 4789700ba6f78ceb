// The Vulkan backend on lavapipe, with the Khronos validation layer on in every test: each test
// ends with no validation message at all.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "backend/backend.h"
#include "backend/driver_threads.h"
#include "backend/shader_constraints.h"
#include "backend/vulkan/vk_util.h"
#include "backend/vulkan/vulkan_backend.h"
#include "copy_pass.h"
#include "core/error.h"
#include "layout.h"
#include "vulkan_fixture.h"
#include "test_shader_ids.h"  // the test-only shaders (TestShader)

namespace mobirt {
namespace {

using test::join;

using test::pack_rgba8;

double median(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  return values.empty() ? 0.0 : values[values.size() / 2];
}

// Resident memory of this process in MiB (Linux).
double resident_mib() {
  std::ifstream statm("/proc/self/statm");
  long pages = 0, resident = 0;
  statm >> pages >> resident;
  return double(resident) * 4096.0 / (1024.0 * 1024.0);
}

class VulkanBackendTest : public test::VulkanTest {
 protected:
  // A copy pass over `count` rays in rows of `width`: texel k/255 values, read back as RGBA8.
  void copy_round_trip(uint32_t width, uint32_t count) { copy_round_trip(*backend, width, count); }
  void copy_round_trip(Backend& b, uint32_t width, uint32_t count) {
    SCOPED_TRACE("width " + std::to_string(width) + ", count " + std::to_string(count));
    const uint32_t height = (count + width - 1) / width;
    std::vector<float> texels(size_t(count) * 4);
    std::vector<uint32_t> expected(count);
    for (uint32_t i = 0; i < count; ++i) {
      uint32_t k[4];
      for (uint32_t c = 0; c < 4; ++c) {
        k[c] = (i * 7 + c * 61 + i / 251) % 256;
        texels[size_t(i) * 4 + c] = float(k[c]) / 255.0f;
      }
      expected[i] = pack_rgba8(k[0], k[1], k[2], k[3]);
    }
    const TextureHandle input = b.create_texture(width, height, TexelFormat::RGBA32F);
    b.upload(input, texels.data(), texels.size() * sizeof(float));
    std::vector<uint32_t> out(count + 5, 0xdeadbeefu);
    const PassTiming timing = test::run_copy_pass(b, input, width, count, out);
    EXPECT_EQ(timing.bytes_read, uint64_t(count) * 4);
    EXPECT_GT(timing.upload_ms, 0.0);
    size_t wrong = 0;
    for (uint32_t i = 0; i < count; ++i) {
      if (out[i] != expected[i] && wrong++ < 5) {
        ADD_FAILURE() << "ray " << i << ": got " << std::hex << out[i] << ", expected " << expected[i];
      }
    }
    EXPECT_EQ(wrong, 0u);
    for (uint32_t i = count; i < out.size(); ++i) EXPECT_EQ(out[i], 0xdeadbeefu) << "written past count";
    b.destroy(input);
  }
};

TEST_F(VulkanBackendTest, DeviceInfoListsLavapipe) {
  const DeviceInfo info = backend->device_info();
  std::printf("api: %s\ndevice: %s\ndriver: %s\nsoftware: %d\n", info.api.c_str(), info.device.c_str(),
              info.driver.c_str(), int(info.is_software));
  for (const std::string& line : info.limits) std::printf("  %s\n", line.c_str());
  EXPECT_NE(info.device.find("llvmpipe"), std::string::npos) << info.device;
  EXPECT_TRUE(info.is_software);
  EXPECT_EQ(info.api.rfind("Vulkan 1.", 0), 0u) << info.api;
  EXPECT_NE(info.driver.find("Mesa"), std::string::npos) << info.driver;
  // What `mobirt info` prints for a ray-query engine: the Mesa version, and the two extensions
  // (lavapipe has them from Mesa 25, not in 22.3).
  std::printf("driver version: %s, ray queries: %d\n", info.driver_version.c_str(), int(info.ray_query));
  EXPECT_EQ(info.driver_version.rfind("Mesa ", 0), 0u) << info.driver_version;
  if (info.driver_version.rfind("Mesa 22.", 0) == 0) {
    EXPECT_FALSE(info.ray_query);
  }
  if (info.driver_version.rfind("Mesa 25.", 0) == 0) {
    EXPECT_TRUE(info.ray_query);
  }
  const std::string limits = join(info.limits);
  for (const char* name : {"maxImageDimension2D", "maxPerStageDescriptorSampledImages", "maxFragmentOutputAttachments",
                           "maxColorAttachments", "maxUniformBufferRange", "timestampPeriod",
                           "timestampComputeAndGraphics"}) {
    EXPECT_NE(limits.find(name), std::string::npos) << name;
  }
}

// A failed Vulkan call names itself, where it was made and the VkResult.
#if defined(__linux__)
// Mesa's rasterizer threads of this process ("llvmpipe-N") and the CPUs each may run on, from
// /proc/self/task/*/status.
std::vector<std::pair<std::string, std::string>> driver_thread_cpus() {
  std::vector<std::pair<std::string, std::string>> threads;
  for (const auto& task : std::filesystem::directory_iterator("/proc/self/task")) {
    std::ifstream status(task.path() / "status");
    std::string line, name, cpus;
    while (std::getline(status, line)) {
      if (line.rfind("Name:", 0) == 0) name = line.substr(line.find_first_not_of(" \t", 5));
      if (line.rfind("Cpus_allowed_list:", 0) == 0) cpus = line.substr(line.find_first_not_of(" \t", 18));
    }
    if (name.rfind("llvmpipe-", 0) == 0) threads.emplace_back(name, cpus);
  }
  return threads;
}

// pin_driver_threads puts each rasterizer thread on one CPU of its own (N mod the CPU count), and
// a pass still runs right afterwards.
TEST_F(VulkanBackendTest, DriverThreadsArePinnedOnePerCpu) {
  if (!backend->device_info().is_software) GTEST_SKIP() << "not lavapipe: no llvmpipe threads";
  // The CPUs pin_driver_threads spreads the threads over (hardware_concurrency() counts the
  // machine's, not this process's CPU set).
  if (allowed_cpus().size() < 2) GTEST_SKIP() << "fewer than 2 CPUs allowed: nothing to spread";
  const int pinned = pin_driver_threads();
  const auto threads = driver_thread_cpus();
  ASSERT_GE(threads.size(), 2u) << "lavapipe made fewer than 2 rasterizer threads (LP_NUM_THREADS?)";
  EXPECT_EQ(pinned, int(threads.size()));
  std::map<std::string, std::string> cpu_of;
  for (const auto& [name, cpus] : threads) {
    EXPECT_EQ(cpus.find_first_of(",-"), std::string::npos) << name << " may run on CPUs " << cpus;
    cpu_of[name] = cpus;  // each device has its own llvmpipe-0, -1, ...: the same number, the same CPU
  }
  EXPECT_NE(cpu_of["llvmpipe-0"], cpu_of["llvmpipe-1"]);
  copy_round_trip(400, 96000);
}
#endif

TEST(VkCheck, NamesTheCallThePlaceAndTheResult) {
  try {
    vk::check(VK_ERROR_OUT_OF_DEVICE_MEMORY, "vkAllocateMemory(device, &info, nullptr, &memory)",
              "/home/x/mobirt/src/backend/vulkan/vk_resources.cpp", 42);
    ADD_FAILURE() << "expected Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Internal);
    EXPECT_STREQ(e.what(),
                 "vkAllocateMemory failed (src/backend/vulkan/vk_resources.cpp:42): VK_ERROR_OUT_OF_DEVICE_MEMORY");
  }
  try {
    VK_CHECK_RESULT(VK_ERROR_DEVICE_LOST, "vkQueueSubmit");
    ADD_FAILURE() << "expected Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("vkQueueSubmit failed (vulkan_backend_test.cpp:"), std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("): VK_ERROR_DEVICE_LOST"), std::string::npos) << e.what();
  }
  EXPECT_NO_THROW(VK_CHECK(VK_SUCCESS));
}

TEST(DeviceInfo, MesaVersionFromDriverStrings) {
  EXPECT_EQ(mesa_version("Mesa 22.3.6 (LLVM 15.0.6)"), "Mesa 22.3.6");             // lavapipe's driverInfo
  EXPECT_EQ(mesa_version("OpenGL ES 3.2 Mesa 25.0.7-2~bpo12+1"), "Mesa 25.0.7");  // GL_VERSION, backports
  EXPECT_EQ(mesa_version("NVIDIA 535.104.05"), "");
  EXPECT_EQ(mesa_version("Mesa Project"), "");  // EGL_VENDOR: no version
}

// The pass-description rules both backends apply before building anything (check_pass_desc).
TEST(PassDesc, SharedChecksRefuseBadDescriptions) {
  auto refused = [](const PassDesc& desc, ErrorKind kind, const std::string& part) {
    try {
      check_pass_desc(desc);
      ADD_FAILURE() << "accepted; expected: " << part;
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), kind) << e.what();
      EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("copy_input.frag"), std::string::npos) << e.what();
    }
  };
  PassDesc desc;
  desc.shader = test_shader(TestShader::CopyInput);
  desc.texture_bindings = {1, 2};
  EXPECT_NO_THROW(check_pass_desc(desc));
  desc.texture_bindings = {0};  // the uniforms' slot, with or without uniforms
  refused(desc, ErrorKind::Internal, "binding 0");
  desc.texture_bindings = {1, 3, 1};
  refused(desc, ErrorKind::Internal, "binding 1 is used twice");
  desc.texture_bindings = {1, 2, 3, 4, 5, 6, 7, 8, 9};
  refused(desc, ErrorKind::Constraint, "at most 8");
  desc.texture_bindings = {1};
  desc.uniform_vec4s = MOBIRT_MAX_PARAM_VEC4S + 1;
  refused(desc, ErrorKind::Internal, "uniform vec4");
  desc.uniform_vec4s = 1;
  desc.specialization = {{MOBIRT_SPEC_PACKING, 0}, {MOBIRT_SPEC_PACKING, 1}};
  refused(desc, ErrorKind::Internal, "set twice");
}

TEST_F(VulkanBackendTest, CopyRoundTripIsExact) {
  copy_round_trip(1, 1);
  copy_round_trip(7, 50);        // count not a multiple of the width
  copy_round_trip(400, 96000);   // 400x240
  copy_round_trip(400, 95877);   // last row partial
  copy_round_trip(4096, 4096 * 300 + 17);  // 19 MB: two staging chunks
  copy_round_trip(64, 64);       // smaller than the cached target: renders a sub-rectangle
}

// The staging path (optimal images, a copy command per chunk), which a device without host-mapped
// linear images takes, gives the same texels as the default in-place writes.
TEST_F(VulkanBackendTest, StagedImagesRoundTripToo) {
  VulkanOptions options{test::validated_options()};
  options.staged_images = true;
  const std::unique_ptr<Backend> staged = create_vulkan_backend(options);
  copy_round_trip(*staged, 7, 50);
  copy_round_trip(*staged, 400, 95877);
  copy_round_trip(*staged, 4096, 4096 * 300 + 17);  // 19 MB: two staging chunks
  // The staged path's output went through the copy command; the default's was read in place
  // from a linear target (lavapipe renders into one), which CopyRoundTripIsExact checks, down to
  // a pass narrower than the cached target (its rows a row pitch apart).
  EXPECT_FALSE(vulkan_reads_target_in_place(*staged));
  copy_round_trip(1, 1);
  EXPECT_TRUE(vulkan_reads_target_in_place(*backend));
  const std::vector<std::string> messages = staged->take_debug_messages();
  EXPECT_TRUE(messages.empty()) << "validation layer messages:\n" << join(messages);
}

// An image takes new contents after a pass has read it (written in place in GENERAL layout, or
// staged), and the next pass reads the new ones, on both upload paths.
TEST_F(VulkanBackendTest, UploadsAfterAPassReachTheNextPass) {
  VulkanOptions options{test::validated_options()};
  options.staged_images = true;
  const std::unique_ptr<Backend> staged = create_vulkan_backend(options);
  for (Backend* b : {backend.get(), staged.get()}) {
    SCOPED_TRACE(b == staged.get() ? "staged images" : "in-place images");
    const uint32_t width = 6, count = 17;
    const TextureHandle image = b->create_texture(width, 3, TexelFormat::RGBA32F);
    std::vector<uint32_t> out(count);
    for (uint32_t round = 1; round <= 3; ++round) {
      std::vector<float> texels(size_t(count) * 4);
      for (size_t i = 0; i < texels.size(); ++i) texels[i] = float((i * round * 13) % 256) / 255.0f;
      b->upload(image, texels.data(), texels.size() * sizeof(float));
      test::run_copy_pass(*b, image, width, count, out);
      for (uint32_t i = 0; i < count; ++i) {
        const auto k = [&](uint32_t c) { return uint32_t((size_t(i * 4 + c) * round * 13) % 256); };
        EXPECT_EQ(out[i], pack_rgba8(k(0), k(1), k(2), k(3))) << "round " << round << ", texel " << i;
      }
    }
    b->destroy(image);
  }
  const std::vector<std::string> messages = staged->take_debug_messages();
  EXPECT_TRUE(messages.empty()) << "validation layer messages:\n" << join(messages);
}

// Texels written in place (Backend::begin_write) where the texture is mapped: a linear image on
// lavapipe, a texel buffer; the next pass reads what was written, round after round. An image the
// backend stages (optimal tiling) says nullptr, so the caller uploads instead; so may one whose
// rows are padded, and either way the pass reads the texels in row-major order.
TEST_F(VulkanBackendTest, TexelsWrittenInPlaceReachTheNextPass) {
  VulkanOptions options{test::validated_options()};
  options.staged_images = true;
  const std::unique_ptr<Backend> staged = create_vulkan_backend(options);
  const TextureHandle optimal = staged->create_texture(64, 3, TexelFormat::RGBA32F);
  EXPECT_EQ(staged->begin_write(optimal, 150 * 16), nullptr);
  staged->destroy(optimal);

  // Rows of 1 KiB (unpadded), and rows of 6 texels (lavapipe pads them).
  for (const uint32_t width : {64u, 6u}) {
    SCOPED_TRACE("width " + std::to_string(width));
    const uint32_t count = width * 2 + width / 2;
    const TextureHandle image = backend->create_texture(width, 3, TexelFormat::RGBA32F);
    std::vector<uint32_t> out(count);
    std::vector<float> staging(size_t(count) * 4);
    for (uint32_t round = 1; round <= 3; ++round) {
      float* in_place = static_cast<float*>(backend->begin_write(image, size_t(count) * 16));
      if (width == 64) {
        ASSERT_NE(in_place, nullptr) << "lavapipe's images are linear and mapped";
      }
      float* texels = in_place ? in_place : staging.data();
      for (size_t i = 0; i < size_t(count) * 4; ++i) texels[i] = float((i * round * 13) % 256) / 255.0f;
      if (in_place) {
        backend->end_write(image);
      } else {
        backend->upload(image, texels, staging.size() * sizeof(float));
      }
      test::run_copy_pass(*backend, image, width, count, out);
      for (uint32_t i = 0; i < count; ++i) {
        const auto k = [&](uint32_t c) { return uint32_t((size_t(i * 4 + c) * round * 13) % 256); };
        EXPECT_EQ(out[i], pack_rgba8(k(0), k(1), k(2), k(3))) << "round " << round << ", texel " << i;
      }
    }
    // Too many bytes, or a partial texel: refused, as upload() refuses them.
    EXPECT_THROW(backend->begin_write(image, size_t(width) * 3 * 16 + 16), Error);
    EXPECT_THROW(backend->begin_write(image, 6), Error);
    backend->destroy(image);
  }

  const TextureHandle buffer = backend->create_texel_buffer(16, TexelFormat::RGBA32F);
  EXPECT_NE(backend->begin_write(buffer, 16 * 16), nullptr);
  backend->end_write(buffer);
  EXPECT_THROW(backend->begin_write(buffer, 17 * 16), Error);
  backend->destroy(buffer);
  const std::vector<std::string> messages = staged->take_debug_messages();
  EXPECT_TRUE(messages.empty()) << "validation layer messages:\n" << join(messages);
}

TEST_F(VulkanBackendTest, UniformsReachTheShader) {
  test::expect_uniforms_reach_the_shader(*backend, 16, 40, ErrorKind::Internal);
}

TEST_F(VulkanBackendTest, PartialUploadKeepsTheRest) {
  const uint32_t width = 5, height = 4;
  std::vector<float> first(size_t(width) * height * 4, 10.0f / 255.0f);
  std::vector<float> second(size_t(7) * 4, 20.0f / 255.0f);  // one row and two texels
  const TextureHandle input = backend->create_texture(width, height, TexelFormat::RGBA32F);
  backend->upload(input, first.data(), first.size() * sizeof(float));
  backend->upload(input, second.data(), second.size() * sizeof(float));
  const PassHandle pass = test::create_copy_pass(*backend);
  const float scale[4] = {1, 1, 1, 1};
  std::vector<uint32_t> out(width * height);
  backend->run_pass(pass, std::span(&input, 1), scale, width, width * height, out);
  for (uint32_t i = 0; i < width * height; ++i) {
    const uint32_t k = i < 7 ? 20 : 10;
    EXPECT_EQ(out[i], pack_rgba8(k, k, k, k)) << "texel " << i;
  }
  // Too many bytes, or a partial texel: refused.
  std::vector<float> big(size_t(width) * height * 4 + 4, 0.0f);
  EXPECT_THROW(backend->upload(input, big.data(), big.size() * sizeof(float)), Error);
  EXPECT_THROW(backend->upload(input, big.data(), 6), Error);
  backend->destroy(pass);
  backend->destroy(input);
}

TEST_F(VulkanBackendTest, OtherTexelFormats) {
  // R32F and RGBA8 textures are created, uploaded and bound (values checked through RGBA8).
  const uint32_t width = 8, count = 8;
  std::vector<uint8_t> bytes(size_t(count) * 4);
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = uint8_t(i * 9);
  const TextureHandle rgba8 = backend->create_texture(width, 1, TexelFormat::RGBA8);
  backend->upload(rgba8, bytes.data(), bytes.size());
  const PassHandle pass = test::create_copy_pass(*backend);
  const float scale[4] = {1, 1, 1, 1};
  std::vector<uint32_t> out(count);
  backend->run_pass(pass, std::span(&rgba8, 1), scale, width, count, out);
  for (uint32_t i = 0; i < count; ++i) {
    EXPECT_EQ(out[i], pack_rgba8(bytes[i * 4], bytes[i * 4 + 1], bytes[i * 4 + 2], bytes[i * 4 + 3]));
  }
  std::vector<float> reds(count);
  for (uint32_t i = 0; i < count; ++i) reds[i] = float(i * 30) / 255.0f;
  const TextureHandle r32f = backend->create_texture(width, 1, TexelFormat::R32F);
  backend->upload(r32f, reds.data(), reds.size() * sizeof(float));
  backend->run_pass(pass, std::span(&r32f, 1), scale, width, count, out);
  for (uint32_t i = 0; i < count; ++i) EXPECT_EQ(out[i], pack_rgba8(i * 30, 0, 0, 255));  // (r, 0, 0, 1)
  backend->destroy(pass);
  backend->destroy(rgba8);
  backend->destroy(r32f);
}

TEST_F(VulkanBackendTest, BadSizesAreRefused) {
  try {
    backend->create_texture(1u << 20, 1, TexelFormat::RGBA32F);
    ADD_FAILURE() << "expected Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    EXPECT_NE(std::string(e.what()).find("maxImageDimension2D"), std::string::npos) << e.what();
  }
  EXPECT_THROW(backend->create_texture(0, 4, TexelFormat::R32F), Error);
  EXPECT_THROW(backend->upload(TextureHandle{12345}, nullptr, 0), Error);
}

void expect_refused(Backend& backend, const ShaderSource& shader, const std::string& rule) {
  PassDesc desc;
  desc.shader = shader;
  desc.uniform_vec4s = 1;
  try {
    backend.create_pass(desc);
    ADD_FAILURE() << shader.name << " was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Constraint) << e.what();
    EXPECT_NE(std::string(e.what()).find(rule), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(shader.name), std::string::npos) << e.what();
    std::printf("refused: %s\n", e.what());
  }
}

TEST_F(VulkanBackendTest, ConstraintShadersAreRefused) {
  const long objects = vulkan_live_objects();
  expect_refused(*backend, test_shader(TestShader::TwoOutputs), "writes 2 colour attachments");
  expect_refused(*backend, test_shader(TestShader::StorageWrite), "storage buffers");
  expect_refused(*backend, test_shader(TestShader::NineTextures), "samples 9 textures; at most 8");
  // Texel buffers are sampled textures of the ES 2.0 model: they count against the 8, and a
  // storage texel buffer is a storage image.
  expect_refused(*backend, test_shader(TestShader::TexelBuffers), "samples 9 textures; at most 8");
  expect_refused(*backend, test_shader(TestShader::TexelBufferStore), "storage buffers, storage images");
  EXPECT_EQ(vulkan_live_objects(), objects) << "a refused pass left Vulkan objects behind";
}

TEST_F(VulkanBackendTest, TexelBufferTraversalKeepsTheConstraints) {
  const ShaderInterface s = reflect_spirv(shader_source(ShaderId::TraverseTexelBuffers).spirv);
  ASSERT_TRUE(s.valid);
  EXPECT_EQ(s.sampled_textures, 5);  // nodes, leaf entries, triangles, ray origins and directions
  EXPECT_EQ(s.storage_resources, 0);
  EXPECT_EQ(s.storage_writes, 0);
  EXPECT_TRUE(es2_constraints_broken(shader_source(ShaderId::TraverseTexelBuffers).spirv).empty());
}

// The shading pass's buffer variants: texel buffers keep every ES 2.0 rule (five inputs and three
// atlas pages are the 8 sampled textures); storage buffers break only the named one.
TEST_F(VulkanBackendTest, ShadingPassBufferVariants) {
  const ShaderInterface t = reflect_spirv(shader_source(ShaderId::ShadeTexelBuffers).spirv);
  ASSERT_TRUE(t.valid);
  EXPECT_EQ(t.sampled_textures, 8);  // hit position, normal, texcoord, ray direction, materials, 3 pages
  EXPECT_EQ(t.storage_resources, 0);
  EXPECT_TRUE(es2_constraints_broken(shader_source(ShaderId::ShadeTexelBuffers).spirv).empty());
  const ShaderInterface b = reflect_spirv(shader_source(ShaderId::ShadeStorageBuffers).spirv);
  ASSERT_TRUE(b.valid);
  EXPECT_EQ(b.storage_resources, 5);
  EXPECT_EQ(b.storage_writes, 0);
  EXPECT_EQ(b.sampled_textures, 3);  // the atlas pages
  EXPECT_EQ(es2_constraints_broken(shader_source(ShaderId::ShadeStorageBuffers).spirv),
            std::vector<std::string>{kEs2StorageReads});
}

// --data storage-buffers: the one rule it breaks is named (reading storage buffers), it writes
// none, and it is accepted only by a pass whose description binds storage buffers there.
TEST_F(VulkanBackendTest, StorageBufferTraversalBreaksOnlyTheNamedRule) {
  const std::span<const uint32_t> spirv = shader_source(ShaderId::TraverseStorageBuffers).spirv;
  const ShaderInterface s = reflect_spirv(spirv);
  ASSERT_TRUE(s.valid);
  EXPECT_EQ(s.storage_resources, 5);  // nodes, leaf entries, triangles, ray origins and directions
  EXPECT_EQ(s.storage_writes, 0);
  EXPECT_EQ(s.sampled_textures, 0);
  EXPECT_EQ(es2_constraints_broken(spirv), std::vector<std::string>{kEs2StorageReads});
  EXPECT_NO_THROW(check_es2_constraints("trace_storage_buffers.frag", spirv, true));
  try {
    check_es2_constraints("trace_storage_buffers.frag", spirv);
    ADD_FAILURE() << "storage reads accepted without the pass declaring them";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Constraint);
    EXPECT_NE(std::string(e.what()).find("reads storage buffers"), std::string::npos) << e.what();
  }
  // A pass that declares images at those bindings is refused before any Vulkan object exists.
  PassDesc desc;
  desc.shader = ShaderId::TraverseStorageBuffers;
  desc.texture_bindings = {MOBIRT_BIND_NODES, MOBIRT_BIND_LEAF_PRIMS, MOBIRT_BIND_TRIANGLES,
                           MOBIRT_BIND_RAY_ORIGIN, MOBIRT_BIND_RAY_DIRECTION};
  EXPECT_THROW(backend->create_pass(desc), Error);
  // Declared as storage buffers, the pass is made.
  desc.uniform_vec4s = MOBIRT_TP_LIGHTS;
  desc.texture_kinds.assign(desc.texture_bindings.size(), TextureKind::StorageBuffer);
  const PassHandle pass = backend->create_pass(desc);
  backend->destroy(pass);
  // Storage-buffer writes stay refused whatever the pass declares.
  EXPECT_THROW(check_es2_constraints("texel_buffer_store.frag", test_shader(TestShader::TexelBufferStore).spirv, true),
               Error);
}

// --data device-addresses: the scene's buffers read through buffer references count as storage
// reads (the one rule named), nothing is written, no texture is sampled; the pass is made only when
// its description reads those bindings by address, and a write through a reference stays refused.
TEST_F(VulkanBackendTest, DeviceAddressTraversalBreaksOnlyTheNamedRule) {
  ASSERT_TRUE(backend->device_info().device_addresses) << "lavapipe has VK_KHR_buffer_device_address";
  for (ShaderId id : {ShaderId::TraverseDeviceAddresses, ShaderId::ShadeDeviceAddresses}) {
    const std::span<const uint32_t> spirv = shader_source(id).spirv;
    const ShaderInterface s = reflect_spirv(spirv);
    ASSERT_TRUE(s.valid);
    EXPECT_GT(s.storage_resources, 0);
    EXPECT_EQ(s.storage_writes, 0);
    EXPECT_EQ(s.sampled_textures, id == ShaderId::ShadeDeviceAddresses ? 3 : 0);  // the atlas pages
    EXPECT_EQ(es2_constraints_broken(spirv), std::vector<std::string>{kEs2StorageReads});
  }
  PassDesc desc;
  desc.shader = ShaderId::TraverseDeviceAddresses;
  desc.uniform_vec4s = MOBIRT_TP_LIGHTS;
  desc.texture_bindings = {MOBIRT_BIND_NODES, MOBIRT_BIND_LEAF_PRIMS, MOBIRT_BIND_TRIANGLES,
                           MOBIRT_BIND_RAY_ORIGIN, MOBIRT_BIND_RAY_DIRECTION};
  EXPECT_THROW(backend->create_pass(desc), Error);  // declared as images: storage reads refused
  desc.texture_kinds.assign(desc.texture_bindings.size(), TextureKind::DeviceAddress);
  const PassHandle pass = backend->create_pass(desc);
  // Its textures are storage buffers; a texel buffer where the pass reads an address is refused.
  const TextureHandle wrong = backend->create_texel_buffer(16, TexelFormat::RGBA32F);
  std::vector<TextureHandle> textures(desc.texture_bindings.size(), wrong);
  std::vector<uint32_t> out(4);
  const std::vector<float> uniforms(4 * MOBIRT_TP_LIGHTS, 0.0f);
  EXPECT_THROW(backend->run_pass(pass, textures, uniforms, 4, 4, out), Error);
  backend->destroy(wrong);
  backend->destroy(pass);
  const std::span<const uint32_t> store = test_shader(TestShader::DeviceAddressStore).spirv;
  EXPECT_GT(reflect_spirv(store).storage_writes, 0);
  EXPECT_THROW(check_es2_constraints("device_address_store.frag", store, true), Error);
}

// A buffer of more than 2^23 texels is made (indices reach 2^24 exactly as floats), but only a
// pass specialised to WIDE_INDICES may bind it: the narrow index conversion would read the wrong
// texels past 2^23, so a pass without it is refused, naming the texture.
TEST_F(VulkanBackendTest, BuffersBeyond2To23NeedWideIndices) {
  const TextureHandle big = backend->create_texel_buffer(uint32_t(MOBIRT_NARROW_INDEX_TEXELS) + 4, TexelFormat::RGBA32F);
  const TextureHandle small = backend->create_texel_buffer(16, TexelFormat::RGBA32F);
  const std::vector<float> zeros(16 * 4, 0.0f);
  backend->upload(small, zeros.data(), zeros.size() * sizeof(float));
  PassDesc desc;
  desc.shader = ShaderId::TraverseTexelBuffers;
  desc.uniform_vec4s = MOBIRT_TP_LIGHTS;
  desc.texture_bindings = {MOBIRT_BIND_NODES, MOBIRT_BIND_LEAF_PRIMS, MOBIRT_BIND_TRIANGLES,
                           MOBIRT_BIND_RAY_ORIGIN, MOBIRT_BIND_RAY_DIRECTION};
  desc.texture_kinds.assign(desc.texture_bindings.size(), TextureKind::TexelBuffer);
  const PassHandle narrow = backend->create_pass(desc);
  desc.specialization = {{MOBIRT_SPEC_WIDE_INDICES, 1}};
  const PassHandle wide = backend->create_pass(desc);
  const TextureHandle textures[] = {small, big, small, small, small};
  const std::vector<float> uniforms(4 * MOBIRT_TP_LIGHTS, 0.0f);
  std::vector<uint32_t> out(4);
  try {
    backend->run_pass(narrow, textures, uniforms, 4, 4, out);
    ADD_FAILURE() << "a narrow pass bound a buffer of more than 2^23 texels";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Internal);
    EXPECT_NE(std::string(e.what()).find("texture 1 is a buffer of 8388612 texels"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("WIDE_INDICES"), std::string::npos) << e.what();
  }
  EXPECT_NO_THROW(backend->run_pass(wide, textures, uniforms, 4, 4, out));  // runs; what it finds is not the point
  const TextureHandle all_small[] = {small, small, small, small, small};
  EXPECT_NO_THROW(backend->run_pass(narrow, all_small, uniforms, 4, 4, out));
  for (PassHandle p : {narrow, wide}) backend->destroy(p);
  for (TextureHandle t : {big, small}) backend->destroy(t);
}

TEST_F(VulkanBackendTest, TexelBuffersRefuseBadUse) {
  EXPECT_TRUE(backend->device_info().texel_buffers);
  try {
    backend->create_texel_buffer(uint32_t(MOBIRT_MAX_INDEX_TEXELS) + 1, TexelFormat::RGBA32F);
    ADD_FAILURE() << "expected Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    EXPECT_NE(std::string(e.what()).find("at most 2^24"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("--data images"), std::string::npos) << e.what();
  }
  EXPECT_THROW(backend->create_texel_buffer(0, TexelFormat::R32F), Error);
  const TextureHandle buffer = backend->create_texel_buffer(16, TexelFormat::RGBA32F);
  const std::vector<float> too_many(17 * 4, 1.0f);
  EXPECT_THROW(backend->upload(buffer, too_many.data(), too_many.size() * sizeof(float)), Error);
  // A pass that reads a 2D image at binding 1 refuses a texel buffer there.
  std::vector<uint32_t> out(4);
  try {
    test::run_copy_pass(*backend, buffer, 4, 4, out);
    ADD_FAILURE() << "expected Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Internal);
    EXPECT_NE(std::string(e.what()).find("texel buffer"), std::string::npos) << e.what();
  }
  backend->destroy(buffer);
}

// Mesa 22.3's llvmpipe (lavapipe) ends a shader invocation's loops after 65535 iterations in all,
// silently (gallivm's LP_MAX_TGSI_LOOP_ITERATIONS): one budget shared by every loop of the shader
// and counted per SIMD group of fragments. Mesa 25.0's llvmpipe, like other drivers, runs the loops
// to their caps, so there the shader's own cap is the only guard against a runaway loop.
constexpr uint32_t kLlvmpipeLoopBudget = 65535;

TEST_F(VulkanBackendTest, SpinHonoursTheCap) {
  const uint32_t width = 32, count = 32 * 32;
  std::vector<float> seeds(size_t(count) * 4);
  for (size_t i = 0; i < seeds.size(); ++i) seeds[i] = float(i % 97) / 97.0f;
  const TextureHandle input = backend->create_texture(width, count / width, TexelFormat::RGBA32F);
  backend->upload(input, seeds.data(), seeds.size() * sizeof(float));

  struct Case { uint32_t cap, second; bool odd_columns_skip_first; };
  auto spin = [&](const Case& c, std::vector<uint32_t>& out, PassTiming* first_run) {
    PassDesc desc;
    desc.shader = test_shader(TestShader::Spin);
    desc.specialization = {{MOBIRT_SPEC_MAX_STEPS, int32_t(c.cap)}, {16, int32_t(c.second)},
                           {17, c.odd_columns_skip_first ? 1 : 0}};
    desc.texture_bindings = {1};
    const PassHandle pass = backend->create_pass(desc);
    out.assign(count, 0);
    const PassTiming first = backend->run_pass(pass, std::span(&input, 1), {}, width, count, out);
    if (first_run) *first_run = first;
    const PassTiming timing = backend->run_pass(pass, std::span(&input, 1), {}, width, count, out);
    backend->destroy(pass);
    return timing;
  };
  // Which loop model this driver follows: a single loop capped above the budget either runs to its
  // cap (every ray reports exactly the cap) or is stopped by llvmpipe's budget (65534 or 65535,
  // the position of the increment against the back edge), and only on llvmpipe. Anything else fails.
  std::vector<uint32_t> probe;
  spin(Case{100000, 0, false}, probe, nullptr);
  const bool llvmpipe = backend->device_info().device.find("llvmpipe") != std::string::npos;
  const uint32_t probed = probe[0] & 0xffffffu;
  const bool budgeted = llvmpipe && probed < 100000u;
  std::printf("loop model: %s (a loop capped at 100000 ran %u iterations; %s)\n",
              budgeted ? "llvmpipe's 65535-iteration budget" : "the shader's cap only", probed,
              backend->device_info().driver.c_str());
  if (budgeted) {
    ASSERT_GE(probed, kLlvmpipeLoopBudget - 1) << "stopped below llvmpipe's budget";
  }
  // The iterations ray `column` should report: [low, high].
  auto expected = [&](const Case& c, uint32_t column) -> std::pair<uint32_t, uint32_t> {
    const uint32_t first = c.odd_columns_skip_first && (column & 1) ? 0 : c.cap;
    const uint32_t wanted = first + c.second;
    if (!budgeted || c.cap + c.second <= kLlvmpipeLoopBudget) return {wanted, wanted};
    if (c.cap >= kLlvmpipeLoopBudget) return {kLlvmpipeLoopBudget - 1, kLlvmpipeLoopBudget};
    // The first loop spent `cap` of the group's budget, even for rays that skipped it; where the
    // second loop's increment sits relative to its back edge costs one more.
    const uint32_t left = kLlvmpipeLoopBudget - c.cap;
    return {first + left - 1, first + left};
  };
  for (const Case c : {Case{1000, 0, false}, Case{100000, 0, false}, Case{40000, 40000, false},
                       Case{60000, 10000, true}}) {
    std::vector<uint32_t> out;
    PassTiming first;
    const PassTiming timing = spin(c, out, &first);
    std::printf("spin caps %u + %u%s over %u rays: %u / %u iterations (even / odd column), gpu %.2f ms "
                "(first run %.2f), wall %.2f ms\n", c.cap, c.second, c.odd_columns_skip_first ? " (odd columns skip the first)" : "",
                count, out[0] & 0xffffffu, out[1] & 0xffffffu, timing.gpu_ms, first.gpu_ms, timing.wall_ms);
    for (uint32_t i = 0; i < count; ++i) {
      ASSERT_EQ(out[i] >> 24, 255u) << "ray " << i << ": loop ended by its data exit";
      const uint32_t total = out[i] & 0xffffffu;
      const auto [low, high] = expected(c, i % width);
      ASSERT_TRUE(total >= low && total <= high) << "ray " << i << ", caps " << c.cap << " + " << c.second << ": "
                                                 << total << " iterations, expected " << low << ".." << high;
    }
  }
  backend->destroy(input);
}

TEST(VulkanBackendDevice, UnknownDeviceListsTheAvailableOnes) {
  BackendOptions options = test::validated_options();
  options.device = "no-such-device";
  try {
    create_vulkan_backend(options);
    ADD_FAILURE() << "expected Error(NoDevice)";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::NoDevice);
    EXPECT_NE(std::string(e.what()).find("no-such-device"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("llvmpipe"), std::string::npos) << e.what();
    std::printf("%s\n", e.what());
  }
  options.device = "99";
  EXPECT_THROW(create_vulkan_backend(options), Error);
  options.device = "LLVMPIPE";  // case-insensitive substring
  auto backend = create_vulkan_backend(options);
  EXPECT_NE(backend->device_info().device.find("llvmpipe"), std::string::npos);
  EXPECT_TRUE(backend->take_debug_messages().empty());
  options.device = "0";
  EXPECT_NO_THROW(create_vulkan_backend(options));
}

TEST_F(VulkanBackendTest, ValidationErrorsThrow) {
  // copy_input.frag reads the uniform block, but this pass declares none: the pipeline layout
  // lacks binding 0, which the validation layer reports and the backend turns into an Error.
  PassDesc desc;
  desc.shader = test_shader(TestShader::CopyInput);
  desc.uniform_vec4s = 0;
  desc.texture_bindings = {1};
  const long objects = vulkan_live_objects();
  try {
    backend->create_pass(desc);
    ADD_FAILURE() << "expected a validation error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Internal);
    EXPECT_NE(std::string(e.what()).find("validation error"), std::string::npos) << e.what();
    std::printf("%.300s...\n", e.what());
  }
  EXPECT_EQ(vulkan_live_objects(), objects) << "the refused pass kept its objects";
  EXPECT_FALSE(backend->take_debug_messages().empty());
}

TEST_F(VulkanBackendTest, CyclesDoNotLeak) {
  const uint32_t width = 40, count = 100;
  std::vector<float> texels(size_t(width) * 3 * 4, 0.5f);
  const float scale[4] = {1, 1, 1, 1};
  std::vector<uint32_t> out(count);
  auto cycle = [&] {
    const TextureHandle input = backend->create_texture(width, 3, TexelFormat::RGBA32F);
    backend->upload(input, texels.data(), texels.size() * sizeof(float));
    const PassHandle pass = test::create_copy_pass(*backend);
    backend->run_pass(pass, std::span(&input, 1), scale, width, count, out);
    backend->destroy(pass);
    backend->destroy(input);
  };
  for (int i = 0; i < 10; ++i) cycle();  // warm-up: caches, target, staging
  const long objects = vulkan_live_objects();
  const double before = resident_mib();
  for (int i = 0; i < 200; ++i) cycle();
  const double after = resident_mib();
  std::printf("200 cycles: %ld -> %ld live Vulkan objects, resident %.1f -> %.1f MiB\n", objects,
              vulkan_live_objects(), before, after);
  EXPECT_EQ(vulkan_live_objects(), objects);
  EXPECT_LT(after - before, 16.0) << "resident memory grew";
  EXPECT_EQ(out[0], pack_rgba8(128, 128, 128, 128));
  // Stale handles are refused, not used.
  const TextureHandle input = backend->create_texture(width, 3, TexelFormat::RGBA32F);
  backend->destroy(input);
  EXPECT_THROW(backend->upload(input, texels.data(), 16), Error);
}

// --gpu-timestamps: a pass timed on the device's clock (timestamp queries) and one timed on the
// CPU's (lavapipe's default: each timestamp there waits for the work) write the same texels, and
// both report a time for the pass and for the raster. Auto takes timestamps on a GPU only.
TEST(GpuTimestamps, ModesChooseTheClock) {
  EXPECT_FALSE(takes_gpu_timestamps(GpuTimestamps::Auto, 64, true));
  EXPECT_TRUE(takes_gpu_timestamps(GpuTimestamps::Auto, 64, false));
  EXPECT_TRUE(takes_gpu_timestamps(GpuTimestamps::On, 64, true));
  EXPECT_FALSE(takes_gpu_timestamps(GpuTimestamps::Off, 64, false));
  EXPECT_FALSE(takes_gpu_timestamps(GpuTimestamps::On, 0, false));  // a queue without timestamps
  EXPECT_STREQ(gpu_timestamps_name(GpuTimestamps::Auto), "auto");
  EXPECT_STREQ(gpu_timestamps_name(GpuTimestamps::On), "on");
  EXPECT_STREQ(gpu_timestamps_name(GpuTimestamps::Off), "off");

  const uint32_t width = 64, height = 16, count = width * height;
  std::vector<float> texels(size_t(count) * 4);
  for (size_t i = 0; i < texels.size(); ++i) texels[i] = float(i % 251) / 251.0f;
  const float scale[4] = {1, 1, 1, 1};
  std::vector<uint32_t> outputs[2], rasters[2];
  int made = 0;
  for (const GpuTimestamps mode : {GpuTimestamps::On, GpuTimestamps::Off}) {
    SCOPED_TRACE(gpu_timestamps_name(mode));
    BackendOptions options = test::validated_options();
    options.timestamps = mode;
    const std::unique_ptr<Backend> backend = create_vulkan_backend(options);
    if (mode == GpuTimestamps::Off) {
      EXPECT_FALSE(backend->device_info().gpu_timestamps);
    } else if (backend->device_info().is_software) {
      EXPECT_TRUE(backend->device_info().gpu_timestamps);  // lavapipe has timestamps: On takes them
    }
    const TextureHandle input = backend->create_texture(width, height, TexelFormat::RGBA32F);
    backend->upload(input, texels.data(), texels.size() * sizeof(float));
    const PassHandle pass = test::create_copy_pass(*backend);
    std::vector<uint32_t>& out = outputs[made++];
    out.assign(count, 0u);
    const PassTiming t = backend->run_pass(pass, std::span(&input, 1), scale, width, count, out);
    EXPECT_GT(t.gpu_ms, 0.0);
    EXPECT_GE(t.wall_ms, t.gpu_ms * (backend->device_info().gpu_timestamps ? 0.0 : 1.0));
    // A raster pass on the same clock: one triangle (index 0) over the whole view, seen from the
    // origin down -z.
    const float vertices[] = {-10, -10, -1, 1, 10, -10, -1, 1, 0, 10, -1, 1};
    const RasterView view{{0, 0, 0, 0}, {1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, -1, 0}, {0.25f, 1, 0.1f, 100}};
    std::vector<uint32_t>& raster = rasters[made - 1];
    raster.assign(size_t(width) * height, 0u);
    const PassTiming r = backend->run_raster(vertices, view, width, height, raster);
    EXPECT_GT(r.gpu_ms, 0.0);
    EXPECT_EQ(raster[size_t(height / 2) * width + width / 2] & 0xFFFFFFu, 1u);
    // A raster started ahead and finished after the caller's own 20 ms of work: on the CPU's clock
    // its time runs from its submission (an upper bound), never only the caller's last wait.
    backend->start_raster(vertices, view, width, height);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    std::vector<uint32_t> later(size_t(width) * height);
    const PassTiming ahead = backend->finish_raster(later);
    EXPECT_EQ(later, raster);
    if (!backend->device_info().gpu_timestamps) {
      EXPECT_GE(ahead.gpu_ms, 20.0);
    }
    backend->destroy(pass);
    backend->destroy(input);
    const std::vector<std::string> messages = backend->take_debug_messages();
    EXPECT_TRUE(messages.empty()) << test::join(messages);
  }
  EXPECT_EQ(outputs[0], outputs[1]);
  EXPECT_EQ(rasters[0], rasters[1]);
  // The default on lavapipe, a CPU device: the CPU's clock.
  const std::unique_ptr<Backend> by_default = create_vulkan_backend(test::validated_options());
  if (by_default->device_info().is_software) {
    EXPECT_FALSE(by_default->device_info().gpu_timestamps);
  }
}

TEST_F(VulkanBackendTest, CopyPassTiming400x240) {
  const uint32_t width = 400, count = 400 * 240;
  std::vector<float> texels(size_t(count) * 4, 0.25f);
  const TextureHandle input = backend->create_texture(width, 240, TexelFormat::RGBA32F);
  backend->upload(input, texels.data(), texels.size() * sizeof(float));
  const PassHandle pass = test::create_copy_pass(*backend);
  const float scale[4] = {1, 1, 1, 1};
  std::vector<uint32_t> out(count);
  const PassTiming first = backend->run_pass(pass, std::span(&input, 1), scale, width, count, out);
  std::vector<double> gpu, readback, wall;
  for (int i = 0; i < 30; ++i) {
    const PassTiming t = backend->run_pass(pass, std::span(&input, 1), scale, width, count, out);
    EXPECT_EQ(t.upload_ms, 0.0);
    gpu.push_back(t.gpu_ms);
    readback.push_back(t.readback_ms);
    wall.push_back(t.wall_ms);
  }
  std::printf("400x240 copy pass: upload %.2f ms (first pass), median of 30: gpu %.3f ms, readback %.3f ms, "
              "wall %.3f ms\n", first.upload_ms, median(gpu), median(readback), median(wall));
  EXPECT_GT(first.upload_ms, 0.0);
  EXPECT_GT(median(gpu), 0.0);
  backend->destroy(pass);
  backend->destroy(input);
}

}  // namespace
}  // namespace mobirt
