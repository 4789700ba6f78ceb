#include "reference/reference.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>
#include <thread>

#include "core/error.h"
#include "raytree/secondary.h"
#include "raytree/shading_math.h"
#include "scene/texture_images.h"

namespace mobirt {

namespace {

using dvec3 = glm::dvec3;
using dvec2 = glm::dvec2;
constexpr double kInf = std::numeric_limits<double>::infinity();

struct DRay {
  dvec3 origin;
  dvec3 direction;
  double tmin = 0.0;
  double tmax = kInf;
};

struct DHit {
  int32_t prim = -1;
  double t = kInf;
  double u = 0.0, v = 0.0;
};

double max_abs(const dvec3& p) { return std::max(std::abs(p.x), std::max(std::abs(p.y), std::abs(p.z))); }

// The first root in [tmin, tmax] of a t^2 + 2 b t + c = 0 whose height z0 + t zd lies in [0, h]
// (quarter discriminant disc >= 0), in the cancellation-free form; false when neither is.
bool first_root_d(double a, double b, double c, double disc, double tmin, double tmax, double z0, double zd,
                  double h, double& t) {
  const double q = -(b + (b >= 0.0 ? 1.0 : -1.0) * std::sqrt(disc));
  double r0 = c / q, r1 = q / a;
  if (r1 < r0) std::swap(r0, r1);
  for (double r : {r0, r1}) {
    const double z = z0 + r * zd;
    if (r >= tmin && r <= tmax && z >= 0.0 && z <= h) {
      t = r;
      return true;
    }
  }
  return false;
}

// A sphere or an open truncated cone (core/shapes.h) in double: the same equations as the
// renderer's (glsl/traverse.glsl), without its rounding.
bool intersect_shape_d(const Shape& s, const dvec3& o, const dvec3& d, double tmin, double tmax, double& t) {
  if (s.kind == ShapeKind::Sphere) {
    const dvec3 f = o - dvec3(s.base);
    const double r = s.base_radius;
    const double a = glm::dot(d, d);
    const double b = glm::dot(f, d);
    const dvec3 g = f - (b / a) * d;
    const double disc = a * (r * r - glm::dot(g, g));
    if (!(disc >= 0.0)) return false;
    return first_root_d(a, b, glm::dot(f, f) - r * r, disc, tmin, tmax, 0.0, 0.0, 1.0, t);
  }
  const ConeFrame<double> f = cone_frame<double>(s);
  const dvec3 k = f.axis;
  const double h = f.height, slope = f.slope;
  const dvec3 w = o - dvec3(s.base);
  const double zo = glm::dot(w, k), zd = glm::dot(d, k);
  const dvec3 ro = w - zo * k, rd = d - zd * k;
  const double ra = double(s.base_radius) + slope * zo;
  const double a = glm::dot(rd, rd) - slope * slope * zd * zd;
  const double b = glm::dot(ro, rd) - ra * slope * zd;
  const double c = glm::dot(ro, ro) - ra * ra;
  const double disc = b * b - a * c;
  if (!(disc >= 0.0)) return false;
  return first_root_d(a, b, c, disc, tmin, tmax, zo, zd, h, t);
}

// ---- BVH in double: median split on the longest axis of the centroid bounds ---------------------

struct BvhNode {
  dvec3 lo{kInf}, hi{-kInf};
  int32_t first = 0;   // leaf: first index into order; interior: index of the left child
  int32_t count = 0;   // leaf: number of triangles; interior: 0 (right child = left + 1)
};

class Bvh {
 public:
  explicit Bvh(const Scene& scene) : shapes_(scene.shapes), triangles_(scene.mesh.triangle_count()) {
    const auto& pos = scene.mesh.positions;
    const size_t n = scene.mesh.triangle_count();
    verts_.resize(n * 3);
    for (size_t i = 0; i < n * 3; ++i) {
      const glm::vec3& p = pos[i];
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
        throw input_error(scene.source, "triangle " + std::to_string(i / 3) + ": vertex " + std::to_string(i % 3) +
                                            " has a non-finite position; the reference tracer needs finite vertices");
      }
      verts_[i] = dvec3(p);
    }
    for (size_t i = 0; i < n; ++i) {
      const dvec3 e = glm::cross(verts_[3 * i + 1] - verts_[3 * i], verts_[3 * i + 2] - verts_[3 * i]);
      if (e != dvec3(0.0)) order_.push_back(int32_t(i));  // zero-area triangles are never hit
    }
    // Analytic shapes follow the triangles (primitive n + k), each with its box.
    for (size_t k = 0; k < shapes_.size(); ++k) order_.push_back(int32_t(n + k));
    lo_.resize(n + shapes_.size());
    hi_.resize(n + shapes_.size());
    for (size_t i = 0; i < n; ++i) {
      lo_[i] = glm::min(verts_[3 * i], glm::min(verts_[3 * i + 1], verts_[3 * i + 2]));
      hi_[i] = glm::max(verts_[3 * i], glm::max(verts_[3 * i + 1], verts_[3 * i + 2]));
    }
    for (size_t k = 0; k < shapes_.size(); ++k) {
      const Aabb box = shape_bounds(shapes_[k]);
      lo_[n + k] = dvec3(box.lo);
      hi_[n + k] = dvec3(box.hi);
    }
    centroids_.resize(n + shapes_.size());
    for (size_t i = 0; i < n; ++i) centroids_[i] = (verts_[3 * i] + verts_[3 * i + 1] + verts_[3 * i + 2]) / 3.0;
    for (size_t i = n; i < centroids_.size(); ++i) centroids_[i] = 0.5 * (lo_[i] + hi_[i]);
    nodes_.reserve(order_.empty() ? 1 : 2 * order_.size());
    nodes_.emplace_back();
    if (!order_.empty()) build(0, 0, int32_t(order_.size()));
  }

  const dvec3& vertex(int32_t prim, int k) const { return verts_[size_t(prim) * 3 + size_t(k)]; }
  // The analytic shape of primitive prim, or nullptr for a triangle.
  const Shape* shape(int32_t prim) const {
    return size_t(prim) >= triangles_ ? &shapes_[size_t(prim) - triangles_] : nullptr;
  }

  // Closest hit (or, with any_hit, any hit) in [tmin, tmax], never on the triangle `exclude` (a
  // shape may be hit again: a ray leaving a sphere's inside meets its far side; the offset origin
  // keeps it off the point it leaves).
  DHit intersect(const DRay& ray, int32_t exclude, bool any_hit) const {
    DHit best;
    best.t = ray.tmax;
    if (order_.empty()) return best;
    const dvec3 inv = 1.0 / ray.direction;
    int32_t stack[128];
    int sp = 0;
    stack[sp++] = 0;
    bool found = false;
    while (sp > 0) {
      const BvhNode& node = nodes_[size_t(stack[--sp])];
      double t0 = 0.0;
      if (!box_hit(node, ray, inv, best.t, t0)) continue;
      if (node.count > 0) {
        for (int32_t k = node.first; k < node.first + node.count; ++k) {
          const int32_t prim = order_[size_t(k)];
          double t = 0, u = 0, v = 0;
          if (const Shape* s = shape(prim)) {
            if (!intersect_shape_d(*s, ray.origin, ray.direction, ray.tmin, best.t, t)) continue;
          } else if (prim == exclude ||
                     !intersect_watertight(ray.origin, ray.direction, vertex(prim, 0), vertex(prim, 1),
                                           vertex(prim, 2), ray.tmin, best.t, t, u, v)) {
            continue;
          }
          // The same order as the renderer's: smaller t, then the lower primitive index.
          if (!found || t < best.t || (t == best.t && prim < best.prim)) {
            best = DHit{prim, t, u, v};
            found = true;
            if (any_hit) return best;
          }
        }
        continue;
      }
      // Near child last on the stack, so that it is visited first.
      const BvhNode& a = nodes_[size_t(node.first)];
      const BvhNode& b = nodes_[size_t(node.first) + 1];
      double ta = kInf, tb = kInf;
      const bool ha = box_hit(a, ray, inv, best.t, ta);
      const bool hb = box_hit(b, ray, inv, best.t, tb);
      if (sp + 2 > 128) throw Error(ErrorKind::Internal, "reference BVH deeper than its stack");
      if (ha && hb) {
        if (ta <= tb) {
          stack[sp++] = node.first + 1;
          stack[sp++] = node.first;
        } else {
          stack[sp++] = node.first;
          stack[sp++] = node.first + 1;
        }
      } else if (ha) {
        stack[sp++] = node.first;
      } else if (hb) {
        stack[sp++] = node.first + 1;
      }
    }
    if (!found) best.prim = -1;
    return best;
  }

 private:
  static bool box_hit(const BvhNode& node, const DRay& ray, const dvec3& inv, double tmax, double& t0) {
    double lo = ray.tmin, hi = tmax;
    for (int a = 0; a < 3; ++a) {
      double tn = (node.lo[a] - ray.origin[a]) * inv[a];
      double tf = (node.hi[a] - ray.origin[a]) * inv[a];
      if (tn > tf) std::swap(tn, tf);
      tf *= 1.0 + 4.0 * std::numeric_limits<double>::epsilon();  // Ize 2013: conservative far plane
      lo = tn > lo ? tn : lo;  // NaN (0 * inf) keeps the interval
      hi = tf < hi ? tf : hi;
      if (lo > hi) return false;
    }
    t0 = lo;
    return true;
  }

  void build(int32_t index, int32_t first, int32_t count) {
    BvhNode node;
    dvec3 clo(kInf), chi(-kInf);
    for (int32_t k = first; k < first + count; ++k) {
      const int32_t prim = order_[size_t(k)];
      node.lo = glm::min(node.lo, lo_[size_t(prim)]);
      node.hi = glm::max(node.hi, hi_[size_t(prim)]);
      clo = glm::min(clo, centroids_[size_t(prim)]);
      chi = glm::max(chi, centroids_[size_t(prim)]);
    }
    const dvec3 extent = chi - clo;
    const int axis = extent.x >= extent.y && extent.x >= extent.z ? 0 : (extent.y >= extent.z ? 1 : 2);
    if (count <= 4 || extent[axis] <= 0.0) {
      node.first = first;
      node.count = count;
      nodes_[size_t(index)] = node;
      return;
    }
    const int32_t mid = first + count / 2;
    std::nth_element(order_.begin() + first, order_.begin() + mid, order_.begin() + first + count,
                     [&](int32_t x, int32_t y) { return centroids_[size_t(x)][axis] < centroids_[size_t(y)][axis]; });
    node.first = int32_t(nodes_.size());
    node.count = 0;
    nodes_[size_t(index)] = node;
    nodes_.emplace_back();
    nodes_.emplace_back();
    build(node.first, first, mid - first);
    build(node.first + 1, mid, first + count - mid);
  }

  const std::vector<Shape>& shapes_;
  size_t triangles_;
  std::vector<dvec3> verts_;
  std::vector<dvec3> lo_, hi_;  // each primitive's box
  std::vector<dvec3> centroids_;
  std::vector<int32_t> order_;
  std::vector<BvhNode> nodes_;
};

// ---- Textures: the original images, bilinear, wrapped, sRGB decoded per texel ------------------

struct RefTexture {
  TextureImage image;
  TextureWrap wrap_s = TextureWrap::Repeat;
  TextureWrap wrap_t = TextureWrap::Repeat;
};

int wrap_index(int64_t i, int size, TextureWrap mode) {
  const int64_t n = size;
  if (mode == TextureWrap::ClampToEdge) return int(std::clamp<int64_t>(i, 0, n - 1));
  if (mode == TextureWrap::MirroredRepeat) {
    const int64_t period = 2 * n;
    int64_t r = ((i % period) + period) % period;
    if (r >= n) r = period - 1 - r;
    return int(r);
  }
  return int(((i % n) + n) % n);
}

double srgb_decode(double c) { return c < 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4); }

dvec3 texel_linear(const TextureImage& image, int x, int y) {
  const uint32_t p = image.at(x, y);
  return dvec3(srgb_decode(double(p & 0xFFu) / 255.0), srgb_decode(double((p >> 8) & 0xFFu) / 255.0),
               srgb_decode(double((p >> 16) & 0xFFu) / 255.0));
}

dvec3 sample_texture(const RefTexture& tex, dvec2 uv) {
  const TextureImage& im = tex.image;
  if (im.width <= 0 || im.height <= 0) return dvec3(1.0);
  if (!std::isfinite(uv.x) || !std::isfinite(uv.y)) uv = dvec2(0.0);
  // Keep the texel index within int64 for absurd coordinates (the pattern repeats anyway).
  uv = glm::clamp(uv, dvec2(-1e12), dvec2(1e12));
  const dvec2 p = uv * dvec2(im.width, im.height) - 0.5;
  const dvec2 p0 = glm::floor(p);
  const dvec2 f = p - p0;
  const int x0 = wrap_index(int64_t(p0.x), im.width, tex.wrap_s);
  const int x1 = wrap_index(int64_t(p0.x) + 1, im.width, tex.wrap_s);
  const int y0 = wrap_index(int64_t(p0.y), im.height, tex.wrap_t);
  const int y1 = wrap_index(int64_t(p0.y) + 1, im.height, tex.wrap_t);
  const dvec3 top = glm::mix(texel_linear(im, x0, y0), texel_linear(im, x1, y0), f.x);
  const dvec3 bottom = glm::mix(texel_linear(im, x0, y1), texel_linear(im, x1, y1), f.x);
  return glm::mix(top, bottom, f.y);
}

// ---- The tracer ----------------------------------------------------------------------------

struct SurfaceD {
  int32_t prim = -1;
  dvec3 position, normal, geometric;  // normals unit, facing the incoming ray
  bool entering = true;
  dvec2 texcoord{0.0};
  uint32_t material = 0;
  dvec3 ng_raw;                        // the unnormalised geometric normal as stored (b-a)x(c-a)
};

class Tracer {
 public:
  Tracer(const Scene& scene, const ReferenceSettings& settings)
      : scene_(scene), settings_(settings), bvh_(scene) {
    if (scene.lights.size() > 32) {
      throw input_error(scene.source, std::to_string(scene.lights.size()) +
                                          " lights; the reference tracer handles at most 32");
    }
    for (int t = 0; t < int(scene.textures.size()); ++t) {
      bool used = false;
      for (const Material& m : scene.materials) used = used || m.texture == t;
      RefTexture rt;
      rt.wrap_s = scene.textures[size_t(t)].wrap_s;
      rt.wrap_t = scene.textures[size_t(t)].wrap_t;
      if (used) rt.image = decode_texture(scene, t);
      textures_.push_back(std::move(rt));
    }
    all_lights_ = scene.lights.empty() ? 0u : uint32_t((uint64_t(2) << (scene.lights.size() - 1)) - 1u);
    depth_ = scene_has_secondary_rays(scene) ? settings.depth : 0;
  }

  // The colour of `ray` times its weight, with its subtree; fills the primary record when asked.
  dvec3 trace(const DRay& ray, int32_t exclude, const dvec3& weight, int generation, int32_t* prim_out,
              uint32_t* mask_out) const {
    const DHit h = bvh_.intersect(ray, exclude, false);
    if (prim_out) *prim_out = h.prim;
    if (h.prim < 0) {
      if (mask_out) *mask_out = 0;
      return weight * glm::clamp(dvec3(scene_.background), 0.0, 1.0);
    }
    const SurfaceD s = surface(ray, h);
    const uint32_t mask = settings_.shadows ? shadow_mask(s, ray) : all_lights_;
    if (mask_out) *mask_out = mask;
    dvec3 color = weight * glm::clamp(phong(s, -ray.direction, mask), 0.0, 1.0);
    if (generation < depth_) color += secondary(s, ray, weight, generation);
    return color;
  }

 private:
  SurfaceD surface(const DRay& ray, const DHit& h) const {
    SurfaceD s;
    s.prim = h.prim;
    if (const Shape* shape = bvh_.shape(h.prim)) {
      s.position = ray.origin + h.t * ray.direction;
      const dvec3 n = shape_normal(*shape, s.position);
      s.ng_raw = n;
      s.entering = glm::dot(n, ray.direction) < 0.0;
      s.geometric = s.entering ? n : -n;
      s.normal = s.geometric;
      s.texcoord = shape_texcoord(*shape, s.position);
      s.material = shape->material;
      return s;
    }
    const dvec3& a = bvh_.vertex(h.prim, 0);
    const dvec3& b = bvh_.vertex(h.prim, 1);
    const dvec3& c = bvh_.vertex(h.prim, 2);
    const double w = 1.0 - h.u - h.v;
    s.position = w * a + h.u * b + h.v * c;
    s.ng_raw = glm::cross(b - a, c - a);
    const dvec3 ng = glm::normalize(s.ng_raw);
    s.entering = glm::dot(ng, ray.direction) < 0.0;
    s.geometric = s.entering ? ng : -ng;
    const TriangleMesh& mesh = scene_.mesh;
    const size_t i0 = size_t(h.prim) * 3;
    dvec3 n = ng;
    if (!mesh.normals.empty()) {
      n = w * dvec3(mesh.normals[i0]) + h.u * dvec3(mesh.normals[i0 + 1]) + h.v * dvec3(mesh.normals[i0 + 2]);
      const double nl = glm::length(n);
      n = nl > 1e-300 && std::isfinite(nl) ? n / nl : ng;
    }
    s.normal = glm::dot(n, s.geometric) < 0.0 ? -n : n;
    s.material = mesh.material_ids[size_t(h.prim)];
    if (!mesh.texcoords.empty()) {
      const dvec2 uv = w * dvec2(mesh.texcoords[i0]) + h.u * dvec2(mesh.texcoords[i0 + 1]) +
                       h.v * dvec2(mesh.texcoords[i0 + 2]);
      // KHR_texture_transform, in double like the rest.
      s.texcoord = dvec2(glm::dmat3(scene_.materials[s.material].texture_transform) * glm::dvec3(uv, 1.0));
    }
    return s;
  }

  double offset(const dvec3& p) const { return settings_.epsilon * (1.0 + max_abs(p)); }

  // The renderer's shadow rays (raytree/hits.cpp), in double and with the watertight test.
  uint32_t shadow_mask(const SurfaceD& s, const DRay& ray) const {
    uint32_t mask = 0;
    const dvec3 ng = s.ng_raw;
    const double view_side = glm::dot(ng, ray.direction) < 0.0 ? 1.0 : -1.0;
    const dvec3 origin = s.position + (view_side * offset(s.position)) * glm::normalize(ng);
    for (size_t l = 0; l < scene_.lights.size(); ++l) {
      const Light& light = scene_.lights[l];
      const bool directional = light.type == LightType::Directional;
      const dvec3 to_light = directional ? -dvec3(light.direction) : dvec3(light.position) - origin;
      bool lit = glm::dot(ng, to_light) * view_side > 0.0;
      if (lit && light.type == LightType::Spot) {
        lit = glm::dot(glm::normalize(-to_light), dvec3(light.direction)) > std::cos(double(light.outer_cone));
      }
      if (!lit) continue;
      const DRay shadow{origin, to_light, 0.0, directional ? kInf : 1.0};
      if (bvh_.intersect(shadow, s.prim, true).prim < 0) mask |= 1u << l;
    }
    return mask;
  }

  // glsl/shade.glsl's shade_hit() in double.
  dvec3 phong(const SurfaceD& s, const dvec3& view_in, uint32_t mask) const {
    const dvec3 view = glm::normalize(view_in);
    const Material& m = scene_.materials[s.material];
    dvec3 diffuse(m.diffuse);
    if (m.texture >= 0 && size_t(m.texture) < textures_.size()) {
      diffuse *= sample_texture(textures_[size_t(m.texture)], s.texcoord);
    }
    return mobirt::phong<double>(scene_.lights, m, diffuse, s.position, s.normal, view, mask);
  }

  // raytree/secondary.cpp's next_generation() for one hit, traced at once.
  dvec3 secondary(const SurfaceD& s, const DRay& ray, const dvec3& weight, int generation) const {
    const Material& m = scene_.materials[s.material];
    if (m.reflectance <= 0.0f && m.transmittance <= 0.0f) return dvec3(0.0);
    const dvec3 d = glm::normalize(ray.direction);
    const dvec3& ng = s.geometric;
    const dvec3& ns = s.normal;
    const double off = offset(s.position);
    const WeightSplit<double> split = split_weight(m, d, ns, ng, s.entering);
    dvec3 color(0.0);
    auto emit = [&](const dvec3& origin, const dvec3& dir, const dvec3& w) {
      const double largest = std::max(w.x, std::max(w.y, w.z));
      if (largest <= 0.0 || largest < settings_.min_weight) return;
      color += trace(DRay{origin, dir, 0.0, kInf}, s.prim, w, generation + 1, nullptr, nullptr);
    };
    if (split.reflect > 0.0) emit(s.position + off * ng, mirror_direction(d, ns, ng), weight * split.reflect);
    if (split.refract > 0.0) emit(s.position - off * ng, split.refracted, weight * split.refract);
    return color;
  }

  const Scene& scene_;
  ReferenceSettings settings_;
  Bvh bvh_;
  std::vector<RefTexture> textures_;
  uint32_t all_lights_ = 0;
  int depth_ = 0;
};

DRay camera_ray_d(const Camera& camera, int width, int height, double x, double y) {
  const dvec3 eye(camera.eye);
  const dvec3 forward = glm::normalize(dvec3(camera.target) - eye);
  const dvec3 right = glm::normalize(glm::cross(forward, dvec3(camera.up)));
  const dvec3 up = glm::cross(right, forward);
  const double tan_half = std::tan(0.5 * double(camera.yfov));
  const double aspect = double(width) / double(height);
  const double sx = (2.0 * x / double(width) - 1.0) * tan_half * aspect;
  const double sy = (1.0 - 2.0 * y / double(height)) * tan_half;
  return DRay{eye, glm::normalize(forward + sx * right + sy * up), double(camera.znear), kInf};
}

}  // namespace

bool intersect_watertight(const dvec3& origin, const dvec3& direction, const dvec3& a, const dvec3& b,
                          const dvec3& c, double tmin, double tmax, double& t, double& u, double& v) {
  const dvec3 ad = glm::abs(direction);
  const int kz = ad.x >= ad.y && ad.x >= ad.z ? 0 : (ad.y >= ad.z ? 1 : 2);
  if (!(ad[kz] > 0.0)) return false;  // a zero (or NaN) direction hits nothing
  int kx = (kz + 1) % 3;
  int ky = (kx + 1) % 3;
  if (direction[kz] < 0.0) std::swap(kx, ky);  // keep the winding
  const double sx = direction[kx] / direction[kz];
  const double sy = direction[ky] / direction[kz];
  const double sz = 1.0 / direction[kz];
  const dvec3 A = a - origin, B = b - origin, C = c - origin;
  const double ax = A[kx] - sx * A[kz], ay = A[ky] - sy * A[kz];
  const double bx = B[kx] - sx * B[kz], by = B[ky] - sy * B[kz];
  const double cx = C[kx] - sx * C[kz], cy = C[ky] - sy * C[kz];
  // Each edge function depends only on its edge's two sheared vertices, and the neighbour across
  // a shared edge computes exactly its negation: no ray slips between two triangles. (The paper's
  // higher-precision retry for zero values is left out on purpose: recomputing some triangles'
  // edges at another precision than their neighbours' breaks that consistency.)
  const double U = cx * by - cy * bx;
  const double V = ax * cy - ay * cx;
  const double W = bx * ay - by * ax;
  if ((U < 0.0 || V < 0.0 || W < 0.0) && (U > 0.0 || V > 0.0 || W > 0.0)) return false;
  const double det = U + V + W;
  if (det == 0.0 || !std::isfinite(det)) return false;
  const double T = U * (sz * A[kz]) + V * (sz * B[kz]) + W * (sz * C[kz]);
  const double tt = T / det;
  if (!(tt >= tmin && tt <= tmax)) return false;
  t = tt;
  u = V / det;
  v = W / det;
  return true;
}

ReferenceSettings reference_settings(const RenderSettings& settings) {
  ReferenceSettings r;
  r.width = settings.width;
  r.height = settings.height;
  r.depth = settings.depth;
  r.shadows = settings.shadows;
  return r;
}

ReferenceResult render_reference(const Scene& scene, const Camera& camera, const ReferenceSettings& settings) {
  const auto start = std::chrono::steady_clock::now();
  const Tracer tracer(scene, settings);
  ReferenceResult result;
  result.image = Image(settings.width, settings.height);
  const size_t n = size_t(settings.width) * size_t(settings.height);
  result.primary_prim.assign(n, -1);
  result.primary_mask.assign(n, 0u);
  const unsigned threads = settings.threads > 0 ? settings.threads : std::max(1u, std::thread::hardware_concurrency());
  std::atomic<int> next_row{0};
  std::vector<std::exception_ptr> errors(threads);
  std::vector<std::thread> pool;
  for (unsigned w = 0; w < threads; ++w) {
    pool.emplace_back([&, w] {
      try {
        for (int y = next_row++; y < settings.height; y = next_row++) {
          for (int x = 0; x < settings.width; ++x) {
            const size_t i = size_t(y) * size_t(settings.width) + size_t(x);
            const DRay ray = camera_ray_d(camera, settings.width, settings.height, x + 0.5, y + 0.5);
            const dvec3 c = tracer.trace(ray, -1, dvec3(1.0), 0, &result.primary_prim[i], &result.primary_mask[i]);
            result.image.pixels[i] = glm::vec3(c);
          }
        }
      } catch (...) {
        errors[w] = std::current_exception();
        next_row = settings.height;
      }
    });
  }
  for (std::thread& t : pool) t.join();
  for (const std::exception_ptr& e : errors) {
    if (e) std::rethrow_exception(e);
  }
  result.elapsed_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace mobirt
