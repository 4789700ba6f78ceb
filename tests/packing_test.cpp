// The traversal pass's output texel: packing round trips at the limits of both variants, the
// capped-ray signal, and the choice of packing for a scene.
#include <gtest/gtest.h>

#include "core/error.h"
#include "raytree/packing.h"

namespace mobirt {
namespace {

TEST(Packing, RoundTrip24x8AtTheLimits) {
  for (uint32_t index : {0u, 1u, 2u, 255u, 256u, 65535u, 65536u, 16777214u, 16777215u}) {
    for (uint32_t mask : {0u, 1u, 0x80u, 0xFFu}) {
      if (index == 0 && mask != 0) continue;  // a miss carries no shadow bits
      const TraceTexel t = unpack_trace(Packing::Bits24_8, pack_trace(Packing::Bits24_8, index, mask));
      EXPECT_EQ(t.prim_plus_one, index);
      EXPECT_EQ(t.mask, mask);
      EXPECT_FALSE(t.capped);
    }
  }
  EXPECT_EQ(MOBIRT_MAX_PRIMS_24_8, (1u << 24) - 1);
}

TEST(Packing, RoundTrip16x16AtTheLimits) {
  for (uint32_t index : {0u, 1u, 255u, 256u, 65534u, 65535u}) {
    for (uint32_t mask : {0u, 1u, 0x8000u, 0xFFFFu}) {
      if (index == 0 && mask != 0) continue;
      const TraceTexel t = unpack_trace(Packing::Bits16_16, pack_trace(Packing::Bits16_16, index, mask));
      EXPECT_EQ(t.prim_plus_one, index);
      EXPECT_EQ(t.mask, mask);
    }
  }
  // All 16 lights visible: every mask bit survives.
  EXPECT_EQ(unpack_trace(Packing::Bits16_16, pack_trace(Packing::Bits16_16, 7, 0xFFFF)).mask, 0xFFFFu);
  EXPECT_EQ(MOBIRT_MAX_LIGHTS_16_16, 16);
}

TEST(Packing, ByteOrderMatchesTheShader) {
  // glsl/packing.glsl writes r = low byte of index + 1, a = mask; RGBA8 reads back little-endian.
  const uint32_t texel = pack_trace(Packing::Bits24_8, 0x123456u, 0xA5u);
  EXPECT_EQ(texel & 0xFFu, 0x56u);
  EXPECT_EQ((texel >> 8) & 0xFFu, 0x34u);
  EXPECT_EQ((texel >> 16) & 0xFFu, 0x12u);
  EXPECT_EQ(texel >> 24, 0xA5u);
  const uint32_t t16 = pack_trace(Packing::Bits16_16, 0xBEEFu, 0x1234u);
  EXPECT_EQ(t16 & 0xFFFFu, 0xBEEFu);
  EXPECT_EQ(t16 >> 16, 0x1234u);
}

TEST(Packing, CappedSignalIsIndexZeroWithMask) {
  for (Packing p : {Packing::Bits24_8, Packing::Bits16_16}) {
    const TraceTexel t = unpack_trace(p, pack_capped(p));
    EXPECT_TRUE(t.capped);
    EXPECT_FALSE(t.hit());
    EXPECT_FALSE(unpack_trace(p, pack_trace(p, 0, 0)).capped);  // a plain miss is not capped
  }
}

TEST(Packing, ChoosesTheSmallestPackingThatHolds) {
  EXPECT_EQ(choose_packing(1000, 1, "s"), Packing::Bits24_8);
  EXPECT_EQ(choose_packing(MOBIRT_MAX_PRIMS_24_8, 8, "s"), Packing::Bits24_8);
  EXPECT_EQ(choose_packing(1000, 9, "s"), Packing::Bits16_16);
  EXPECT_EQ(choose_packing(MOBIRT_MAX_PRIMS_16_16, 16, "s"), Packing::Bits16_16);
}

TEST(Packing, RefusesScenesOverTheLimits) {
  auto expect_error = [](uint64_t prims, int lights, const char* fragment) {
    try {
      choose_packing(prims, lights, "scene.gltf");
      FAIL() << "accepted " << prims << " prims and " << lights << " lights";
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::BadInput);
      EXPECT_NE(std::string(e.what()).find("scene.gltf"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
  };
  expect_error(uint64_t(MOBIRT_MAX_PRIMS_24_8) + 1, 1, "24-bit");
  expect_error(MOBIRT_MAX_PRIMS_16_16 + 1, 9, "16/16");
  expect_error(10, 17, "17 lights");
}

// decode_colour's table gives what dividing each byte by 255 gives, bit for bit, in every
// channel, and ignores the alpha byte.
TEST(Packing, ColourDecodingIsTheByteOver255) {
  for (uint32_t b = 0; b < 256; ++b) {
    const float expected = float(b) / 255.0f;
    const glm::vec3 c = decode_colour(b | ((255u - b) << 8) | ((b ^ 0x5Au) << 16) | (b << 24));
    ASSERT_EQ(c.x, expected) << b;
    ASSERT_EQ(c.y, float(255u - b) / 255.0f) << b;
    ASSERT_EQ(c.z, float(b ^ 0x5Au) / 255.0f) << b;
  }
  EXPECT_EQ(decode_colour(0xFFFFFFFFu), glm::vec3(1.0f));
  EXPECT_EQ(decode_colour(0xFF000000u), glm::vec3(0.0f));
}

}  // namespace
}  // namespace mobirt
