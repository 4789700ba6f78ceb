// Coherent secondary rays: a generation reordered before it is packed, so that the 8 lanes of each
// SIMD group of the traversal pass (a 4x2 tile of the ray textures, rays.h) walk the same nodes.
//
// next_generation() emits rays in the order of their parents, a glass hit's mirror ray right
// beside its refracted ray: one tile then holds rays going opposite ways, and llvmpipe runs every
// loop until the tile's slowest lane is done. Sorted by direction octant, then by the Morton code
// of the origin inside the scene box, a tile holds rays that start close together and point the
// same way.
#pragma once

#include <cstdint>
#include <vector>

#include "core/geometry.h"
#include "raytree/rays.h"

namespace mobirt {

// The sort key of a ray: its direction octant (3 bits, sign of x, y, z) above the 21-bit Morton
// code of its origin quantised to 128 steps per axis of `bounds` (origins outside are clamped).
// (512 steps sorted no better and cost a third radix pass.)
uint32_t ray_order_key(const glm::vec3& origin, const glm::vec3& direction, const Aabb& bounds);

// The order in which a batch's rays are packed: out[k] = the index of the k-th ray, ascending
// ray_order_key, ties in their original order (stable). A permutation of 0..count-1.
std::vector<uint32_t> coherent_ray_order(const RayBatch& batch, const Aabb& bounds);

// The share of consecutive rays (in batch order) whose direction octants differ: about 0.5 where
// every hit makes a mirror and a refracted ray, near 0 for the mirror rays of a floor.
float octant_change_rate(const RayBatch& batch);

// order_for_traversal sorts only a batch whose octant_change_rate reaches this: a batch made in
// a coherent order (its parents' tiles) keeps it, because the sort then costs more than the few
// traversal steps it saves (toaster, marbles: 1-4 % fewer node-loop iterations; fish: 14-24 %).
// The sort's cost, keys, radix passes and the sorted gather (mobirt_microbench
// OrderRays/fish/coherent:1 minus coherent:0, 2 cores): about 18 ns a ray with the radix passes
// on one core, 12 ns on all cores with the keys from a table (session 19, alternated runs).
inline constexpr float kSortAboveOctantChanges = 0.1f;

// Reorders the batch by coherent_ray_order and then lays it out in SIMD tiles
// (order_in_simd_tiles): the one call the renderer makes before tracing a secondary generation.
// A batch whose octant_change_rate is below sort_above is only tiled (0: always sorted, for
// measurements). Every ray keeps its pixel and weight, so the image is the same.
void order_for_traversal(RayBatch& batch, const Aabb& bounds, float sort_above = kSortAboveOctantChanges);

}  // namespace mobirt
