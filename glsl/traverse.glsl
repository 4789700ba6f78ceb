// kd-tree traversal with a short stack (Horn et al. 2007) that falls back to kd-restart (Foley and
// Sugerman 2005) when the stack runs dry, Möller-Trumbore or watertight intersection, shadow rays.
//
// The same algorithm as src/accel/kdtree_traverse.cpp, step for step, so that the CPU traversal
// is an oracle for this shader. Written in the common subset of GLSL 450 and GLSL ES 1.00: no
// integer bit operations, no `%`; the walk's loops are UNBOUNDED_LOOP, which ES bounds by the cap
// MAX_STEPS (its loops need constant bounds) and GLSL 450 does not (the cap is checked inside).
//
// Needs from the prelude: DATA_TEXEL, DATA_ROWS, DATA_TEXEL_ROWS, PARAM, STACK_DEPTH, MAX_STEPS,
// LIGHT_COUNT, INTERSECT, PRECISION, OFFSET_MODE, PRECISE, add_float_bits, UNBOUNDED_LOOP,
// STACK_COUNTED, LEAF_CLOSE_IN_NODE, KEEP_BRANCH, KEEP_BRANCH_PAD and precision.glsl (mp, mp_cross,
// mp_dot).
#include "offset.glsl"
#include "light_buffer.glsl"

// Scene data: 2D textures, or texel buffers where the prelude says so (DATA_SAMPLER).
#ifndef DATA_SAMPLER
#define DATA_SAMPLER(slot, name) SAMPLER(slot, name)
#endif
DATA_SAMPLER(MOBIRT_BIND_NODES, u_nodes);
DATA_SAMPLER(MOBIRT_BIND_LEAF_PRIMS, u_leaf_prims);
DATA_SAMPLER(MOBIRT_BIND_TRIANGLES, u_triangles);

// traverse()'s short stack is 16 vec4 of two entries each (s0 .. s15): the C++ refuses deeper
// stacks against MOBIRT_MAX_STACK_DEPTH, so the two must change together.
#if MOBIRT_MAX_STACK_DEPTH != 32
#error the short stack s0 to s15 holds 32 entries: MOBIRT_MAX_STACK_DEPTH must be 32
#endif

// The ray/triangle test, by INTERSECT and PRECISION (specialization constants, glsl/layout.h):
// the CPU mirror, operation for operation, is src/accel/kdtree_traverse.cpp. Each returns t of a
// hit in [tmin, tmax], else -1; comparisons are written so that NaN rejects. Under mediump mp()
// rounds the vertices and every intermediate result to fp16; the ray arrives rounded. Each returns
// (t, u, v), u and v the barycentric weights of v1 and v2 as the CPU's test computes them: the
// traversal reads t alone (the rest folds away), the compute pass's wide hit record all three.

// Möller-Trumbore (1997).
vec3 intersect_mt(vec3 a, vec3 b, vec3 c, vec3 o, vec3 d, float tmin, float tmax) {
  vec3 v0 = mp(a);
  vec3 e1 = mp(mp(b) - v0);
  vec3 e2 = mp(mp(c) - v0);
  vec3 p = mp(mp_cross(d, e2));
  float det = mp(mp_dot(e1, p));
  if (!(det != 0.0)) return vec3(-1.0);
  float inv_det = mp(1.0 / det);
  vec3 s = mp(o - v0);
  float u = mp(mp(mp_dot(s, p)) * inv_det);
  if (!(u >= 0.0 && u <= 1.0)) return vec3(-1.0);
  // v's numerator as -(s.(d x e1)), u's products: exact negations across a fan's shared edge
  // v0-v2, so no ray slips between the two triangles (src/accel/kdtree_traverse.cpp).
  vec3 r = mp(mp_cross(d, e1));
  float v = mp(-mp(mp_dot(s, r)) * inv_det);
  if (!(v >= 0.0 && mp(u + v) <= 1.0)) return vec3(-1.0);
  vec3 q = mp(mp_cross(s, e1));
  float t = mp(mp(mp_dot(e2, q)) * inv_det);
  return (t >= tmin && t <= tmax) ? vec3(t, u, v) : vec3(-1.0);
}

// The axis permutation (kx, ky, kz) of the watertight test, applied to v: kz is the largest
// component of |d|, and kx, ky swap when d points down kz, to keep the winding.
vec3 watertight_permute(vec3 v, vec3 d) {
  vec3 ad = abs(d);
  vec3 r = v;  // kz = z: (x, y, z)
  if (ad.x >= ad.y && ad.x >= ad.z) {
    r = v.yzx;  // kz = x
  } else if (ad.y >= ad.z) {
    r = v.zxy;  // kz = y
  }
  return r;
}

// Woop, Benthin and Wald, "Watertight Ray/Triangle Intersection" (JCGT 2013), in single precision:
// the vertices relative to the origin, sheared so that the ray runs along +z, then 2D edge
// functions. Each edge function depends only on its edge's two vertices and the triangle across a
// shared edge computes exactly its negation, so a ray through an edge or a vertex meets at least
// one triangle there. The paper's retry in double for edge functions of exactly 0 is left out: 0 is accepted on both
// sides instead.
vec3 intersect_watertight(vec3 v0, vec3 v1, vec3 v2, vec3 o, vec3 d, float tmin, float tmax) {
  vec3 pd = watertight_permute(d, d);
  bool flip = pd.z < 0.0;
  if (flip) pd = pd.yxz;
  float sx = mp(pd.x / pd.z);
  float sy = mp(pd.y / pd.z);
  float sz = mp(1.0 / pd.z);
  vec3 a = watertight_permute(mp(mp(v0) - o), d);
  vec3 b = watertight_permute(mp(mp(v1) - o), d);
  vec3 c = watertight_permute(mp(mp(v2) - o), d);
  if (flip) {
    a = a.yxz;
    b = b.yxz;
    c = c.yxz;
  }
  // Columns: x, y and z of the three vertices; then sheared. The products are PRECISE: a product
  // fused into the subtraction that follows would round differently from the CPU's, and, in the
  // edge functions, differently from the neighbouring triangle's.
  vec3 pz = vec3(a.z, b.z, c.z);
  PRECISE vec3 shear_x = sx * pz;
  PRECISE vec3 shear_y = sy * pz;
  vec3 x = mp(vec3(a.x, b.x, c.x) - mp(shear_x));
  vec3 y = mp(vec3(a.y, b.y, c.y) - mp(shear_y));
  // The edge functions of edges bc, ca, ab: the weights of a, b, c times det.
  PRECISE vec3 edge_plus = x.zxy * y.yzx;
  PRECISE vec3 edge_minus = y.zxy * x.yzx;
  vec3 uvw = mp(mp(edge_plus) - mp(edge_minus));
  if ((uvw.x < 0.0 || uvw.y < 0.0 || uvw.z < 0.0) && (uvw.x > 0.0 || uvw.y > 0.0 || uvw.z > 0.0)) return vec3(-1.0);
  float det = mp(mp(uvw.x + uvw.y) + uvw.z);
  if (!(det != 0.0)) return vec3(-1.0);
  float big_t = mp(mp_dot(uvw, mp(sz * pz)));
  float inv_det = mp(1.0 / det);
  float t = mp(big_t * inv_det);
  return (t >= tmin && t <= tmax) ? vec3(t, mp(uvw.y * inv_det), mp(uvw.z * inv_det)) : vec3(-1.0);
}

// (t, u, v) of a hit in [tmin, tmax], else t = -1.
vec3 intersect_triangle_texels(vec3 v0, vec3 v1, vec3 v2, vec3 o, vec3 d, float tmin, float tmax) {
  if (INTERSECT == MOBIRT_INTERSECT_WATERTIGHT) return intersect_watertight(v0, v1, v2, o, d, tmin, tmax);
  return intersect_mt(v0, v1, v2, o, d, tmin, tmax);
}

// The same for primitive `prim` of the triangle array.
vec3 intersect_triangle_tuv(float prim, vec3 o, vec3 d, float tmin, float tmax) {
  float base = prim * float(MOBIRT_TEXELS_PER_TRIANGLE);
  return intersect_triangle_texels(DATA_TEXEL(u_triangles, base).xyz, DATA_TEXEL(u_triangles, base + 1.0).xyz,
                                   DATA_TEXEL(u_triangles, base + 2.0).xyz, o, d, tmin, tmax);
}

// Analytic primitives (glsl/layout.h, MOBIRT_PRIM_*; src/core/shapes.h), compiled only for scenes
// that have them (ANALYTIC). The CPU mirror, operation for operation, is intersect_shape() in
// src/accel/kdtree_traverse.cpp.

// The first root of a t^2 + 2 b t + c = 0 in [tmin, tmax], else the second, else -1, given the
// quarter discriminant disc = b^2 - a c >= 0. q = -(b + sign(b) sqrt(disc)) loses no digits to
// cancellation, and its roots c / q and q / a hold for a = 0 (the linear case: q / a is infinite).
// `z0 + t zd` in [0, h] bounds each root along an axis (spheres pass an interval that always holds).
float first_root(float a, float b, float c, float disc, float tmin, float tmax, float z0, float zd, float h) {
  float q = mp(-mp(b + (b >= 0.0 ? 1.0 : -1.0) * mp(sqrt(disc))));
  float r0 = mp(c / q);
  float r1 = mp(q / a);
  bool swap = r1 < r0;
  float first = swap ? r1 : r0;
  float second = swap ? r0 : r1;
  float z_first = mp(z0 + mp(first * zd));
  float z_second = mp(z0 + mp(second * zd));
  if (first >= tmin && first <= tmax && z_first >= 0.0 && z_first <= h) return first;
  return (second >= tmin && second <= tmax && z_second >= 0.0 && z_second <= h) ? second : -1.0;
}

// A sphere: |o + t d - c|^2 = r^2 with the discriminant in the form of Haines et al. (Ray Tracing
// Gems, ch. 7), r^2 - |f - (b / a) d|^2 with f = o - c, which stays accurate for distant spheres.
float intersect_sphere(vec4 t0, vec4 t1, vec3 o, vec3 d, float tmin, float tmax) {
  vec3 f = mp(o - mp(t0.xyz));
  float r = mp(t1.x);
  float a = mp(mp_dot(d, d));
  float b = mp(mp_dot(f, d));
  vec3 g = mp(f - mp(mp(b / a) * d));
  float rr = mp(r * r);
  float disc = mp(a * mp(rr - mp(mp_dot(g, g))));
  if (!(disc >= 0.0)) return -1.0;
  float c = mp(mp(mp_dot(f, f)) - rr);
  return first_root(a, b, c, disc, tmin, tmax, 0.0, 0.0, 1.0);
}

// An open truncated cone: base b, unit axis k, height h, radius(z) = r0 + s z for z in [0, h].
// In the axis frame the ray's height is zo + t zd and its radial offset ro + t rd; the surface is
// |ro + t rd|^2 = (r0 + s (zo + t zd))^2.
float intersect_cone(vec4 t0, vec4 t1, vec4 t2, vec3 o, vec3 d, float tmin, float tmax) {
  vec3 k = mp(t1.xyz);
  float h = mp(t1.w);
  float r0 = mp(t2.x);
  float s = mp(t2.y);
  vec3 w = mp(o - mp(t0.xyz));
  float zo = mp(mp_dot(w, k));
  float zd = mp(mp_dot(d, k));
  vec3 ro = mp(w - mp(zo * k));
  vec3 rd = mp(d - mp(zd * k));
  float ra = mp(r0 + mp(s * zo));  // the radius at the origin's height
  float sz = mp(s * zd);
  float a = mp(mp(mp_dot(rd, rd)) - mp(sz * sz));
  float b = mp(mp(mp_dot(ro, rd)) - mp(ra * sz));
  float c = mp(mp(mp_dot(ro, ro)) - mp(ra * ra));
  float disc = mp(mp(b * b) - mp(a * c));
  if (!(disc >= 0.0)) return -1.0;
  return first_root(a, b, c, disc, tmin, tmax, zo, zd, h);
}

// Any primitive: a triangle, or (ANALYTIC) a sphere or a cone, by the kind in its first texel.
float intersect_primitive(vec4 t0, vec4 t1, vec4 t2, vec3 o, vec3 d, float tmin, float tmax) {
  if (ANALYTIC != 0) {
    if (t0.w == MOBIRT_PRIM_SPHERE) return intersect_sphere(t0, t1, o, d, tmin, tmax);
    if (t0.w == MOBIRT_PRIM_CONE) return intersect_cone(t0, t1, t2, o, d, tmin, tmax);
  }
  return intersect_triangle_texels(t0.xyz, t1.xyz, t2.xyz, o, d, tmin, tmax).x;
}

// The (unnormalised) geometric normal of an analytic primitive at p, outwards: a sphere's p - c;
// a cone's radial offset tilted against the slope, radial - s |radial| k.
vec3 analytic_normal(vec4 t0, vec4 t1, vec4 t2, vec3 p) {
  vec3 w = p - t0.xyz;
  if (t0.w == MOBIRT_PRIM_SPHERE) return w;
  vec3 radial = w - dot(w, t1.xyz) * t1.xyz;
  return radial - (t2.y * length(radial)) * t1.xyz;
}

// Slab test against the scene box; returns (t0, t1), empty when t0 > t1.
vec2 intersect_scene_box(vec3 o, vec3 inv_d, float tmin, float tmax) {
  vec3 lo = PARAM(MOBIRT_TP_BOUNDS_LO).xyz;
  vec3 hi = PARAM(MOBIRT_TP_BOUNDS_HI).xyz;
  vec3 ta = (lo - o) * inv_d;
  vec3 tb = (hi - o) * inv_d;
  vec3 tn = min(ta, tb);
  vec3 tf = max(ta, tb);
  // A NaN (origin on a slab with a zero direction component) must not shrink the interval:
  // comparisons with NaN are false, so it keeps the previous bound, as on the CPU.
  float t0 = tmin;
  float t1 = tmax;
  if (tn.x > t0) t0 = tn.x;
  if (tn.y > t0) t0 = tn.y;
  if (tn.z > t0) t0 = tn.z;
  if (tf.x < t1) t1 = tf.x;
  if (tf.y < t1) t1 = tf.y;
  if (tf.z < t1) t1 = tf.z;
  return vec2(t0, t1);
}

float component(vec3 v, float axis) {
  return axis < 0.5 ? v.x : (axis < 1.5 ? v.y : v.z);
}

// The stack entry at index `slot` (0 = newest) after a push: kept where the stack has that slot,
// else dropped (zeros, which read as empty).
vec2 inside_stack(int slot, vec2 entry) {
  return slot < STACK_DEPTH ? entry : vec2(0.0);
}

// Result of one traversal: x = primitive index (-1 = miss), y = t, z = 1 when the loop cap stopped
// it before it could decide (the CPU then traces the ray itself).
// any_hit: stop at the first hit in [tmin, tmax] (shadow rays).
vec3 traverse(vec3 o, vec3 d, float ray_tmin, float ray_tmax, bool any_hit) {
  vec3 inv_d = 1.0 / d;
  vec2 box = intersect_scene_box(o, inv_d, ray_tmin, ray_tmax);
  // The node loop's 1 / d, with -inf for both zeros: then inv_a < 0 says d_a <= 0, so d is not
  // needed there. Every split decision stays the same: a zero component gives tsplit = +-inf
  // (near side only either way) or NaN (near side only).
  vec3 inv_s = vec3(d.x == 0.0 ? -inv_d.x * inv_d.x : inv_d.x, d.y == 0.0 ? -inv_d.y * inv_d.y : inv_d.y,
                    d.z == 0.0 ? -inv_d.z * inv_d.z : inv_d.z);
  if (!(box.x <= box.y)) return vec3(-1.0, ray_tmax, 0.0);
  // The data textures' row scale (ES; nothing on Vulkan), read once rather than at every fetch.
  float node_rows = DATA_ROWS(u_nodes);
  float entry_rows = DATA_ROWS(u_leaf_prims);
  float scene_tmax = box.y;
  float tmin = box.x;
  float tmax = box.y;

  // The short stack: entries (node, tmax), newest first, two per vec4: s0.xy, s0.zw, s1.xy, ...
  // A shift register in named variables, not an array: llvmpipe keeps an array that is indexed
  // with a variable in memory and reads and writes it lane by lane (about 50 scalar loads, stores
  // and branches per access, on every step, whether or not a lane pushes), and does not unroll
  // loops, so only constant names stay in registers. Shifting drops the oldest entry when the
  // stack is full, as a ring would. An entry's tmin is the tmax in force when it is popped (the
  // near side always ends where the far side begins), so it is not stored.
  vec4 s0 = vec4(0.0), s1 = vec4(0.0), s2 = vec4(0.0), s3 = vec4(0.0), s4 = vec4(0.0), s5 = vec4(0.0),
       s6 = vec4(0.0), s7 = vec4(0.0), s8 = vec4(0.0), s9 = vec4(0.0), s10 = vec4(0.0), s11 = vec4(0.0),
       s12 = vec4(0.0), s13 = vec4(0.0), s14 = vec4(0.0), s15 = vec4(0.0);
  // Vulkan keeps no count of the entries: an entry's node is never the root (a far child follows
  // its parent), so the stack is empty exactly when s0.x is 0, the zeros a pop shifts in. One
  // value fewer live across the node fetch's call: -2.6 % of the passes' JIT instructions. The ES
  // path counts them (STACK_COUNTED): measured there, without the count it ran 2.4 % more
  // (toaster, 200x120, depth 2, tools/profile/jit_instructions.sh; +3.7 % once the push was a
  // branch). Its fetches are calls too on Mesa 25.0.7 (tools/profile/jit_dump.sh), so the reason
  // lies elsewhere in what llvmpipe makes of the ES loop.
#if STACK_COUNTED
  int size = 0;
#endif

  float node = 0.0;
  float best_t = 3.4e38;  // hits are accepted anywhere in [ray_tmin, ray_tmax]
  // kd-restart progress: a restart at the same point as the previous one sends ties to the far
  // side, so that restarts always move forward (see src/accel/kdtree_traverse.cpp).
  float restart_t = box.x;
  float best_prim = -1.0;
  // The steps of src/accel/kdtree_traverse.cpp: one per interior node, one per triangle test,
  // one per empty leaf (a leaf's node fetch shares the step of its first triangle test).
  int steps = 0;
  // The leaf just walked must be closed (done, pop or restart) before the next node. Vulkan
  // (LEAF_CLOSE_IN_NODE) says so with a node of -1, so that no flag of its own is live across the
  // node fetch's call: -0.9 % of the fish's JIT instructions (2 bounces), -0.15 % of the
  // toaster's. ES keeps the flag: measured there, the node's selects cost more (+0.5 %).
  bool leaf_done = false;

  // Loops nested the way llvmpipe runs them cheaply (Aila and Laine's while-while). llvmpipe runs
  // an `if` under a lane mask, skipping it only when no lane of the SIMD group takes it (the
  // compiler turns small ones into selects that always run, unless marked KEEP_BRANCH or, on ES,
  // padded with KEEP_BRANCH_PAD), and a loop until the last of the 8 lanes of a group is done. One
  // loop with a node step and a triangle test in each iteration paid for both (four texel fetches
  // and the intersection) on every step, when 3 in 4 steps are interior nodes. Here an iteration
  // of the inner node loop costs one node fetch, one of the triangle loop one triangle test.
  UNBOUNDED_LOOP(leaf, MAX_STEPS) {
    // Down to the next leaf with primitives, one node per iteration; empty leaves are closed on
    // the way.
    float leaf_first = 0.0;
    float leaf_count = 0.0;  // > 0: the lane stands at a leaf with primitives
    UNBOUNDED_LOOP(i, MAX_STEPS) {
      if (LEAF_CLOSE_IN_NODE != 0 ? node < 0.0 : leaf_done) {
        leaf_done = false;
        if (best_t <= tmax) return vec3(best_prim, best_t, 0.0);
#if STACK_COUNTED
        if (size > 0) {
          size = size - 1;
#else
        if (s0.x > 0.0) {
#endif
          node = s0.x;
          tmin = tmax;
          tmax = s0.y;
          s0 = vec4(s0.zw, s1.xy);
          if (STACK_DEPTH > 2) s1 = vec4(s1.zw, s2.xy);
          if (STACK_DEPTH > 4) s2 = vec4(s2.zw, s3.xy);
          if (STACK_DEPTH > 6) s3 = vec4(s3.zw, s4.xy);
          if (STACK_DEPTH > 8) s4 = vec4(s4.zw, s5.xy);
          if (STACK_DEPTH > 10) s5 = vec4(s5.zw, s6.xy);
          if (STACK_DEPTH > 12) s6 = vec4(s6.zw, s7.xy);
          if (STACK_DEPTH > 14) s7 = vec4(s7.zw, s8.xy);
          if (STACK_DEPTH > 16) s8 = vec4(s8.zw, s9.xy);
          if (STACK_DEPTH > 18) s9 = vec4(s9.zw, s10.xy);
          if (STACK_DEPTH > 20) s10 = vec4(s10.zw, s11.xy);
          if (STACK_DEPTH > 22) s11 = vec4(s11.zw, s12.xy);
          if (STACK_DEPTH > 24) s12 = vec4(s12.zw, s13.xy);
          if (STACK_DEPTH > 26) s13 = vec4(s13.zw, s14.xy);
          if (STACK_DEPTH > 28) s14 = vec4(s14.zw, s15.xy);
          if (STACK_DEPTH > 30) s15 = vec4(s15.zw, 0.0, 0.0);
        } else if (tmax >= scene_tmax) {
          return vec3(best_prim, best_t, 0.0);
        } else {
          // kd-restart: everything before tmax is done; walk down again from the root.
          // A restart at the previous restart point sends ties at tmin to the far side until the
          // next pop or skipped near side (the CPU's `strict`): here tmin one ulp up, so that
          // `tsplit < tmin` holds for tsplit equal to the restart point, as `tsplit < tmin ||
          // (strict && tsplit == tmin)` does, and no loop-carried flag is needed (-3.2 to -3.4 %
          // of the Vulkan passes' JIT instructions, -1.8 % on ES). Only for tmax > 0: a tsplit
          // <= 0 is near only anyway.
          tmin = tmax == restart_t && tmax > 0.0 ? add_float_bits(tmax, 1.0) : tmax;
          restart_t = tmax;
          tmax = scene_tmax;
          node = 0.0;
        }
      }
      vec4 n = DATA_TEXEL_ROWS(u_nodes, node_rows, node);
      bool leaf = n.b == MOBIRT_NODE_LEAF;
      if (leaf && n.g > 0.0) {
        leaf_first = n.r;
        leaf_count = n.g;
        break;
      }
      if (steps >= MAX_STEPS) return vec3(best_prim, best_t, 1.0);
      steps = steps + 1;
      // An interior node, or an empty leaf (closed at the start of the next iteration). Empty
      // children flagged in the node are closed without a visit (src/accel/kdtree_traverse.cpp):
      // an empty near side when the ray also crosses into the far side, an empty only side. Written
      // as selects: every assignment in a loop costs llvmpipe a blend per component.
      float split = n.r;
      float oa = component(o, n.b);
      float inv_a = component(inv_s, n.b);
      float tsplit = (split - oa) * inv_a;
      bool below_first = oa < split || (oa == split && inv_a < 0.0);
      bool below_empty = n.a == MOBIRT_NODE_BELOW_EMPTY || n.a == MOBIRT_NODE_BELOW_EMPTY + MOBIRT_NODE_ABOVE_EMPTY;
      bool above_empty = n.a >= MOBIRT_NODE_ABOVE_EMPTY;
      bool near_empty = below_first ? below_empty : above_empty;
      bool far_empty = below_first ? above_empty : below_empty;
      bool near_only = tsplit > tmax || tsplit <= 0.0 || tsplit != tsplit;
      bool far_only = !near_only && tsplit < tmin;
      bool both = !leaf && !near_only && !far_only;
      bool skip_near = both && near_empty;
      bool push = both && !near_empty;
      bool below = below_first != (far_only || skip_near);
      float next = below ? node + 1.0 : n.g;
      float far_child = below_first ? n.g : node + 1.0;
      bool closing = leaf || (near_only && near_empty) || (far_only && far_empty) || (skip_near && far_empty);
      node = LEAF_CLOSE_IN_NODE != 0 ? (closing ? -1.0 : next) : (leaf ? node : next);
      tmin = skip_near ? tsplit : tmin;
      leaf_done = closing;
      // KEEP_BRANCH (Vulkan): a real branch, which a SIMD group skips when none of its lanes
      // pushes. Without it the compiler turns this small `if` into selects, and every node step
      // paid a select, a blend under the loop's mask and a store for each stack component. -6.7 to
      // -7.6 % of the Vulkan passes' JIT instructions, the time within noise (x1.01 in two
      // interleaved A/B runs). ES has no attribute: KEEP_BRANCH_PAD gives the body the size at
      // which Mesa's GL front end leaves it a branch (prelude_es.glsl), -3.4 to -4.0 % of the ES
      // passes' JIT instructions. The pop, behind the `if`s above, is a branch already.
      KEEP_BRANCH if (STACK_DEPTH > 0 && push) {
        // Push (the far child, tmax): entry j moves to j + 1, and one that lands at STACK_DEPTH or
        // beyond is dropped (an odd depth's last vec4 keeps no entry in its zw). The guards fold
        // away with the constant STACK_DEPTH.
        if (STACK_DEPTH > 30) s15 = vec4(s14.zw, inside_stack(31, s15.xy));
        if (STACK_DEPTH > 28) s14 = vec4(s13.zw, inside_stack(29, s14.xy));
        if (STACK_DEPTH > 26) s13 = vec4(s12.zw, inside_stack(27, s13.xy));
        if (STACK_DEPTH > 24) s12 = vec4(s11.zw, inside_stack(25, s12.xy));
        if (STACK_DEPTH > 22) s11 = vec4(s10.zw, inside_stack(23, s11.xy));
        if (STACK_DEPTH > 20) s10 = vec4(s9.zw, inside_stack(21, s10.xy));
        if (STACK_DEPTH > 18) s9 = vec4(s8.zw, inside_stack(19, s9.xy));
        if (STACK_DEPTH > 16) s8 = vec4(s7.zw, inside_stack(17, s8.xy));
        if (STACK_DEPTH > 14) s7 = vec4(s6.zw, inside_stack(15, s7.xy));
        if (STACK_DEPTH > 12) s6 = vec4(s5.zw, inside_stack(13, s6.xy));
        if (STACK_DEPTH > 10) s5 = vec4(s4.zw, inside_stack(11, s5.xy));
        if (STACK_DEPTH > 8) s4 = vec4(s3.zw, inside_stack(9, s4.xy));
        if (STACK_DEPTH > 6) s3 = vec4(s2.zw, inside_stack(7, s3.xy));
        if (STACK_DEPTH > 4) s2 = vec4(s1.zw, inside_stack(5, s2.xy));
        if (STACK_DEPTH > 2) s1 = vec4(s0.zw, inside_stack(3, s1.xy));
        // A push needs 0 < tsplit <= tmax: tmax is a number above 0, KEEP_BRANCH_PAD's domain.
        s0 = vec4(far_child, KEEP_BRANCH_PAD(tmax), inside_stack(1, s0.xy));
#if STACK_COUNTED
        if (size < STACK_DEPTH) size = size + 1;  // a full stack dropped its oldest entry
#endif
      }
      tmax = push ? tsplit : tmax;
    }
    // The leaf's triangles, one test per iteration. (Only lanes that reached a leaf: Mesa 22.3's
    // llvmpipe ended loops on its own and may have ended the node loop early; 25.0's does not,
    // README *Loop cap*.) The entries' texels run from base to leaf_end, exact integers (below
    // kKdIndexLimit, 2^24): no loop index, and no multiply per triangle. The leaf's steps are
    // counted before its tests, and its tests end where the steps left to the cap do (the walk
    // then returns capped after them, below): the tests and the result of a step-by-step count,
    // with no count updated across the loop's three fetch calls (-1.1 % of the fish's JIT
    // instructions at 2 bounces on Vulkan, -1.9 % on ES).
    float base = leaf_first * float(MOBIRT_TEXELS_PER_TRIANGLE);
    float leaf_end = min(base + leaf_count * float(MOBIRT_TEXELS_PER_TRIANGLE),
                         base + float(MAX_STEPS - steps) * float(MOBIRT_TEXELS_PER_TRIANGLE));
    steps = steps + int(leaf_count);
    UNBOUNDED_LOOP(k, MAX_STEPS) {
      if (base >= leaf_end) break;
      // The leaf entry: a copy of the primitive's texels, its index in the third one's w.
      vec4 t0 = DATA_TEXEL_ROWS(u_leaf_prims, entry_rows, base);
      vec4 t1 = DATA_TEXEL_ROWS(u_leaf_prims, entry_rows, base + 1.0);
      vec4 t2 = DATA_TEXEL_ROWS(u_leaf_prims, entry_rows, base + 2.0);
      base = base + float(MOBIRT_TEXELS_PER_TRIANGLE);
      float prim = t2[MOBIRT_LEAF_PRIM_INDEX];
      float t = intersect_primitive(t0, t1, t2, o, d, ray_tmin, ray_tmax);
      // Ties in t go to the lower primitive index, so they do not depend on the test order.
      if (t >= 0.0 && (t < best_t || (t == best_t && prim < best_prim))) {
        best_t = t;
        best_prim = prim;
        if (any_hit) return vec3(best_prim, best_t, 0.0);
      }
    }
    if (steps > MAX_STEPS) return vec3(best_prim, best_t, 1.0);
    if (leaf_count > 0.0) {
      // The leaf's close begins here: a hit within its interval ends the walk at once. Left to
      // the node loop's next iteration (which closes it all the same), the group ran that
      // iteration, its node fetch and one more triangle-loop iteration for lanes that were done.
      if (best_t <= tmax) return vec3(best_prim, best_t, 0.0);
      leaf_done = true;
      if (LEAF_CLOSE_IN_NODE != 0) node = -1.0;
    }
  }
  // The cap, or (Mesa 22.3's llvmpipe) the driver's own loop limit, ended the walk before it could
  // decide.
  return vec3(best_prim, best_t, 1.0);
}

// Whether the segment from `origin` to `light` meets a triangle of light l's light buffer cell
// (src/accel/light_buffer.cpp's light_buffer_occluded, the same cell, list, parts and test): 1.0
// yes, 0.0 no, -1.0 the step cap ended the list first. `to_light` = light - origin as the walk gets
// it.
float light_buffer_occluded(int l, vec3 origin, vec3 to_light) {
  vec4 head = PARAM(MOBIRT_TP_LIGHT_BUFFERS + l);
  vec3 dir = -to_light;
  vec3 a = abs(dir);
  float face;
  vec3 f;
  if (a.x >= a.y && a.x >= a.z) {
    face = dir.x >= 0.0 ? 0.0 : 1.0;
    f = dir.x >= 0.0 ? vec3(-dir.z, -dir.y, dir.x) : vec3(dir.z, -dir.y, -dir.x);
  } else if (a.y >= a.z) {
    face = dir.y >= 0.0 ? 2.0 : 3.0;
    f = dir.y >= 0.0 ? vec3(dir.x, dir.z, dir.y) : vec3(dir.x, -dir.z, -dir.y);
  } else {
    face = dir.z >= 0.0 ? 4.0 : 5.0;
    f = dir.z >= 0.0 ? vec3(dir.x, -dir.y, dir.z) : vec3(-dir.x, -dir.y, -dir.z);
  }
  vec4 w = DATA_TEXEL(u_nodes, head.x - float(MOBIRT_LIGHT_BUFFER_WINDOWS) + face);
  float res = head.y;
  float x = (f.x / f.z - w.x) * w.z;
  float y = (f.y / f.z - w.y) * w.w;
  if (!(x >= 0.0 && y >= 0.0 && x < res && y < res)) return 0.0;
  float cx = floor(x);
  float cy = floor(y);
  vec4 cell = DATA_TEXEL(u_nodes, head.x + (face * res + cy) * res + cx);
  // The ray's column and row of the cell's MOBIRT_LIGHT_BUFFER_SUBCELLS (exact: x - floor(x) and
  // its product with a power of two), against each entry's part of the cell (layout.h).
  const float S = float(MOBIRT_LIGHT_BUFFER_SUBCELLS);
  float sx = floor((x - cx) * S);
  float sy = floor((y - cy) * S);
  float base = cell.r * float(MOBIRT_TEXELS_PER_TRIANGLE);
  float end = base + cell.g * float(MOBIRT_TEXELS_PER_TRIANGLE);
  // Past the segment's end (a little beyond, for the rounding of its length) no triangle meets it.
  float reach = length(to_light) * (1.0 + 1e-4);
  float entry_rows = DATA_ROWS(u_leaf_prims);  // read once (traverse())
  int steps = 0;
  // An entry's first texel holds its near and its part (layout.h): a ray that stops there or skips
  // the triangle reads nothing else. Light buffers hold triangles only (no analytic primitives:
  // src/render/renderer.cpp).
  UNBOUNDED_LOOP(k, MAX_STEPS + 1) {
    if (base >= end) break;
    if (steps >= MAX_STEPS) return -1.0;
    steps = steps + 1;
    vec4 t0 = DATA_TEXEL_ROWS(u_leaf_prims, entry_rows, base);
    if (t0.x > reach) break;
    float entry = base;
    base = base + float(MOBIRT_TEXELS_PER_TRIANGLE);
    KEEP_BRANCH if (light_buffer_part_contains(t0.y, sx, sy)) {
      vec4 t1 = DATA_TEXEL_ROWS(u_leaf_prims, entry_rows, entry + 1.0);
      vec4 t2 = DATA_TEXEL_ROWS(u_leaf_prims, entry_rows, entry + 2.0);
      vec3 v0 = vec3(t0.zw, t1.x);
      if (intersect_triangle_texels(v0, t1.yzw, t2.xyz, origin, to_light, 0.0, 1.0).x >= 0.0) return 1.0;
    }
  }
  return 0.0;
}

// The shadow mask of a hit: bit i set when light i is visible. Lights behind the surface as seen
// from the ray and points outside a spot's outer cone get no shadow ray: they cannot light it.
// Returns -1.0 when a shadow ray hit the loop cap. rays_cast: the shadow rays it cast (the compute
// pass's hit record counts them; the fragment passes leave it to the CPU). t0, t1, t2: the hit
// primitive's texels of u_triangles, passed in so that a caller that read them already (the
// raster's hits in trace_main.glsl) does not fetch them twice; shadow_mask_counted fetches them.
float shadow_mask_of(vec4 t0, vec4 t1, vec4 t2, vec3 o, vec3 d, float t, out float rays_cast) {
  float mask = 0.0;
  rays_cast = 0.0;
  if (LIGHT_COUNT == 0) return mask;
  vec3 v0 = t0.xyz;
  vec3 e1 = t1.xyz - v0;
  vec3 e2 = t2.xyz - v0;
  vec3 ng = cross(e1, e2);
  vec3 p = mp(OFFSET_MODE == MOBIRT_OFFSET_NORMAL_ULP ? point_on_triangle(v0, e1, e2, o, d) : o + t * d);
  // An analytic primitive: the point on the ray (every offset mode), the surface's normal there.
  if (ANALYTIC != 0 && t0.w != MOBIRT_PRIM_TRIANGLE) {
    p = mp(o + t * d);
    ng = analytic_normal(t0, t1, t2, p);
  }
  float view_side = dot(ng, d) < 0.0 ? 1.0 : -1.0;
  // The origin off the surface, on the viewer's side (offset.glsl); under mediump the shadow ray
  // is rounded as the primary rays are.
  vec3 n = (view_side / max(length(ng), 1e-30)) * ng;
  vec3 origin = mp(offset_origin(p, n, PARAM(MOBIRT_TP_BOUNDS_LO).w));
  float bit = 1.0;
  // Mesa 22.3's lavapipe ended a shader's loops silently once they ran 65,535 iterations in all
  // (llvmpipe's LP_MAX_TGSI_LOOP_ITERATIONS; 25.0's does not: VulkanBackendTest.SpinHonoursTheCap
  // tells which model a driver follows), so completion is counted rather than assumed: a light
  // loop that was cut short reports the ray as capped, and the CPU traces it.
  int lights_done = 0;
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
    if (lit) {
      rays_cast = rays_cast + 1.0;
      if (LIGHT_BUFFERS != 0 && PARAM(MOBIRT_TP_LIGHT_BUFFERS + l).z > 0.5) {
        float occluded = light_buffer_occluded(l, origin, mp(to_light));
        if (occluded < 0.0) return -1.0;
        if (occluded < 0.5) mask = mask + bit;
      } else {
        vec3 r = traverse(origin, mp(to_light), 0.0, tmax, true);
        if (r.z > 0.5) return -1.0;
        if (r.x < 0.0) mask = mask + bit;
      }
    }
    bit = bit * 2.0;
    lights_done = lights_done + 1;
  }
  return lights_done == LIGHT_COUNT ? mask : -1.0;
}

float shadow_mask_counted(float prim, vec3 o, vec3 d, float t, out float rays_cast) {
  float base = prim * float(MOBIRT_TEXELS_PER_TRIANGLE);
  return shadow_mask_of(DATA_TEXEL(u_triangles, base), DATA_TEXEL(u_triangles, base + 1.0),
                        DATA_TEXEL(u_triangles, base + 2.0), o, d, t, rays_cast);
}
