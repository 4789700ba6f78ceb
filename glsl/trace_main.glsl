// main() of the traversal pass, shared by glsl/trace.frag (Vulkan) and glsl/es/trace.frag (GLES).
// One fragment per ray: closest hit, then one shadow ray per light; writes ONE RGBA8 texel: hit
// index + 1 and the shadow mask (glsl/layout.h).
#include "traverse.glsl"
#include "packing.glsl"

// Per-ray data, read as the scene data is: 2D textures, or buffers where the prelude says so.
DATA_SAMPLER(MOBIRT_BIND_RAY_ORIGIN, u_ray_origin);
DATA_SAMPLER(MOBIRT_BIND_RAY_DIRECTION, u_ray_direction);

void main() {
  vec4 origin = RAY_TEXEL(u_ray_origin);     // xyz, tmin
  vec4 direction = RAY_TEXEL(u_ray_direction);  // xyz, tmax
  // Under mediump the ray is rounded to fp16 once, before the walk (precision.glsl).
  origin.xyz = mp(origin.xyz);
  direction.xyz = mp(direction.xyz);
  vec3 hit;
  // The hit primitive's texels where main() read them (where the raster's triangle stands: its
  // test's hit, or its plane's), so that the shadow rays do not fetch them again: 3 of a raster
  // pass's 20-40 fetches a group of 8 fragments.
  vec4 tri0 = vec4(0.0), tri1 = vec4(0.0), tri2 = vec4(0.0);
  bool tri_read = false;
  if (PRIMARY_HITS != 0) {
    // --primary raster: the raster pass found the ray's closest triangle, its index + 1 in the
    // direction's w (0: none covers the pixel's centre; the ray's tmax is infinite). Only that
    // triangle is tested, for the hit point the shadow rays start from. Where this test misses it
    // (the pixel centre on an edge, rounded the other way) the ray walks the tree as usual; in a
    // frame without a kd-tree (its shadow rays all test light buffers: frame_walks_tree) the
    // rasterizer's choice stands, as it does in a frame without shadow rays: t from the
    // triangle's plane (the CPU's decoding clamps the barycentrics into the triangle, surface_hit).
    float prim = direction.w - 1.0;
    if (PRIMARY_HITS == MOBIRT_PRIMARY_HITS_WALK && direction.w < 0.0) {
      // MOBIRT_HIT_UNKNOWN: a ray of the same pass whose closest primitive no raster found (the
      // other rays of a generation whose mirror rays were drawn, --mirrors) walks as without
      // PRIMARY_HITS, its tmax infinite.
      hit = traverse(origin.xyz, direction.xyz, origin.w, 3.0e38, false);
    } else {
      if (prim < 0.0) {
        OUTPUT(pack_trace(0.0, 0.0));
        return;
      }
      float base = prim * float(MOBIRT_TEXELS_PER_TRIANGLE);
      tri0 = DATA_TEXEL(u_triangles, base);
      tri1 = DATA_TEXEL(u_triangles, base + 1.0);
      tri2 = DATA_TEXEL(u_triangles, base + 2.0);
      vec3 v0 = tri0.xyz;
      vec3 v1 = tri1.xyz;
      vec3 v2 = tri2.xyz;
      vec3 tuv = intersect_triangle_texels(v0, v1, v2, origin.xyz, direction.xyz, origin.w, 3.0e38);
      if (tuv.x >= 0.0) {
        hit = vec3(prim, tuv.x, 0.0);
        tri_read = true;
      } else if (PRIMARY_HITS == MOBIRT_PRIMARY_HITS_PLANE) {
        vec3 ng = cross(v1 - v0, v2 - v0);
        float denom = dot(ng, direction.xyz);
        float t = mp(denom != 0.0 ? dot(ng, v0 - origin.xyz) / denom : origin.w);
        hit = vec3(prim, t >= origin.w ? t : origin.w, 0.0);
        tri_read = true;
      } else {
        hit = traverse(origin.xyz, direction.xyz, origin.w, 3.0e38, false);
      }
    }
  } else {
    hit = traverse(origin.xyz, direction.xyz, origin.w, direction.w, false);
  }
  if (hit.z > 0.5) {
    OUTPUT(pack_capped());
    return;
  }
  if (hit.x < 0.0) {
    OUTPUT(pack_trace(0.0, 0.0));
    return;
  }
  // A hit the walk found: its texels read here (on Vulkan a branch, KEEP_BRANCH: a group whose
  // lanes all kept the raster's triangle skips the three fetch calls).
  KEEP_BRANCH if (!tri_read) {
    float base = hit.x * float(MOBIRT_TEXELS_PER_TRIANGLE);
    tri0 = DATA_TEXEL(u_triangles, base);
    tri1 = DATA_TEXEL(u_triangles, base + 1.0);
    tri2 = DATA_TEXEL(u_triangles, base + 2.0);
  }
  float rays_cast;
  float mask = shadow_mask_of(tri0, tri1, tri2, origin.xyz, direction.xyz, hit.y, rays_cast);
  OUTPUT(mask < 0.0 ? pack_capped() : pack_trace(hit.x + 1.0, mask));
}
