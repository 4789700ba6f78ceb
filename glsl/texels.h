// C++ only: the texels and uniforms of layout.h read and written by name, so that no C++ code
// indexes a texel by position. Each struct is the texel's memory layout (uploaded as it is) and is
// checked against layout.h's sizes and component numbers; the node texel, which means different
// things in leaves and interior nodes, has accessor functions over its glm::vec4 instead.
// GLSL reads the same texels by layout.h's component numbers (n[MOBIRT_NODE_AXIS] is n.b).
#pragma once

#ifndef __cplusplus
#error "texels.h is C++ only: GLSL uses layout.h's component numbers"
#endif

#include <glm/glm.hpp>

#include <cstddef>
#include <cstdint>
#include <span>
#include <type_traits>

#include "layout.h"

namespace mobirt {

static_assert(sizeof(glm::vec4) == 16, "one RGBA32F texel is a glm::vec4");

// ---- kd-tree node (MOBIRT_BIND_NODES) ---------------------------------------------------------
namespace node_texel {

inline bool is_leaf(const glm::vec4& n) { return n[MOBIRT_NODE_AXIS] == float(MOBIRT_NODE_LEAF); }

// Interior nodes. The "below" child is the next node.
inline float split(const glm::vec4& n) { return n[MOBIRT_NODE_SPLIT]; }
inline float axis(const glm::vec4& n) { return n[MOBIRT_NODE_AXIS]; }  // 0, 1, 2
inline float above_child(const glm::vec4& n) { return n[MOBIRT_NODE_ABOVE_CHILD]; }
inline float& above_child(glm::vec4& n) { return n[MOBIRT_NODE_ABOVE_CHILD]; }
inline float empty_flags(const glm::vec4& n) { return n[MOBIRT_NODE_EMPTY_FLAGS]; }
inline bool below_empty(const glm::vec4& n) {
  return empty_flags(n) == MOBIRT_NODE_BELOW_EMPTY ||
         empty_flags(n) == MOBIRT_NODE_BELOW_EMPTY + MOBIRT_NODE_ABOVE_EMPTY;
}
inline bool above_empty(const glm::vec4& n) { return empty_flags(n) >= MOBIRT_NODE_ABOVE_EMPTY; }
inline void set_empty_flags(glm::vec4& n, bool below_is_empty, bool above_is_empty) {
  n[MOBIRT_NODE_EMPTY_FLAGS] = (below_is_empty ? MOBIRT_NODE_BELOW_EMPTY : 0.0f) +
                               (above_is_empty ? MOBIRT_NODE_ABOVE_EMPTY : 0.0f);
}
// No empty-child flags (mark_empty_children sets them).
inline glm::vec4 interior(float split_position, float above_child_index, float split_axis) {
  glm::vec4 n(0.0f);
  n[MOBIRT_NODE_SPLIT] = split_position;
  n[MOBIRT_NODE_ABOVE_CHILD] = above_child_index;
  n[MOBIRT_NODE_AXIS] = split_axis;
  return n;
}

// Leaves: `first` is the leaf's first entry in the leaf-primitive array (leaf_prim_texel).
inline float leaf_first(const glm::vec4& n) { return n[MOBIRT_LEAF_FIRST]; }
inline float& leaf_first(glm::vec4& n) { return n[MOBIRT_LEAF_FIRST]; }
inline float leaf_count(const glm::vec4& n) { return n[MOBIRT_LEAF_COUNT]; }
inline glm::vec4 leaf(float first, float count) {
  glm::vec4 n(0.0f);
  n[MOBIRT_LEAF_FIRST] = first;
  n[MOBIRT_LEAF_COUNT] = count;
  n[MOBIRT_NODE_AXIS] = float(MOBIRT_NODE_LEAF);
  return n;
}

}  // namespace node_texel

// ---- Triangles (MOBIRT_BIND_TRIANGLES): MOBIRT_TEXELS_PER_TRIANGLE texels per primitive --------
namespace triangle_texel {

inline glm::vec4 vertex_texel(const glm::vec3& v) { return glm::vec4(v, 0.0f); }  // w unused
// The first of the primitive's texels in the triangle array.
inline const glm::vec4* of(std::span<const glm::vec4> triangles, int32_t prim) {
  return triangles.data() + static_cast<size_t>(prim) * MOBIRT_TEXELS_PER_TRIANGLE;
}
inline glm::vec3 vertex(std::span<const glm::vec4> triangles, int32_t prim, int k) {
  return glm::vec3(of(triangles, prim)[k]);
}
// The primitive's kind (MOBIRT_PRIM_*: a triangle, or an analytic shape of src/core/shapes.h,
// which writes its texels).
inline float kind(const glm::vec4* texels) { return texels[0][MOBIRT_PRIM_KIND]; }

}  // namespace triangle_texel

// ---- Leaf primitives (MOBIRT_BIND_LEAF_PRIMS): MOBIRT_TEXELS_PER_TRIANGLE texels per entry ---
namespace leaf_prim_texel {

// The first of entry `entry`'s texels: a copy of its primitive's triangle texels.
inline const glm::vec4* of(std::span<const glm::vec4> leaf_prims, size_t entry) {
  return leaf_prims.data() + entry * MOBIRT_TEXELS_PER_TRIANGLE;
}
// The entry's primitive index (an exact float in the texels).
inline float prim(const glm::vec4* texels) {
  return texels[MOBIRT_LEAF_PRIM_INDEX_TEXEL][MOBIRT_LEAF_PRIM_INDEX];
}
// Writes the entry: the primitive's texels, then its index.
inline void write(glm::vec4* out, const glm::vec4* triangle_texels, int32_t prim_index) {
  for (int k = 0; k < MOBIRT_TEXELS_PER_TRIANGLE; ++k) out[k] = triangle_texels[k];
  out[MOBIRT_LEAF_PRIM_INDEX_TEXEL][MOBIRT_LEAF_PRIM_INDEX] = static_cast<float>(prim_index);
}

}  // namespace leaf_prim_texel

// ---- Materials (MOBIRT_BIND_MATERIALS) ----------------------------------------------------------
struct MaterialTexels {
  glm::vec3 diffuse;  // texel 0
  float texture;      //   index into the atlas, -1 = none
  glm::vec3 specular;  // texel 1
  float shininess;
  float reflectance;  // texel 2
  float transmittance;
  float ior;
  float ambient;
};
static_assert(sizeof(MaterialTexels) == MOBIRT_TEXELS_PER_MATERIAL * sizeof(glm::vec4));
static_assert(std::is_standard_layout_v<MaterialTexels>);
static_assert(offsetof(MaterialTexels, texture) == 3 * sizeof(float) &&
              offsetof(MaterialTexels, specular) == sizeof(glm::vec4) &&
              offsetof(MaterialTexels, reflectance) == 2 * sizeof(glm::vec4));

// ---- Shading-pass hit inputs (MOBIRT_BIND_HIT_POSITION, _NORMAL, _TEXCOORD), one per ray --------
struct HitPositionTexel {
  glm::vec3 position;
  float material;  // < 0: a miss, shaded with the background
  static HitPositionTexel miss() { return {glm::vec3(0.0f), -1.0f}; }
};
struct HitNormalTexel {
  glm::vec3 normal;   // unit shading normal facing the incoming ray
  float shadow_mask;  // bit i set when light i is visible
};
struct HitTexcoordTexel {
  glm::vec2 texcoord;
  glm::vec2 unused;
};
static_assert(sizeof(HitPositionTexel) == sizeof(glm::vec4) && sizeof(HitNormalTexel) == sizeof(glm::vec4) &&
              sizeof(HitTexcoordTexel) == sizeof(glm::vec4));
static_assert(offsetof(HitPositionTexel, material) == MOBIRT_HIT_MATERIAL * sizeof(float) &&
              offsetof(HitNormalTexel, shadow_mask) == MOBIRT_HIT_SHADOW_MASK * sizeof(float));

// ---- Uniforms (vec4 arrays at binding 0) --------------------------------------------------------
// Traversal pass, MOBIRT_TP_VEC4S_PER_LIGHT vec4 per light from MOBIRT_TP_LIGHTS.
struct TraceLightParams {
  glm::vec3 where;  // position (point, spot) or the direction towards the light (directional)
  float type;       // MOBIRT_LIGHT_*
  glm::vec3 spot_direction;
  float cos_outer;
};
static_assert(sizeof(TraceLightParams) == MOBIRT_TP_VEC4S_PER_LIGHT * sizeof(glm::vec4));

// Shading pass, MOBIRT_SP_VEC4S_PER_LIGHT vec4 per light from MOBIRT_SP_LIGHTS.
struct ShadeLightParams {
  glm::vec3 where;  // as TraceLightParams::where
  float type;
  glm::vec3 radiance;  // colour x intensity
  float range;         // 0 = unlimited
  glm::vec3 spot_direction;
  float cos_inner;
  float cos_outer;
  float unused[3];
};
static_assert(sizeof(ShadeLightParams) == MOBIRT_SP_VEC4S_PER_LIGHT * sizeof(glm::vec4));

// Shading pass, MOBIRT_SP_VEC4S_PER_TEXTURE vec4 per atlas tile from MOBIRT_SP_TEXTURES(lights).
struct AtlasTileParams {
  glm::vec2 origin;  // in its page's texels: the tile's first texel, inside its gutter
  glm::vec2 size;
  float wrap_s;      // MOBIRT_WRAP_*
  float wrap_t;
  float page;
  float unused;
};
static_assert(sizeof(AtlasTileParams) == MOBIRT_SP_VEC4S_PER_TEXTURE * sizeof(glm::vec4));

// ---- Compute pass output (MOBIRT_BIND_HIT_RECORDS): one wide hit record per ray --------------
struct HitRecord {
  float t;
  float u, v;               // barycentric weights of v1 and v2
  float unused;
  uint32_t prim_plus_one;   // 0 = miss
  uint32_t mask;            // shadow bits, bit i = light i visible
  uint32_t shadow_rays;     // shadow rays the pass cast for this hit
  uint32_t flags;           // MOBIRT_HIT_CAPPED, MOBIRT_HIT_NO_BARYCENTRICS

  bool hit() const { return prim_plus_one != 0; }
  int32_t prim() const { return int32_t(prim_plus_one) - 1; }
  bool capped() const { return (flags & MOBIRT_HIT_CAPPED) != 0; }
};
static_assert(sizeof(HitRecord) == MOBIRT_HIT_RECORD_BYTES && std::is_trivially_copyable_v<HitRecord>);

// The pages get the texture units that the shading pass's data textures leave (one binding each).
static_assert(MOBIRT_ATLAS_MAX_PAGES == MOBIRT_MAX_SAMPLED_TEXTURES - MOBIRT_SHADE_DATA_TEXTURES);
static_assert(MOBIRT_ATLAS_MAX_TEXTURES == MOBIRT_ATLAS_MAX_PAGES * MOBIRT_ATLAS_TILES_PER_PAGE);
static_assert(MOBIRT_BIND_ATLAS_PAGE_2 == MOBIRT_BIND_ATLAS_PAGE_0 + MOBIRT_ATLAS_MAX_PAGES - 1);
static_assert((MOBIRT_ATLAS_SURE_TILE + 2 * MOBIRT_ATLAS_GUTTER) * 4 == MOBIRT_ATLAS_SIZE && MOBIRT_ATLAS_TILES_PER_PAGE == 16);

// The largest passes fit the uniform array.
static_assert(MOBIRT_TP_LIGHTS + MOBIRT_TP_VEC4S_PER_LIGHT * MOBIRT_MAX_LIGHTS <= MOBIRT_MAX_PARAM_VEC4S);
static_assert(MOBIRT_SP_TEXTURES(MOBIRT_MAX_LIGHTS) + MOBIRT_SP_VEC4S_PER_TEXTURE * MOBIRT_ATLAS_MAX_TEXTURES <=
              MOBIRT_MAX_PARAM_VEC4S);

}  // namespace mobirt
