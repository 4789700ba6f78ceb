// Binned-SAH kd-tree construction (Shevtsov, Soupikov and Kapustin 2007, "Highly parallel fast
// kd-tree construction for interactive ray tracing of dynamic scenes"), flattened on the fly into
// the texel arrays of glsl/layout.h.
//
// Per node and axis: `bins` uniform bins over the node box; each reference (a triangle and its box
// inside the node) counts its box's min into one bin and its max into another; one sweep over the
// bin boundaries gives, for every candidate plane, the references below and above, and the SAH
//   cost = traversal_cost + intersection_cost * (1 - empty_bonus if a side is empty)
//                                              * (P_below N_below + P_above N_above) / P
// The node becomes a leaf when no plane beats intersection_cost * N, when N <= max_leaf_prims or at
// the depth limit. Axes with a zero extent are skipped (planar scenes), boxes with zero area are
// leaves.
//
// Classification at the chosen plane s: a reference goes below when its box min <= s and above
// when its box max >= s, so a triangle that touches the plane is referenced on both sides. This is
// what makes traversal robust for rays that lie in a split plane (they visit the below side only,
// see kdtree_traverse.cpp).
//
// Split clipping: a reference that straddles the plane gets the bounds of its triangle clipped
// exactly to each child: the triangle polygon is clipped against the node box and split by the
// plane (Sutherland-Hodgman in double precision, bounds rounded outwards to float, then
// intersected with the reference's box). A side the triangle misses, although its box overlaps
// it, gets no reference. The cheaper alternative, clipping only the reference's box to the child
// box, builds exactly the same tree as no clipping at all (the binning clamps to the node box and
// the classification compares with a plane inside it), so exact clipping is the only one worth
// having. Measured (-O2, one thread, 32 bins, pbrt costs), clipping off -> on:
//   Utah toasters 11,141 tris: refs/tri 13.8 -> 6.4, SAH 1669 -> 893, build 26 -> 32 ms,
//                              traversal 1.71 -> 1.92 Mrays/s (full stack, one thread)
//   SPD balls 9,830 tris:      refs/tri 7.2 -> 3.3, SAH 169 -> 128, build 13 -> 12 ms
//   random soup 100K tris:     refs/tri 7.3 -> 3.4, SAH 5880 -> 3569, build 461 -> 370 ms
//
// The build is depth-first with an explicit task stack (no recursion) and one reference arena used
// as a stack: a split writes the above child's references then the below child's at the parent's
// offset, the below child is built next, so memory stays about twice the root's references.
// Nodes are emitted in depth-first order: the below child is the next node, the above child's
// index is patched into the parent when the above child is emitted.
#include <glm/glm.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "accel/kdtree.h"
#include "core/error.h"
#include "layout.h"

namespace mobirt {

namespace {

// No split plane closer than this (relative to the scene's size and coordinate magnitude) to the
// node's faces. Without it the SAH, rewarded by the empty bonus, cuts ever thinner empty slabs off
// flat walls (down to 1e-9 thick next to a floor at y = 0); their planes then round to the same
// ray parameter t as the wall's and the traversal cannot order them: a kd-restart lost the wall
// behind such a tie. With the limit, two planes on one axis along any root-to-leaf path are at
// least 1e-5 * scale apart, far more than the rounding of t for rays starting within ~80 scene
// sizes of the scene. The SAH cost hardly changes (those slabs were empty).
constexpr float kMinWidthRelative = 1e-5f;

struct Ref {
  Aabb box;       // the triangle's bounds inside the node (its full box without split clipping)
  uint32_t prim;
};

struct Task {
  size_t offset;  // references in arena[offset, offset + count)
  size_t count;
  Aabb box;
  int depth;
  int64_t parent;  // node whose "above" index is this task's node, or -1
};

double area(const glm::dvec3& d) { return 2.0 * (d.x * d.y + d.y * d.z + d.z * d.x); }

float round_down(double x) {
  float f = static_cast<float>(x);
  if (static_cast<double>(f) > x) f = std::nextafter(f, -kInfinity);
  return f;
}

float round_up(double x) {
  float f = static_cast<float>(x);
  if (static_cast<double>(f) < x) f = std::nextafter(f, kInfinity);
  return f;
}

// The triangle (a, b, c) clipped against `box` (inclusive; Sutherland-Hodgman in double), then
// split by the plane x[axis] = split: the bounds of the part below (<= split) and above (>= split),
// rounded outwards to float. Returns bit 1 when the below part is not empty, bit 2 for above.
int clip_and_split(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c, const Aabb& box,
                   int split_axis, float split, Aabb& below, Aabb& above) {
  constexpr int kMax = 16;  // 3 vertices + at most one per clipping plane
  std::array<glm::dvec3, kMax> poly_a;
  std::array<glm::dvec3, kMax> poly_b;
  glm::dvec3* poly = poly_a.data();
  glm::dvec3* next = poly_b.data();
  poly[0] = glm::dvec3(a);
  poly[1] = glm::dvec3(b);
  poly[2] = glm::dvec3(c);
  int n = 3;
  for (int axis = 0; axis < 3; ++axis) {
    for (int side = 0; side < 2; ++side) {
      const double plane = side == 0 ? box.lo[axis] : box.hi[axis];
      const double sign = side == 0 ? 1.0 : -1.0;  // inside: sign * (x - plane) >= 0
      bool all_inside = true;
      for (int i = 0; i < n; ++i) {
        if (!(sign * (poly[i][axis] - plane) >= 0.0)) {
          all_inside = false;
          break;
        }
      }
      if (all_inside) continue;
      int m = 0;
      for (int i = 0; i < n; ++i) {
        const glm::dvec3& p = poly[i];
        const glm::dvec3& q = poly[i + 1 == n ? 0 : i + 1];
        const double dp = sign * (p[axis] - plane);
        const double dq = sign * (q[axis] - plane);
        if (dp >= 0.0) next[m++] = p;
        if ((dp >= 0.0) != (dq >= 0.0)) {
          glm::dvec3 x = p + (dp / (dp - dq)) * (q - p);
          x[axis] = plane;  // exactly on the plane
          next[m++] = x;
        }
      }
      std::swap(poly, next);
      n = m;
      if (n == 0) return 0;
    }
  }
  // Split: bounds of the vertices on each side plus the edge crossings (which lie on both).
  const double s = split;
  glm::dvec3 lo[2] = {glm::dvec3(kInfinity), glm::dvec3(kInfinity)};
  glm::dvec3 hi[2] = {glm::dvec3(-kInfinity), glm::dvec3(-kInfinity)};
  for (int i = 0; i < n; ++i) {
    const glm::dvec3& p = poly[i];
    const glm::dvec3& q = poly[i + 1 == n ? 0 : i + 1];
    const double dp = p[split_axis] - s;
    const double dq = q[split_axis] - s;
    if (dp <= 0.0) {
      lo[0] = glm::min(lo[0], p);
      hi[0] = glm::max(hi[0], p);
    }
    if (dp >= 0.0) {
      lo[1] = glm::min(lo[1], p);
      hi[1] = glm::max(hi[1], p);
    }
    if ((dp < 0.0 && dq > 0.0) || (dp > 0.0 && dq < 0.0)) {
      glm::dvec3 x = p + (dp / (dp - dq)) * (q - p);
      x[split_axis] = s;
      for (int k = 0; k < 2; ++k) {
        lo[k] = glm::min(lo[k], x);
        hi[k] = glm::max(hi[k], x);
      }
    }
  }
  int result = 0;
  Aabb* out[2] = {&below, &above};
  for (int k = 0; k < 2; ++k) {
    if (!(lo[k].x <= hi[k].x)) continue;
    result |= 1 << k;
    for (int axis = 0; axis < 3; ++axis) {
      out[k]->lo[axis] = round_down(lo[k][axis]);
      out[k]->hi[axis] = round_up(hi[k][axis]);
    }
  }
  return result;
}

Aabb intersect(const Aabb& a, const Aabb& b) {
  Aabb r;
  r.lo = glm::max(a.lo, b.lo);
  r.hi = glm::min(a.hi, b.hi);
  return r;
}

std::string count_text(size_t n) {
  const std::string digits = std::to_string(n);
  std::string s;
  for (size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) s += ',';
    s += digits[i];
  }
  return s;
}

class Builder {
 public:
  Builder(std::span<const glm::vec3> positions, const KdBuildOptions& options)
      : positions_(positions), options_(options), bins_(std::max(1, options.bins)) {}

  FlatKdTree build() {
    FlatKdTree tree;
    const size_t n = positions_.size() / 3;
    tree.max_depth = kdtree_depth_limit(n, options_.max_depth);

    // Triangles and root references.
    tree.triangles.reserve(n * MOBIRT_TEXELS_PER_TRIANGLE);
    arena_.resize(n);
    for (size_t i = 0; i < n; ++i) {
      Aabb box;
      for (int k = 0; k < 3; ++k) {
        const glm::vec3& p = positions_[3 * i + k];
        tree.triangles.emplace_back(p, 0.0f);
        box.extend(p);
      }
      arena_[i] = Ref{box, static_cast<uint32_t>(i)};
      tree.bounds.extend(box);
    }
    nodes_ = &tree.nodes;
    prim_list_ = &tree.prim_list;
    stats_ = &tree.stats;
    tree.nodes.reserve(std::min<size_t>(4 * n + 1, kKdIndexLimit));
    tree.prim_list.reserve(std::min<size_t>(2 * n, kKdIndexLimit));

    const double root_area = area(glm::dvec3(tree.bounds.extent()));
    if (n > 0) {
      const glm::vec3 magnitude = glm::max(glm::abs(tree.bounds.lo), glm::abs(tree.bounds.hi));
      const glm::vec3 ext = tree.bounds.extent();
      const float scale = std::max({ext.x, ext.y, ext.z, magnitude.x, magnitude.y, magnitude.z});
      min_width_ = std::max(kMinWidthRelative * scale, std::numeric_limits<float>::min());
    }
    tasks_.push_back(Task{0, n, tree.bounds, 0, -1});
    while (!tasks_.empty()) {
      const Task task = tasks_.back();
      tasks_.pop_back();
      process(task, tree.max_depth);
    }
    stats_->nodes = tree.nodes.size();
    stats_->sah_cost = root_area > 0.0 ? cost_ / root_area
                                       : options_.intersection_cost * double(n);
    return tree;
  }

 private:
  size_t emit(const glm::vec4& node, int64_t parent) {
    const size_t index = nodes_->size();
    if (index >= kKdIndexLimit) {
      throw Error(ErrorKind::BadInput,
                  "kd-tree for " + count_text(positions_.size() / 3) + " triangles needs more than " +
                      count_text(kKdIndexLimit) +
                      " nodes, the limit of exact float indices (2^24) in the node texture; "
                      "lower max_depth or raise max_leaf_prims");
    }
    nodes_->push_back(node);
    if (parent >= 0) (*nodes_)[static_cast<size_t>(parent)].y = static_cast<float>(index);
    return index;
  }

  void make_leaf(const Task& task, double box_area) {
    const Ref* refs = arena_.data() + task.offset;
    const size_t count = task.count;
    glm::vec4 node(0.0f, static_cast<float>(count), static_cast<float>(MOBIRT_NODE_LEAF), 0.0f);
    if (count == 1) {
      node.x = static_cast<float>(refs[0].prim);
    } else if (count > 1) {
      const size_t start = prim_list_->size();
      if (start + count > kKdIndexLimit) {
        throw Error(ErrorKind::BadInput,
                    "kd-tree for " + count_text(positions_.size() / 3) +
                        " triangles needs more than " + count_text(kKdIndexLimit) +
                        " leaf references (prim-list entries), the limit of exact float indices "
                        "(2^24); lower max_depth or turn split_clipping on");
      }
      node.x = static_cast<float>(start);
      for (size_t i = 0; i < count; ++i) prim_list_->push_back(static_cast<float>(refs[i].prim));
    }
    emit(node, task.parent);
    stats_->leaves += 1;
    if (count == 0) stats_->empty_leaves += 1;
    stats_->prim_references += count;
    stats_->max_leaf_size = std::max(stats_->max_leaf_size, count);
    stats_->max_depth_reached = std::max(stats_->max_depth_reached, task.depth);
    cost_ += options_.intersection_cost * double(count) * box_area;
  }

  void process(const Task& task, int max_depth) {
    const Aabb& box = task.box;
    const glm::dvec3 ext(box.extent());
    const double box_area = area(ext);
    const size_t n = task.count;
    const double leaf_cost = options_.intersection_cost * double(n);
    if (n <= static_cast<size_t>(std::max(0, options_.max_leaf_prims)) || task.depth >= max_depth ||
        !(box_area > 0.0)) {
      make_leaf(task, box_area);
      return;
    }

    // ---- Binning: per axis, bin counts of reference minima and maxima.
    const int k = bins_;
    counts_.assign(static_cast<size_t>(6 * k), 0u);
    const Ref* refs = arena_.data() + task.offset;
    float scale[3];
    bool active[3];
    for (int a = 0; a < 3; ++a) {
      // A box thinner than float can bin (k / width overflows: 0 * inf would be NaN) is not split.
      active[a] = box.hi[a] > box.lo[a] && std::isfinite(float(k) / (box.hi[a] - box.lo[a]));
      scale[a] = active[a] ? float(k) / (box.hi[a] - box.lo[a]) : 0.0f;
    }
    const float top = float(k - 1);
    for (size_t i = 0; i < n; ++i) {
      const Aabb& b = refs[i].box;
      for (int a = 0; a < 3; ++a) {
        if (!active[a]) continue;
        const float fl = std::clamp((b.lo[a] - box.lo[a]) * scale[a], 0.0f, top);
        const float fh = std::clamp((b.hi[a] - box.lo[a]) * scale[a], 0.0f, top);
        counts_[static_cast<size_t>((2 * a) * k + static_cast<int>(fl))] += 1;
        counts_[static_cast<size_t>((2 * a + 1) * k + static_cast<int>(fh))] += 1;
      }
    }

    // ---- Sweep.
    float best_cost = kInfinity;
    int best_axis = -1;
    float best_split = 0.0f;
    const double inv_area = 1.0 / box_area;
    // Candidate i (1 .. k-1) lies at lo + i * step; the child areas are linear in i:
    //   P_below / P = c + g * i, P_above / P = c + g * (k - i).
    const float trav = options_.traversal_cost;
    const float isect = options_.intersection_cost;
    const float empty_factor = 1.0f - options_.empty_bonus;
    const float empty_min_bins = options_.empty_bonus_min_width * float(k);
    for (int a = 0; a < 3; ++a) {
      if (!active[a]) continue;
      const float o1 = static_cast<float>(ext[(a + 1) % 3]);
      const float o2 = static_cast<float>(ext[(a + 2) % 3]);
      const float step = (box.hi[a] - box.lo[a]) / float(k);
      const float g = static_cast<float>(2.0 * double(step) * (double(o1) + double(o2)) * inv_area);
      const float c = static_cast<float>(2.0 * double(o1) * double(o2) * inv_area);
      // Planes computed as lo + i * step are monotone in i; every plane must keep min_width_
      // from the node's faces (checked one by one only when the bins are that thin).
      const bool all_valid = step >= 2.0f * min_width_;
      const uint32_t* lo_counts = counts_.data() + (2 * a) * k;
      const uint32_t* hi_counts = counts_.data() + (2 * a + 1) * k;
      uint32_t below = 0;
      uint32_t ended = 0;  // references whose max lies in a bin below the plane
      const uint32_t total = static_cast<uint32_t>(n);
      for (int i = 1; i < k; ++i) {
        const uint32_t change_before = lo_counts[i - 1] | hi_counts[i - 1];
        below += lo_counts[i - 1];
        ended += hi_counts[i - 1];
        // The counts are constant between bins that hold no minimum or maximum and the cost is
        // linear in i there: only the ends of such runs can be the minimum.
        if (i > 1 && i + 1 < k && change_before == 0 && (lo_counts[i] | hi_counts[i]) == 0) continue;
        const uint32_t above = total - ended;
        const float pb = c + g * float(i);
        const float pa = c + g * float(k - i);
        float cost = pb * float(below) + pa * float(above);
        if ((below == 0 && float(i) >= empty_min_bins) || (above == 0 && float(k - i) >= empty_min_bins)) {
          cost *= empty_factor;
        }
        cost = trav + isect * cost;
        if (cost < best_cost) {
          if (!all_valid) {
            const float split = box.lo[a] + float(i) * step;
            if (!(split - box.lo[a] >= min_width_ && box.hi[a] - split >= min_width_)) continue;
          }
          best_cost = cost;
          best_axis = a;
          best_split = box.lo[a] + float(i) * step;
        }
      }
    }
    if (best_axis < 0 || !(double(best_cost) < leaf_cost)) {
      make_leaf(task, box_area);
      return;
    }

    // ---- Partition (order-preserving, so leaf lists stay sorted by primitive index).
    const int a = best_axis;
    const float s = best_split;
    Aabb below_box = box;
    below_box.hi[a] = s;
    Aabb above_box = box;
    above_box.lo[a] = s;
    below_.clear();
    above_.clear();
    const bool clipping = options_.split_clipping;
    for (size_t i = 0; i < n; ++i) {
      const Ref& r = refs[i];
      const float lo = r.box.lo[a];
      const float hi = r.box.hi[a];
      const bool to_below = lo <= s;
      const bool to_above = hi >= s;
      if (!(to_below && to_above)) {
        if (to_below) {
          below_.push_back(r);
        } else {
          above_.push_back(r);
        }
        continue;
      }
      if (!clipping) {
        below_.push_back(r);
        above_.push_back(r);
        continue;
      }
      Ref rb = r;
      rb.box.hi[a] = s;
      Ref ra = r;
      ra.box.lo[a] = s;
      if (lo < s && s < hi) {
        const glm::vec3* v = positions_.data() + 3 * size_t(r.prim);
        Aabb cb;
        Aabb ca;
        const int sides = clip_and_split(v[0], v[1], v[2], box, a, s, cb, ca);
        const bool hit_b = (sides & 1) != 0;
        const bool hit_a = (sides & 2) != 0;
        if (hit_b || hit_a) {  // both empty can only be rounding: keep the box clip then
          if (hit_b) {
            rb.box = intersect(rb.box, cb);
            if (!rb.box.empty()) below_.push_back(rb);
          }
          if (hit_a) {
            ra.box = intersect(ra.box, ca);
            if (!ra.box.empty()) above_.push_back(ra);
          }
          continue;
        }
      }
      below_.push_back(rb);
      above_.push_back(ra);
    }

    const size_t nb = below_.size();
    const size_t na = above_.size();
    if (arena_.size() < task.offset + na + nb) arena_.resize(task.offset + na + nb);
    std::copy(above_.begin(), above_.end(), arena_.begin() + static_cast<std::ptrdiff_t>(task.offset));
    std::copy(below_.begin(), below_.end(),
              arena_.begin() + static_cast<std::ptrdiff_t>(task.offset + na));

    const size_t index =
        emit(glm::vec4(s, 0.0f, static_cast<float>(a), 0.0f), task.parent);
    cost_ += options_.traversal_cost * box_area;
    tasks_.push_back(Task{task.offset, na, above_box, task.depth + 1, static_cast<int64_t>(index)});
    tasks_.push_back(Task{task.offset + na, nb, below_box, task.depth + 1, -1});
  }

  std::span<const glm::vec3> positions_;
  const KdBuildOptions& options_;
  int bins_;
  std::vector<Ref> arena_;
  std::vector<Ref> below_;
  std::vector<Ref> above_;
  std::vector<Task> tasks_;
  std::vector<uint32_t> counts_;
  std::vector<glm::vec4>* nodes_ = nullptr;
  std::vector<float>* prim_list_ = nullptr;
  KdBuildStats* stats_ = nullptr;
  double cost_ = 0.0;
  float min_width_ = std::numeric_limits<float>::min();
};

}  // namespace

int kdtree_depth_limit(size_t triangle_count, int max_depth_option) {
  if (max_depth_option >= 0) return max_depth_option;
  int log2n = 0;
  for (size_t n = triangle_count; n > 1; n >>= 1) ++log2n;
  return static_cast<int>(std::lround(8.0 + 1.3 * log2n));
}

FlatKdTree build_kdtree(std::span<const glm::vec3> positions, const KdBuildOptions& options) {
  if (positions.size() % 3 != 0) {
    throw Error(ErrorKind::BadInput, "kd-tree: " + count_text(positions.size()) +
                                         " positions do not make whole triangles (3 per triangle)");
  }
  const size_t n = positions.size() / 3;
  if (n > kKdMaxTriangles) {
    throw Error(ErrorKind::BadInput,
                "kd-tree: " + count_text(n) + " triangles need " + count_text(3 * n) +
                    " triangle texels, more than the " + count_text(kKdIndexLimit) +
                    " that exact float indices (2^24) address; at most " +
                    count_text(kKdMaxTriangles) + " triangles");
  }
  for (size_t i = 0; i < positions.size(); ++i) {
    const glm::vec3& p = positions[i];
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
      throw Error(ErrorKind::BadInput, "kd-tree: triangle " + std::to_string(i / 3) + " vertex " +
                                           std::to_string(i % 3) +
                                           " has a non-finite position (NaN or infinity)");
    }
  }
  if (options.bins < 2) {
    throw Error(ErrorKind::BadInput,
                "kd-tree: bins must be at least 2 (got " + std::to_string(options.bins) + ")");
  }
  FlatKdTree tree = Builder(positions, options).build();
  mark_empty_children(tree);
  return tree;
}

}  // namespace mobirt
