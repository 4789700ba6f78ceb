#version 460
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_ray_query : require
// The ray-query peer's traversal pass (src/baseline/ray_query_engine.h): the same inputs and the
// same output texel as glsl/trace.frag, with the driver's own acceleration structure and ray/triangle
// test instead of mobirt's kd-tree. One fragment per ray: closest hit, then one shadow ray per light,
// cast exactly as traverse.glsl's shadow_mask_of() casts them (offset.glsl); writes ONE RGBA8 texel
// (packing.glsl). It breaks the OpenGL ES 2.0 constraints on purpose: the scene is an acceleration
// structure, not textures (shader_constraints.h lists what it breaks). Compiled for Vulkan 1.2
// (SPIR-V 1.5: SPV_KHR_ray_query needs 1.4). PRECISION stays highp: the driver's test has no fp16.
#include "prelude_vk.glsl"
#include "offset.glsl"
#include "packing.glsl"

// The acceleration structure takes the slot of the kd-tree's nodes; the other slots are the
// traversal pass's (glsl/layout.h).
#define MOBIRT_BIND_SCENE_AS MOBIRT_BIND_NODES
layout(set = 0, binding = MOBIRT_BIND_SCENE_AS) uniform accelerationStructureEXT u_scene;
SAMPLER(MOBIRT_BIND_TRIANGLES, u_triangles);
SAMPLER(MOBIRT_BIND_RAY_ORIGIN, u_ray_origin);
SAMPLER(MOBIRT_BIND_RAY_DIRECTION, u_ray_direction);

// A ray the driver may be given: finite origin and direction, 0 <= tmin <= tmax, no NaN (Vulkan's
// rules for OpRayQueryInitializeKHR). mobirt's traversal treats any other ray as a miss.
bool valid_ray(vec3 o, vec3 d, float tmin, float tmax) {
  return !any(isnan(o)) && !any(isinf(o)) && !any(isnan(d)) && !any(isinf(d)) && tmin >= 0.0 && tmin <= tmax;
}

// Any hit in [tmin, tmax]: the driver stops at the first one it accepts.
bool occluded(vec3 o, vec3 d, float tmin, float tmax) {
  if (!valid_ray(o, d, tmin, tmax)) return false;
  rayQueryEXT q;
  rayQueryInitializeEXT(q, u_scene, gl_RayFlagsOpaqueEXT | gl_RayFlagsTerminateOnFirstHitEXT, 0xFF, o, tmin, d, tmax);
  while (rayQueryProceedEXT(q)) {
  }
  return rayQueryGetIntersectionTypeEXT(q, true) != gl_RayQueryCommittedIntersectionNoneEXT;
}

// traverse.glsl's shadow_mask_of() with its kd-tree walk replaced by occluded(): the same hit point,
// offset origin, light tests and bits. (traverse.glsl's own copy calls its traverse() directly, so
// it cannot be included here; keep the two in step.)
float shadow_mask(float prim, vec3 o, vec3 d, float t) {
  float mask = 0.0;
  if (LIGHT_COUNT == 0) return mask;
  float base = prim * float(MOBIRT_TEXELS_PER_TRIANGLE);
  vec3 v0 = DATA_TEXEL(u_triangles, base).xyz;
  vec3 e1 = DATA_TEXEL(u_triangles, base + 1.0).xyz - v0;
  vec3 e2 = DATA_TEXEL(u_triangles, base + 2.0).xyz - v0;
  vec3 ng = cross(e1, e2);
  vec3 p = OFFSET_MODE == MOBIRT_OFFSET_NORMAL_ULP ? point_on_triangle(v0, e1, e2, o, d) : o + t * d;
  float view_side = dot(ng, d) < 0.0 ? 1.0 : -1.0;
  vec3 n = (view_side / max(length(ng), 1e-30)) * ng;
  vec3 origin = offset_origin(p, n, PARAM(MOBIRT_TP_BOUNDS_LO).w);
  float bit = 1.0;
  for (int l = 0; l < LIGHT_COUNT; ++l) {
    vec4 light = PARAM(MOBIRT_TP_LIGHTS + MOBIRT_TP_VEC4S_PER_LIGHT * l);
    vec4 spot = PARAM(MOBIRT_TP_LIGHTS + MOBIRT_TP_VEC4S_PER_LIGHT * l + 1);
    bool directional = light.w == MOBIRT_LIGHT_DIRECTIONAL;
    vec3 to_light = directional ? light.xyz : light.xyz - origin;
    float tmax = directional ? 3.0e38 : 1.0;
    bool lit = light.w != MOBIRT_LIGHT_NONE && dot(ng, to_light) * view_side > 0.0;
    if (lit && light.w == MOBIRT_LIGHT_SPOT) {
      lit = dot(normalize(-to_light), spot.xyz) > spot.w;
    }
    if (lit && !occluded(origin, to_light, 0.0, tmax)) mask = mask + bit;
    bit = bit * 2.0;
  }
  return mask;
}

void main() {
  vec4 origin = RAY_TEXEL(u_ray_origin);        // xyz, tmin
  vec4 direction = RAY_TEXEL(u_ray_direction);  // xyz, tmax
  if (!valid_ray(origin.xyz, direction.xyz, origin.w, direction.w)) {
    OUTPUT(pack_trace(0.0, 0.0));
    return;
  }
  rayQueryEXT q;
  rayQueryInitializeEXT(q, u_scene, gl_RayFlagsOpaqueEXT, 0xFF, origin.xyz, origin.w, direction.xyz, direction.w);
  while (rayQueryProceedEXT(q)) {
  }
  if (rayQueryGetIntersectionTypeEXT(q, true) == gl_RayQueryCommittedIntersectionNoneEXT) {
    OUTPUT(pack_trace(0.0, 0.0));
    return;
  }
  // One geometry in one instance: the primitive index is the triangle's index in Scene::mesh.
  float prim = float(rayQueryGetIntersectionPrimitiveIndexEXT(q, true));
  float t = rayQueryGetIntersectionTEXT(q, true);
  OUTPUT(pack_trace(prim + 1.0, shadow_mask(prim, origin.xyz, direction.xyz, t)));
}
