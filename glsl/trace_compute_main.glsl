// main() of the compute engine's traversal pass, shared by glsl/trace_compute.comp (scene data in
// storage buffers) and glsl/trace_compute_texel_buffers.comp (in uniform texel buffers).
#include "traverse.glsl"

layout(local_size_x = MOBIRT_COMPUTE_GROUP_SIZE) in;

layout(std430, set = 0, binding = MOBIRT_BIND_RAY_ORIGIN) readonly buffer RayOrigins { vec4 ray_origin[]; };  // xyz, tmin
layout(std430, set = 0, binding = MOBIRT_BIND_RAY_DIRECTION) readonly buffer RayDirections { vec4 ray_direction[]; };  // xyz, tmax

struct HitRecord {
  vec4 tuv;   // t, u, v, 0
  uvec4 hit;  // primitive + 1 (0 = miss), shadow mask, shadow rays cast, MOBIRT_HIT_* flags
};
layout(std430, set = 0, binding = MOBIRT_BIND_HIT_RECORDS) writeonly buffer HitRecords { HitRecord records[]; };

layout(push_constant) uniform Dispatch {
  uint ray_count;
};

void main() {
  const uint i = gl_GlobalInvocationID.x;
  if (i >= ray_count) return;
  vec4 origin = ray_origin[i];
  vec4 direction = ray_direction[i];
  // Under mediump the ray is rounded to fp16 once, before the walk (precision.glsl).
  origin.xyz = mp(origin.xyz);
  direction.xyz = mp(direction.xyz);
  vec3 hit = traverse(origin.xyz, direction.xyz, origin.w, direction.w, false);
  HitRecord r;
  r.tuv = vec4(0.0);
  r.hit = uvec4(0u);
  if (hit.z > 0.5) {
    r.hit.w = MOBIRT_HIT_CAPPED;
  } else if (hit.x >= 0.0) {
    float rays_cast;
    float mask = shadow_mask_counted(hit.x, origin.xyz, direction.xyz, hit.y, rays_cast);
    // The barycentrics from the same test on the one triangle the walk found.
    vec3 tuv = intersect_triangle_tuv(hit.x, origin.xyz, direction.xyz, origin.w, direction.w);
    r.tuv = vec4(hit.y, tuv.y, tuv.z, 0.0);
    r.hit = uvec4(uint(hit.x) + 1u, mask < 0.0 ? 0u : uint(mask), uint(rays_cast),
                  mask < 0.0 ? MOBIRT_HIT_CAPPED : (tuv.x < 0.0 ? MOBIRT_HIT_NO_BARYCENTRICS : 0u));
  }
  records[i] = r;
}
