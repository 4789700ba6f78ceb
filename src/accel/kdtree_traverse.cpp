// CPU traversal of the flattened kd-tree: the oracle for glsl/traverse.glsl, which follows it step
// for step.
//
// Algorithm (Horn et al. 2007 short stack, falling back to Foley and Sugerman 2005 kd-restart):
//   [t0, t1] = slab test of the root box (intersect_aabb) clipped to [ray.tmin, ray.tmax];
//   miss if empty (or if the tree's box is empty).
//   scene_tmax = t1, tmin = t0, tmax = t1, node = root, inv = 1 / dir,
//   restart_t = t0, strict = false.
//   interior node (split s, axis a, empty-child flags):
//     tsplit = (s - o[a]) * inv[a]
//     below_first = o[a] < s || (o[a] == s && d[a] <= 0)   (near = below_first ? below : above)
//     if (tsplit > tmax || tsplit <= 0 || isnan(tsplit))      near only:  close if near is empty,
//                                                                         else node = near
//     else if (tsplit < tmin || (strict && tsplit == tmin))  far only:   close if far is empty,
//                                                                         else node = far
//     else if (near empty)           { tmin = tsplit; strict = false;
//                                      close if far is empty, else node = far }
//     else { push(far, tsplit, tmax); node = near; tmax = tsplit; }
//   leaf: test its triangles (hits anywhere in [ray.tmin, ray.tmax], not only inside the leaf),
//     then close.
//   close (a leaf, or an empty child, whose interval ends at tmax):
//     if (best_t <= tmax) done
//     else if (stack not empty) { (node, tmin, tmax) = pop newest; strict = false; }
//     else if (tmax >= scene_tmax) done
//     else { strict = (tmax == restart_t); restart_t = tmax;       // kd-restart
//            tmin = tmax; tmax = scene_tmax; node = root; }
//   The stack is a ring of stack_depth entries that overwrites its oldest entry when full; the
//   restart covers whatever was dropped, because dropped entries are always the farthest.
//   A popped entry's tmin is always the tmax in force when it is popped (the near side of a split
//   ends where its far side begins), which lets the shader keep only (node, tmax) per entry.
//
// Empty children (flagged by mark_empty_children) are closed without a visit: the same walk as
// pushing the far child, visiting the empty near leaf (closing it) and popping, or as visiting an
// empty leaf that is the only side, minus the steps and texel fetches of those visits. Skipping
// the empty near leaf also skips its early-out test (best_t <= tsplit), which cannot pass: the
// near side holds no triangle, and a hit before it would have ended the walk earlier. An empty
// far side of a split is pushed and visited as before: walking the near side with the far side's
// tmax instead would widen the interval of every node below it (more nodes and triangles), and
// not pushing it at all would break the (node, tmax) stack above.
//
// Equality cases, and why:
// - tsplit == tmin visits both children (the near one with [tmin, tmin]). Equal t values do not
//   mean the ray meets the plane where the interval starts: two planes one float ulp apart (the
//   SAH likes cutting thin empty slabs off flat walls) round to the same t, and the thin slab
//   between them can hold the wall the ray hits. Sending such rays to the far side only missed
//   real hits on the Utah toasters.
// - That tie rule alone can loop forever under kd-restart: restarting at tmin = t_b (the plane
//   that ended the last leaf) descends again to the near side with [t_b, t_b], reaches a leaf
//   already tested and restarts at t_b again. So a restart that makes no progress (tmax equal to
//   the previous restart point) sets `strict`: ties go to the far side until the next pop, which
//   reaches a leaf that ends beyond t_b. Restart points therefore increase at least every second
//   restart and traversal always terminates (without a step cap). The only cost: with tiny stacks,
//   a second degenerate [t_b, t_b] leaf may be skipped in this tie-of-ties case. (The shader keeps
//   `strict` as tmin = the next float above t_b, where `tsplit < tmin` decides the same.)
// - tsplit == tmax visits both (the far side with [tmax, tmax]): conservative, rare.
// - A ray lying in a split plane (o[a] == s, d[a] == 0) gives tsplit = 0 * inf = NaN: near only,
//   and below_first picks the below side; the builder references every triangle that touches a
//   split plane on both sides, so the below side has everything in the plane.
// - A ray starting on a split plane (o[a] == s, d[a] != 0) gives tsplit = 0: near only, the side
//   the ray goes into (below when d[a] < 0, above when d[a] > 0).
// - Hits: t in [ray.tmin, ray.tmax]; ties in t go to the lower primitive index (closer_hit), the
//   same rule as brute_force(), so ties do not depend on the order of the tests.
#include <glm/glm.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "accel/kdtree.h"
#include "core/error.h"
#include "core/half.h"
#include "layout.h"
#include "texels.h"

namespace mobirt {

namespace {

// The precision of the intersection arithmetic: every intermediate result passes through R.
struct Exact {
  static float r(float x) { return x; }
  static glm::vec3 r(const glm::vec3& v) { return v; }
};
struct Half {
  static float r(float x) { return round_to_half(x); }
  static glm::vec3 r(const glm::vec3& v) { return round_to_half(v); }
};

bool accept(float t, float u, float v, int32_t prim, const Ray& ray, Hit& hit) {
  if (!(t >= ray.tmin && t <= ray.tmax)) return false;
  if (!closer_hit(t, prim, hit)) return false;
  hit.prim = prim;
  hit.t = t;
  hit.u = u;
  hit.v = v;
  return true;
}

// Möller-Trumbore, as glsl/traverse.glsl's intersect_mt().
template <class R>
bool intersect_mt(const glm::vec4* texels, int32_t prim, const Ray& ray, Hit& hit) {
  const glm::vec3 o = R::r(ray.origin), d = R::r(ray.direction);
  const glm::vec3 v0 = R::r(glm::vec3(texels[0]));
  const glm::vec3 e1 = R::r(R::r(glm::vec3(texels[1])) - v0);
  const glm::vec3 e2 = R::r(R::r(glm::vec3(texels[2])) - v0);
  const glm::vec3 p = R::r(glm::cross(d, e2));
  const float det = R::r(glm::dot(e1, p));
  if (det == 0.0f || std::isnan(det)) return false;
  const float inv_det = R::r(1.0f / det);
  const glm::vec3 s = R::r(o - v0);
  const float u = R::r(R::r(glm::dot(s, p)) * inv_det);
  if (!(u >= 0.0f && u <= 1.0f)) return false;
  // v's numerator d.(s x e1) as -(s.(d x e1)): the same products as u's s.(d x e2), so that the
  // triangle (v0, v2, v3) of a fan, whose e1 is this e2, computes exactly the negation of this
  // u on their shared edge v0-v2 and a ray on the edge meets at least one of the two. The
  // textbook form rounds the two differently and let rays through quads' diagonals slip through
  // both triangles (a flat grid seen head-on: ~0.5 % of pixels; kdtree_test, FlatGrids).
  const glm::vec3 r = R::r(glm::cross(d, e1));
  const float v = R::r(-R::r(glm::dot(s, r)) * inv_det);
  if (!(v >= 0.0f && R::r(u + v) <= 1.0f)) return false;
  const glm::vec3 q = R::r(glm::cross(s, e1));
  return accept(R::r(R::r(glm::dot(e2, q)) * inv_det), u, v, prim, ray, hit);
}

// The watertight test of Woop, Benthin and Wald (JCGT 2013) in single precision, as
// glsl/traverse.glsl's intersect_watertight(): the vertices relative to the origin, sheared so that
// the ray runs along +z, then 2D edge functions. Each edge function depends only on its edge's two
// vertices, and the triangle across a shared edge computes exactly its negation (products commute,
// a - b = -(b - a) in floats), so a ray through an edge or a vertex meets at least one of the
// triangles there. The paper's retry in double for edge functions of exactly 0 is left out: an
// edge test of exactly 0 is accepted on both sides instead (the test is inclusive), and the GPU
// has no double.
template <class R>
bool intersect_wt(const glm::vec4* texels, int32_t prim, const Ray& ray, Hit& hit) {
  const glm::vec3 o = R::r(ray.origin), d = R::r(ray.direction);
  const glm::vec3 ad = glm::abs(d);
  const int kz = ad.x >= ad.y && ad.x >= ad.z ? 0 : (ad.y >= ad.z ? 1 : 2);
  int kx = kz == 2 ? 0 : kz + 1;
  int ky = kx == 2 ? 0 : kx + 1;
  if (d[kz] < 0.0f) std::swap(kx, ky);  // keep the winding, so that det keeps its sign
  const float sx = R::r(d[kx] / d[kz]);
  const float sy = R::r(d[ky] / d[kz]);
  const float sz = R::r(1.0f / d[kz]);
  // Columns: the three vertices relative to the origin, then sheared.
  const glm::vec3 a = R::r(R::r(glm::vec3(texels[0])) - o);
  const glm::vec3 b = R::r(R::r(glm::vec3(texels[1])) - o);
  const glm::vec3 c = R::r(R::r(glm::vec3(texels[2])) - o);
  const glm::vec3 px(a[kx], b[kx], c[kx]), py(a[ky], b[ky], c[ky]), pz(a[kz], b[kz], c[kz]);
  const glm::vec3 x = R::r(px - R::r(sx * pz));
  const glm::vec3 y = R::r(py - R::r(sy * pz));
  // (U, V, W): the edge functions of edges bc, ca, ab, i.e. the weights of a, b, c times det.
  const glm::vec3 uvw = R::r(R::r(glm::vec3(x.z, x.x, x.y) * glm::vec3(y.y, y.z, y.x)) -
                             R::r(glm::vec3(y.z, y.x, y.y) * glm::vec3(x.y, x.z, x.x)));
  if ((uvw.x < 0.0f || uvw.y < 0.0f || uvw.z < 0.0f) && (uvw.x > 0.0f || uvw.y > 0.0f || uvw.z > 0.0f)) {
    return false;
  }
  const float det = R::r(R::r(uvw.x + uvw.y) + uvw.z);
  if (det == 0.0f || std::isnan(det)) return false;
  const glm::vec3 z = R::r(sz * pz);
  const float big_t = R::r(glm::dot(uvw, z));
  const float inv_det = R::r(1.0f / det);
  return accept(R::r(big_t * inv_det), R::r(uvw.y * inv_det), R::r(uvw.z * inv_det), prim, ray, hit);
}

// glsl/traverse.glsl's first_root(): the first root of a t^2 + 2 b t + c = 0 in [tmin, tmax] whose
// height z0 + t zd lies in [0, h], else the second, else none (t < 0 returned).
template <class R>
float first_root(float a, float b, float c, float disc, float tmin, float tmax, float z0, float zd, float h) {
  const float q = R::r(-R::r(b + (b >= 0.0f ? 1.0f : -1.0f) * R::r(std::sqrt(disc))));
  const float r0 = R::r(c / q);
  const float r1 = R::r(q / a);
  const bool swap = r1 < r0;
  const float first = swap ? r1 : r0;
  const float second = swap ? r0 : r1;
  const float z_first = R::r(z0 + R::r(first * zd));
  const float z_second = R::r(z0 + R::r(second * zd));
  if (first >= tmin && first <= tmax && z_first >= 0.0f && z_first <= h) return first;
  return second >= tmin && second <= tmax && z_second >= 0.0f && z_second <= h ? second : -1.0f;
}

// glsl/traverse.glsl's intersect_sphere() and intersect_cone(), on the primitive's texels
// (glsl/layout.h). Returns t, or a negative value for no hit in [tmin, tmax].
template <class R>
float intersect_sphere(const glm::vec4* texels, const glm::vec3& o, const glm::vec3& d, float tmin, float tmax) {
  const glm::vec3 f = R::r(o - R::r(glm::vec3(texels[0])));
  const float r = R::r(texels[1].x);
  const float a = R::r(glm::dot(d, d));
  const float b = R::r(glm::dot(f, d));
  const glm::vec3 g = R::r(f - R::r(R::r(b / a) * d));
  const float rr = R::r(r * r);
  const float disc = R::r(a * R::r(rr - R::r(glm::dot(g, g))));
  if (!(disc >= 0.0f)) return -1.0f;
  const float c = R::r(R::r(glm::dot(f, f)) - rr);
  return first_root<R>(a, b, c, disc, tmin, tmax, 0.0f, 0.0f, 1.0f);
}

template <class R>
float intersect_cone(const glm::vec4* texels, const glm::vec3& o, const glm::vec3& d, float tmin, float tmax) {
  const glm::vec3 k = R::r(glm::vec3(texels[1]));
  const float h = R::r(texels[1].w);
  const float r0 = R::r(texels[2].x);
  const float s = R::r(texels[2].y);
  const glm::vec3 w = R::r(o - R::r(glm::vec3(texels[0])));
  const float zo = R::r(glm::dot(w, k));
  const float zd = R::r(glm::dot(d, k));
  const glm::vec3 ro = R::r(w - R::r(zo * k));
  const glm::vec3 rd = R::r(d - R::r(zd * k));
  const float ra = R::r(r0 + R::r(s * zo));
  const float sz = R::r(s * zd);
  const float a = R::r(R::r(glm::dot(rd, rd)) - R::r(sz * sz));
  const float b = R::r(R::r(glm::dot(ro, rd)) - R::r(ra * sz));
  const float c = R::r(R::r(glm::dot(ro, ro)) - R::r(ra * ra));
  const float disc = R::r(R::r(b * b) - R::r(a * c));
  if (!(disc >= 0.0f)) return -1.0f;
  return first_root<R>(a, b, c, disc, tmin, tmax, zo, zd, h);
}

template <class R>
bool intersect_shape(const glm::vec4* texels, int32_t prim, const Ray& ray, Hit& hit) {
  const glm::vec3 o = R::r(ray.origin), d = R::r(ray.direction);
  const float t = triangle_texel::kind(texels) == float(MOBIRT_PRIM_SPHERE)
                      ? intersect_sphere<R>(texels, o, d, ray.tmin, ray.tmax)
                      : intersect_cone<R>(texels, o, d, ray.tmin, ray.tmax);
  // The shader's "t >= 0" hit test; the texture coordinates come from the surface (hits.cpp).
  return t >= 0.0f && accept(t, 0.0f, 0.0f, prim, ray, hit);
}

bool intersect_triangle_texels(const glm::vec4* texels, int32_t prim, const Ray& ray, Hit& hit, const RayTest& test) {
  const bool half = test.precision == Precision::Medium;
  if (test.test == IntersectTest::Watertight) {
    return half ? intersect_wt<Half>(texels, prim, ray, hit) : intersect_wt<Exact>(texels, prim, ray, hit);
  }
  return half ? intersect_mt<Half>(texels, prim, ray, hit) : intersect_mt<Exact>(texels, prim, ray, hit);
}

// The test of intersect_primitive on the primitive's texels (from the triangle array, or the copy
// in a leaf entry).
bool intersect_texels(const glm::vec4* texels, int32_t prim, const Ray& ray, Hit& hit, const RayTest& test) {
  if (triangle_texel::kind(texels) == float(MOBIRT_PRIM_TRIANGLE)) return intersect_triangle_texels(texels, prim, ray, hit, test);
  return test.precision == Precision::Medium ? intersect_shape<Half>(texels, prim, ray, hit)
                                             : intersect_shape<Exact>(texels, prim, ray, hit);
}

}  // namespace

bool is_analytic(const FlatKdTree& tree, int32_t prim) {
  return triangle_texel::kind(triangle_texel::of(tree.triangles, prim)) != float(MOBIRT_PRIM_TRIANGLE);
}

bool intersect_primitive(const FlatKdTree& tree, int32_t prim, const Ray& ray, Hit& hit, const RayTest& test) {
  return intersect_texels(triangle_texel::of(tree.triangles, prim), prim, ray, hit, test);
}

glm::vec3 analytic_normal(const FlatKdTree& tree, int32_t prim, const glm::vec3& p) {
  const glm::vec4* t = triangle_texel::of(tree.triangles, prim);
  const glm::vec3 w = p - glm::vec3(t[0]);
  if (triangle_texel::kind(t) == float(MOBIRT_PRIM_SPHERE)) return w;
  const glm::vec3 k(t[1]);
  const glm::vec3 radial = w - glm::dot(w, k) * k;
  return radial - (t[2].y * glm::length(radial)) * k;
}

bool intersect_triangle(const FlatKdTree& tree, int32_t prim, const Ray& ray, Hit& hit, const RayTest& test) {
  return intersect_triangle_texels(triangle_texel::of(tree.triangles, prim), prim, ray, hit, test);
}

namespace {

[[noreturn, gnu::cold, gnu::noinline]] void throw_corrupt_index(float value, size_t size, const char* what) {
  throw Error(ErrorKind::Internal, std::string("kd-tree corrupt: ") + what + " " + std::to_string(value) +
                                       " out of range [0, " + std::to_string(size) + ")");
}

// A texel's index field as an index into an array of `size` entries. Only a corrupt tree (one not
// made by build_kdtree, e.g. a test's) fails this; it ends in an error instead of a wild read.
// The message is built in throw_corrupt_index: built in this function's body, it kept GCC from
// inlining the check, a call per node and two per triangle test, a third of the CPU traversal.
inline int32_t checked_index(float value, size_t size, const char* what) {
  if (!(value >= 0.0f && value < static_cast<float>(size))) [[unlikely]] throw_corrupt_index(value, size, what);
  return static_cast<int32_t>(value);
}

// An interior node's step (glsl/traverse.glsl's): the near child only (the split beyond the
// interval, behind the origin, or NaN from a zero direction), the far child only (the split before
// it; `strict`: a kd-restart at the same point sends ties there too), the far child from the split
// on (the near child flagged empty), or both: the far child pushed, the near one walked first.
enum class Step { Near, Far, SkipNear, Push };
inline Step choose_step(float tsplit, float tmin, float tmax, bool strict, bool near_empty) {
  if (tsplit > tmax || tsplit <= 0.0f || std::isnan(tsplit)) return Step::Near;
  if (tsplit < tmin || (strict && tsplit == tmin)) return Step::Far;
  return near_empty ? Step::SkipNear : Step::Push;
}
// A step to one child (any but Push): node and tmin set; true when that child is an empty leaf to
// close at once.
inline bool take_step(Step step, int32_t near_child, int32_t far_child, bool near_empty, bool far_empty,
                      float tsplit, int32_t& node, float& tmin) {
  if (step == Step::Near) {
    node = near_child;
    return near_empty;
  }
  node = far_child;
  if (step == Step::SkipNear) tmin = tsplit;
  return far_empty;
}

struct Entry {
  int32_t node;
  float tmin;
  float tmax;
};

// A ring of `capacity` entries that overwrites its oldest entry when full.
class ShortStack {
 public:
  explicit ShortStack(int capacity) : capacity_(capacity) {
    if (capacity_ > static_cast<int>(local_.size())) {
      heap_.resize(static_cast<size_t>(capacity_));
      data_ = heap_.data();
    } else {
      data_ = local_.data();
    }
  }
  bool empty() const { return size_ == 0; }
  // Returns true when the push overwrote (dropped) the oldest entry.
  bool push(const Entry& e) {
    if (capacity_ <= 0) return true;
    top_ = top_ + 1 == capacity_ ? 0 : top_ + 1;
    data_[top_] = e;
    if (size_ < capacity_) {
      ++size_;
      return false;
    }
    return true;
  }
  Entry pop() {
    const Entry e = data_[top_];
    top_ = top_ == 0 ? capacity_ - 1 : top_ - 1;
    --size_;
    return e;
  }

 private:
  std::array<Entry, 64> local_;
  std::vector<Entry> heap_;
  Entry* data_;
  int capacity_;
  int top_ = 0;
  int size_ = 0;
};

// Records TraversalTrace segments when a trace is wanted.
class TraceRecorder {
 public:
  explicit TraceRecorder(TraversalTrace* trace) : trace_(trace) {
    if (trace_) *trace_ = TraversalTrace{};
  }
  // An iteration of the node loop at an interior node or a leaf.
  void node(bool interior) {
    ++node_iterations_;
    if (!trace_) return;
    // Two levels a fetch (TraversalTrace::Segment::two_level_iterations): an interior node the
    // last iteration descended into shares that iteration unless it was itself the second level.
    const bool second_level = interior && descended_ && !paired_;
    if (!second_level) ++two_level_;
    paired_ = second_level;
    descended_ = false;
  }
  // The interior node just walked chose a child to visit next (no close, pop or restart).
  void descend() {
    if (trace_) descended_ = true;
  }
  void leaf(uint32_t triangle_tests, float tmax) {
    if (!trace_) return;
    trace_->segments.push_back({node_iterations_, triangle_tests, tmax, two_level_});
    node_iterations_ = 0;
    two_level_ = 0;
    descended_ = paired_ = false;
  }
  // The walk ends in the node loop: the iteration that closes the last leaf ends it.
  void end() {
    if (trace_) trace_->segments.push_back({node_iterations_ + 1, 0, 0.0f, two_level_ + 1});
  }
  // The walk ended at a hit in the leaf just recorded; the walk on past it is measured next.
  void hit() {
    if (!trace_) return;
    trace_->ended_at_hit = true;
    node_iterations_ = 0;
  }
  // The walk on past the hit reached a leaf with primitives (fetch included) or, closing, its end.
  void walked_on(bool closing) {
    if (trace_) trace_->past_hit_iterations = node_iterations_ + (closing ? 1 : 0);
  }
  bool wanted() const { return trace_ != nullptr; }

 private:
  TraversalTrace* trace_;
  uint32_t node_iterations_ = 0;
  uint32_t two_level_ = 0;
  bool descended_ = false;
  bool paired_ = false;
};

template <bool kAnyHit>
Hit traverse_impl(const FlatKdTree& tree, const Ray& input, int stack_depth, TraversalStats& stats,
                  int64_t max_steps, const RayTest& test, TraversalTrace* trace) {
  stats = TraversalStats{};
  TraceRecorder recorder(trace);
  // Under mediump the pass rounds its ray once, before the walk (glsl/trace_main.glsl and the
  // shadow rays of glsl/traverse.glsl): the traversal walks the rounded ray.
  Ray ray = input;
  if (test.precision == Precision::Medium) {
    ray.origin = round_to_half(ray.origin);
    ray.direction = round_to_half(ray.direction);
  }
  Hit best;
  float t0 = 0.0f;
  float t1 = 0.0f;
  if (tree.nodes.empty() || tree.bounds.empty() || !intersect_aabb(tree.bounds, ray, t0, t1)) {
    return best;
  }
  const float scene_tmax = t1;
  float tmin = t0;
  float tmax = t1;
  const glm::vec3 o = ray.origin;
  const glm::vec3 d = ray.direction;
  const glm::vec3 inv = 1.0f / d;
  // A full stack never holds more entries than the tree is deep.
  const int capacity =
      stack_depth >= 0 ? stack_depth : std::max(tree.stats.max_depth_reached, tree.max_depth) + 1;
  ShortStack stack(capacity);
  const uint64_t cap = max_steps < 0 ? ~uint64_t(0) : static_cast<uint64_t>(max_steps);
  const glm::vec4* nodes = tree.nodes.data();
  const size_t entries = tree.leaf_entries();
  const size_t prim_count = tree.triangles.size() / MOBIRT_TEXELS_PER_TRIANGLE;

  int32_t node = 0;
  float restart_t = t0;
  bool strict = false;
  // Closes a leaf or an empty child whose interval ends at tmax; true when the walk is done.
  auto close = [&]() {
    if (best.t <= tmax) return true;
    if (!stack.empty()) {
      const Entry e = stack.pop();
      ++stats.pops;
      node = e.node;
      tmin = e.tmin;
      tmax = e.tmax;
      strict = false;
      return false;
    }
    if (tmax >= scene_tmax) return true;
    ++stats.restarts;
    strict = tmax == restart_t;
    restart_t = tmax;
    tmin = tmax;
    tmax = scene_tmax;
    node = 0;
    return false;
  };
  // For a trace only: once the walk has ended at a hit in a leaf, it walks on as a lane that had
  // not yet tested that leaf would (knowing the hits of the leaves before it), to measure what a
  // lane walking on speculatively spends (TraversalTrace::past_hit_iterations); the result and the
  // statistics are those of the moment the hit ended the walk.
  bool probing = false;
  Hit result;
  Hit before_leaf;  // the best hit before the current leaf's triangles
  TraversalStats ended_stats;
  auto walk_on = [&]() {
    if (!recorder.wanted()) return false;
    recorder.hit();
    probing = true;
    result = best;
    ended_stats = stats;
    best = before_leaf;
    return true;
  };
  auto walked_on = [&](bool closing) {
    recorder.walked_on(closing);
    stats = ended_stats;
    return result;
  };
  for (;;) {
    const glm::vec4 n = nodes[node];
    const bool interior = !node_texel::is_leaf(n);
    recorder.node(interior);
    if (interior) {
      if (!probing && stats.steps >= cap) {
        stats.capped = 1;
        return Hit{};
      }
      ++stats.steps;
      ++stats.nodes_visited;
      const int a = checked_index(node_texel::axis(n), 3, "split axis");
      const float s = node_texel::split(n);
      const float tsplit = (s - o[a]) * inv[a];
      const bool below_first = o[a] < s || (o[a] == s && d[a] <= 0.0f);
      const int32_t below = checked_index(static_cast<float>(node + 1), tree.nodes.size(), "child");
      const int32_t above = checked_index(node_texel::above_child(n), tree.nodes.size(), "child");
      const int32_t near_child = below_first ? below : above;
      const int32_t far_child = below_first ? above : below;
      const bool below_empty = node_texel::below_empty(n);
      const bool above_empty = node_texel::above_empty(n);
      const bool near_empty = below_first ? below_empty : above_empty;
      const bool far_empty = below_first ? above_empty : below_empty;
      bool closed = false;
      const Step step = choose_step(tsplit, tmin, tmax, strict, near_empty);
      if (step != Step::Push) {
        closed = take_step(step, near_child, far_child, near_empty, far_empty, tsplit, node, tmin);
        if (step == Step::SkipNear) strict = false;
      } else {
        if (stack.push(Entry{far_child, tsplit, tmax})) ++stats.dropped;
        node = near_child;
        tmax = tsplit;
      }
      if (!closed) recorder.descend();
      if (closed && close()) {
        if (probing) return walked_on(true);
        recorder.end();
        return best;
      }
      continue;
    }

    // Leaf: the node fetch shares a step with the first triangle test (an empty leaf: one step).
    ++stats.nodes_visited;
    ++stats.leaves_visited;
    const int count = checked_index(node_texel::leaf_count(n), entries + 1, "leaf count");
    if (probing && count > 0) return walked_on(false);
    if (count == 0 && !probing) {
      if (stats.steps >= cap) {
        stats.capped = 1;
        return Hit{};
      }
      ++stats.steps;
    }
    bool any_hit = false;
    before_leaf = best;
    for (int i = 0; i < count; ++i) {
      if (stats.steps >= cap) {
        stats.capped = 1;
        return Hit{};
      }
      ++stats.steps;
      ++stats.triangles_tested;
      // The shader's three fetches from the leaf entry: the primitive's texels and its index.
      const size_t entry = size_t(checked_index(node_texel::leaf_first(n) + float(i), entries, "leaf entry"));
      const glm::vec4* texels = leaf_prim_texel::of(tree.leaf_prims, entry);
      const int32_t prim = checked_index(leaf_prim_texel::prim(texels), prim_count, "primitive");
      if (intersect_texels(texels, prim, ray, best, test) && kAnyHit) {
        recorder.leaf(uint32_t(i + 1), tmax);
        if (!walk_on()) return best;
        any_hit = true;
        break;
      }
    }
    if (count > 0 && !any_hit) {
      recorder.leaf(uint32_t(count), tmax);
      // glsl/traverse.glsl closes a leaf with primitives right after its triangle loop: a hit
      // within the leaf's interval ends the walk there, without a node-loop iteration (close()
      // would return true at once; only the trace differs).
      if (best.valid() && best.t <= tmax && !walk_on()) return best;
    }
    if (close()) {
      if (probing) return walked_on(true);
      recorder.end();
      return best;
    }
  }
}

[[noreturn, gnu::cold, gnu::noinline]] void throw_corrupt_walk(int64_t bound) {
  throw Error(ErrorKind::Internal, "kd-tree corrupt: a CPU walk took more than " + std::to_string(bound) +
                                       " steps or a stack of more than 128 entries (a cycle in the tree)");
}

// The walk of traverse_impl with a full stack and nothing else: no counters, no cap, no trace,
// no index checks (a tree made by build_kdtree), so that it runs at the CPU's pace. With a full
// stack it never restarts, and a leaf's interval, its tests and its close are the same as
// traverse_impl's, so it returns the same hit (tests/kdtree_test.cpp: bit for bit). Per ray 1.3-1.9x
// faster than traverse() with a full stack (tools/profile/simd_stats.cpp, *CPU walks*).
template <bool kAnyHit>
Hit traverse_fast_impl(const FlatKdTree& tree, const Ray& ray, const RayTest& test) {
  if (test.precision == Precision::Medium) {  // the rounded ray of traverse_impl
    TraversalStats stats;
    return traverse_impl<kAnyHit>(tree, ray, -1, stats, -1, test, nullptr);
  }
  Hit best;
  float t0 = 0.0f, t1 = 0.0f;
  if (tree.nodes.empty() || tree.bounds.empty() || !intersect_aabb(tree.bounds, ray, t0, t1)) return best;
  const float o[3] = {ray.origin.x, ray.origin.y, ray.origin.z};
  const float d[3] = {ray.direction.x, ray.direction.y, ray.direction.z};
  const float inv[3] = {1.0f / d[0], 1.0f / d[1], 1.0f / d[2]};
  constexpr int kStack = 128;
  if (std::max(tree.stats.max_depth_reached, tree.max_depth) + 1 > kStack) {
    TraversalStats stats;
    return traverse_impl<kAnyHit>(tree, ray, -1, stats, -1, test, nullptr);
  }
  Entry stack[kStack];
  int size = 0;
  // A sound tree's full-stack walk visits each node once: more iterations than this, or a stack
  // deeper than the tree, is a corrupt tree (never a hang or a wild write; as traverse_impl's cap).
  const int64_t bound = 4 * int64_t(tree.nodes.size() + tree.leaf_entries()) + 64;
  int64_t iterations = 0;
  float tmin = t0, tmax = t1;
  const glm::vec4* nodes = tree.nodes.data();
  const glm::vec4* entries = tree.leaf_prims.data();
  int32_t node = 0;
  for (;;) {
    if (++iterations > bound) [[unlikely]] throw_corrupt_walk(bound);
    const glm::vec4 n = nodes[node];
    bool closed;
    if (!node_texel::is_leaf(n)) {
      const int a = int(node_texel::axis(n));
      const float s = node_texel::split(n);
      const float tsplit = (s - o[a]) * inv[a];
      const bool below_first = o[a] < s || (o[a] == s && d[a] <= 0.0f);
      const int32_t below = node + 1;
      const int32_t above = int32_t(node_texel::above_child(n));
      const bool below_empty = node_texel::below_empty(n);
      const bool above_empty = node_texel::above_empty(n);
      const int32_t near_child = below_first ? below : above;
      const int32_t far_child = below_first ? above : below;
      const bool near_empty = below_first ? below_empty : above_empty;
      const bool far_empty = below_first ? above_empty : below_empty;
      const Step step = choose_step(tsplit, tmin, tmax, false, near_empty);
      if (step != Step::Push) {
        closed = take_step(step, near_child, far_child, near_empty, far_empty, tsplit, node, tmin);
      } else {
        if (size == kStack) [[unlikely]] throw_corrupt_walk(bound);
        stack[size++] = Entry{far_child, tsplit, tmax};
        node = near_child;
        tmax = tsplit;
        closed = false;
      }
      if (!closed) continue;
    } else {
      const int count = int(node_texel::leaf_count(n));
      const size_t first = size_t(node_texel::leaf_first(n));
      for (int i = 0; i < count; ++i) {
        const glm::vec4* texels = entries + (first + size_t(i)) * MOBIRT_TEXELS_PER_TRIANGLE;
        const int32_t prim = int32_t(leaf_prim_texel::prim(texels));
        if (intersect_texels(texels, prim, ray, best, test) && kAnyHit) return best;
      }
    }
    // Close the leaf or empty child: a hit within its interval ends the walk, else the next entry.
    if (best.t <= tmax || size == 0) return best;
    const Entry e = stack[--size];
    node = e.node;
    tmin = e.tmin;
    tmax = e.tmax;
  }
}

}  // namespace

void mark_empty_children(FlatKdTree& tree) {
  auto empty_leaf = [&](size_t i) {
    return i < tree.nodes.size() && node_texel::is_leaf(tree.nodes[i]) && node_texel::leaf_count(tree.nodes[i]) == 0.0f;
  };
  for (size_t i = 0; i < tree.nodes.size(); ++i) {
    glm::vec4& n = tree.nodes[i];
    if (node_texel::is_leaf(n)) continue;
    node_texel::set_empty_flags(n, empty_leaf(i + 1), empty_leaf(static_cast<size_t>(node_texel::above_child(n))));
  }
}

Hit traverse(const FlatKdTree& tree, const Ray& ray, int stack_depth, TraversalStats& stats,
             int64_t max_steps, const RayTest& test, TraversalTrace* trace) {
  return traverse_impl<false>(tree, ray, stack_depth, stats, max_steps, test, trace);
}

Hit traverse(const FlatKdTree& tree, const Ray& ray, int stack_depth, const RayTest& test) {
  TraversalStats stats;
  return traverse_impl<false>(tree, ray, stack_depth, stats, -1, test, nullptr);
}

bool occluded(const FlatKdTree& tree, const Ray& ray, int stack_depth, TraversalStats& stats,
              int64_t max_steps, const RayTest& test, TraversalTrace* trace) {
  return traverse_impl<true>(tree, ray, stack_depth, stats, max_steps, test, trace).valid();
}

bool occluded(const FlatKdTree& tree, const Ray& ray, int stack_depth, const RayTest& test) {
  TraversalStats stats;
  return traverse_impl<true>(tree, ray, stack_depth, stats, -1, test, nullptr).valid();
}

Hit traverse_fast(const FlatKdTree& tree, const Ray& ray, const RayTest& test) {
  return traverse_fast_impl<false>(tree, ray, test);
}

bool occluded_fast(const FlatKdTree& tree, const Ray& ray, const RayTest& test) {
  return traverse_fast_impl<true>(tree, ray, test).valid();
}

Hit brute_force(const FlatKdTree& tree, const Ray& ray, const RayTest& test) {
  Hit best;
  const int32_t n = static_cast<int32_t>(tree.triangles.size() / MOBIRT_TEXELS_PER_TRIANGLE);
  for (int32_t prim = 0; prim < n; ++prim) intersect_primitive(tree, prim, ray, best, test);
  return best;
}

}  // namespace mobirt
