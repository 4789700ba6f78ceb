// The reference tracer (src/reference/) against answers known in closed form: a lit plane's
// radiance, a tessellated sphere's silhouette, a mirror, the lateral shift of a glass slab, total
// internal reflection, and a box's shadow on a plane. Each expectation is computed here in double,
// independently of the tracer.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "reference/reference.h"
#include "test_scenes.h"
#include "test_support.h"

namespace mobirt {
namespace {

using dvec3 = glm::dvec3;

// The camera ray of pixel (x, y), as the model defines it (core/camera.cpp), in double.
dvec3 pixel_direction(const Camera& c, int w, int h, int x, int y) {
  const dvec3 f = glm::normalize(dvec3(c.target) - dvec3(c.eye));
  const dvec3 r = glm::normalize(glm::cross(f, dvec3(c.up)));
  const dvec3 u = glm::cross(r, f);
  const double t = std::tan(0.5 * double(c.yfov));
  const double sx = (2.0 * (x + 0.5) / w - 1.0) * t * double(w) / double(h);
  const double sy = (1.0 - 2.0 * (y + 0.5) / h) * t;
  return glm::normalize(f + sx * r + sy * u);
}

ReferenceSettings small(int w, int h, int depth, bool shadows) {
  ReferenceSettings s;
  s.width = w;
  s.height = h;
  s.depth = depth;
  s.shadows = shadows;
  return s;
}

Material plain(glm::vec3 diffuse) {
  Material m;
  m.diffuse = diffuse;
  m.specular = glm::vec3(0.0f);
  return m;
}

void add_quad_z(Scene& s, double z, double half, uint32_t material, bool facing_plus_z) {
  const float h = float(half), zf = float(z);
  if (facing_plus_z) {
    test::add_triangle(s, {-h, -h, zf}, {h, -h, zf}, {h, h, zf}, material);
    test::add_triangle(s, {-h, -h, zf}, {h, h, zf}, {-h, h, zf}, material);
  } else {
    test::add_triangle(s, {-h, -h, zf}, {h, h, zf}, {h, -h, zf}, material);
    test::add_triangle(s, {-h, -h, zf}, {-h, h, zf}, {h, h, zf}, material);
  }
}

TEST(Reference, LitPlaneRadianceIsThePhongFormula) {
  Scene s;
  s.source = "plane";
  Material m = plain({0.6f, 0.5f, 0.4f});
  m.specular = glm::vec3(0.3f);
  m.shininess = 20.0f;
  s.materials = {m};
  add_quad_z(s, 0.0, 10.0, 0, true);
  Light point;
  point.position = {0.5f, -0.25f, 2.0f};
  point.intensity = 2.5f;
  point.range = 6.0f;
  Light spot;
  spot.type = LightType::Spot;
  spot.position = {-1.0f, 0.5f, 3.0f};
  spot.direction = glm::normalize(glm::vec3(0.2f, -0.1f, -1.0f));
  spot.inner_cone = 0.2f;
  spot.outer_cone = 0.5f;
  spot.intensity = 4.0f;
  spot.color = {1.0f, 0.8f, 0.6f};
  s.lights = {point, spot};
  const Camera cam{{0.3f, -2.0f, 4.0f}, {0.0f, 0.0f, 0.0f}, {0.0f, 1.0f, 0.0f}, 0.9f, 0.0f};
  const int w = 48, h = 32;
  const ReferenceResult r = render_reference(s, cam, small(w, h, 0, true));
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const dvec3 d = pixel_direction(cam, w, h, x, y);
      const dvec3 e(cam.eye);
      const dvec3 p = e + (-e.z / d.z) * d;
      const dvec3 n(0, 0, 1), v = -d;
      const dvec3 kd(m.diffuse);
      dvec3 c = 0.1 * kd;
      for (const Light& l : s.lights) {
        const dvec3 to = dvec3(l.position) - p;
        const double d2 = glm::dot(to, to);
        double fall = 1.0 / d2;
        if (l.range > 0) fall *= std::pow(std::clamp(1.0 - std::pow(d2 / (double(l.range) * l.range), 2), 0.0, 1.0), 2);
        const dvec3 ld = glm::normalize(to);
        if (l.type == LightType::Spot) {
          const double co = std::cos(double(l.outer_cone)), ci = std::cos(double(l.inner_cone));
          const double cone = std::clamp((glm::dot(-ld, dvec3(l.direction)) - co) / (ci - co), 0.0, 1.0);
          fall *= cone * cone;
        }
        const double ndl = glm::dot(n, ld);
        if (ndl <= 0) continue;
        const dvec3 refl = 2.0 * ndl * n - ld;
        const double spec = std::pow(std::max(glm::dot(refl, v), 0.0), double(m.shininess));
        c += fall * dvec3(l.color) * double(l.intensity) * (kd * ndl + dvec3(m.specular) * spec);
      }
      c = glm::clamp(c, 0.0, 1.0);
      const glm::vec3 got = r.image.at(x, y);
      ASSERT_NEAR(got.x, c.x, 2e-6) << x << "," << y;
      ASSERT_NEAR(got.y, c.y, 2e-6) << x << "," << y;
      ASSERT_NEAR(got.z, c.z, 2e-6) << x << "," << y;
      EXPECT_GE(r.primary_prim[size_t(y) * w + x], 0);
    }
  }
}

// A UV sphere with vertices on the sphere: every ray closer to the centre than the polyhedron's
// inscribed radius hits (no cracks at shared edges and vertices), every ray farther than R misses.
TEST(Reference, TessellatedSphereSilhouetteIsWatertight) {
  Scene s;
  s.source = "sphere";
  s.materials = {plain({0.8f, 0.8f, 0.8f})};
  const int rings = 24, segments = 48;
  const double R = 1.0;
  auto at = [&](int i, int j) {
    // j = segments is j = 0 exactly (sin(2 pi) is not 0 in double: that would open a seam).
    const double th = std::numbers::pi * i / rings, ph = 2.0 * std::numbers::pi * (j % segments) / segments;
    return glm::vec3(float(R * std::sin(th) * std::cos(ph)), float(R * std::cos(th)), float(R * std::sin(th) * std::sin(ph)));
  };
  for (int i = 0; i < rings; ++i) {
    for (int j = 0; j < segments; ++j) {
      const glm::vec3 a = at(i, j), b = at(i + 1, j), c = at(i + 1, j + 1), d = at(i, j + 1);
      if (i > 0) test::add_triangle(s, a, d, c, 0);
      if (i < rings - 1) test::add_triangle(s, a, c, b, 0);
    }
  }
  Light l;
  l.position = {2, 3, 4};
  s.lights = {l};
  // The camera looks at a pole, so that many rays pass through the shared vertex and edges there.
  const Camera cam{{0.0f, 4.0f, 0.0f}, {0.0f, 0.0f, 0.0f}, {0.0f, 0.0f, -1.0f}, 0.6f, 0.0f};
  const int w = 81, h = 81;
  const ReferenceResult r = render_reference(s, cam, small(w, h, 0, true));
  // Inscribed radius of the polyhedron: the faces' smallest distance to the centre.
  const double inner = R * std::cos(std::numbers::pi / rings) * std::cos(std::numbers::pi / segments) - 1e-6;
  int must_hit = 0, must_miss = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const dvec3 d = pixel_direction(cam, w, h, x, y);
      const dvec3 e(cam.eye);
      const double dist = glm::length(glm::cross(-e, d));  // ray's distance to the centre
      const int32_t prim = r.primary_prim[size_t(y) * w + x];
      if (dist < inner) {
        ++must_hit;
        EXPECT_GE(prim, 0) << "crack at pixel " << x << "," << y;
      } else if (dist > R * (1 + 1e-9)) {
        ++must_miss;
        EXPECT_LT(prim, 0) << "hit outside the sphere at " << x << "," << y;
      }
    }
  }
  EXPECT_GT(must_hit, 1000);
  EXPECT_GT(must_miss, 1000);
  // The centre pixel's ray goes exactly through the pole vertex shared by 48 triangles.
  EXPECT_GE(r.primary_prim[size_t(h / 2) * w + w / 2], 0);
}

TEST(Reference, WatertightTestHitsSharedEdgesAndVertices) {
  // A fan of 8 triangles around the origin in z = 0; rays along -z through the shared vertex and
  // through each shared edge hit at least one triangle.
  std::vector<dvec3> rim;
  for (int k = 0; k < 8; ++k) rim.emplace_back(std::cos(k * std::numbers::pi / 4), std::sin(k * std::numbers::pi / 4), 0.0);
  auto hits = [&](dvec3 o) {
    int count = 0;
    for (int k = 0; k < 8; ++k) {
      double t, u, v;
      if (intersect_watertight(o, {0, 0, -1}, dvec3(0.0), rim[k], rim[(k + 1) % 8], 0.0, 1e30, t, u, v)) {
        EXPECT_NEAR(t, 1.0, 1e-12);
        ++count;
      }
    }
    return count;
  };
  EXPECT_GE(hits({0, 0, 1}), 1);
  for (int k = 0; k < 8; ++k) {
    for (double s : {0.1, 0.3, 0.7, 0.93}) EXPECT_GE(hits(dvec3(s * rim[k].x, s * rim[k].y, 1.0)), 1) << k << " " << s;
  }
  double t, u, v;
  // Degenerate, zero direction and NaN: no hit.
  EXPECT_FALSE(intersect_watertight({0, 0, 1}, {0, 0, -1}, dvec3(0.0), {1, 0, 0}, {2, 0, 0}, 0, 1e30, t, u, v));
  EXPECT_FALSE(intersect_watertight({0, 0, 1}, {0, 0, 0}, dvec3(0.0), {1, 0, 0}, {0, 1, 0}, 0, 1e30, t, u, v));
  EXPECT_FALSE(intersect_watertight({0, 0, 1}, {0, 0, -1}, dvec3(NAN), {1, 0, 0}, {0, 1, 0}, 0, 1e30, t, u, v));
}

// A perfect mirror at z = 0 shows a wall behind the camera, red for x < 0 and green for x > 0,
// lit head-on by a directional light (shadows off): each mirror pixel is the wall's colour at the
// mirrored ray's end.
TEST(Reference, MirrorShowsTheReflectedWall) {
  Scene s;
  s.source = "mirror";
  Material mirror = plain({0, 0, 0});
  mirror.reflectance = 1.0f;
  mirror.ambient = 0.0f;
  s.materials = {mirror, plain({0.5f, 0, 0}), plain({0, 0.5f, 0})};
  add_quad_z(s, 0.0, 3.0, 0, true);
  // The wall at z = 10 facing -z, two halves.
  test::add_triangle(s, {-50, -50, 10}, {0, 50, 10}, {0, -50, 10}, 1);
  test::add_triangle(s, {-50, -50, 10}, {-50, 50, 10}, {0, 50, 10}, 1);
  test::add_triangle(s, {0, -50, 10}, {50, 50, 10}, {50, -50, 10}, 2);
  test::add_triangle(s, {0, -50, 10}, {0, 50, 10}, {50, 50, 10}, 2);
  Light sun;
  sun.type = LightType::Directional;
  sun.direction = {0, 0, 1};
  s.lights = {sun};
  const Camera cam{{0.7f, 0.2f, 5.0f}, {0.0f, 0.0f, 0.0f}, {0.0f, 1.0f, 0.0f}, 0.8f, 0.0f};
  const int w = 64, h = 48;
  const ReferenceResult r = render_reference(s, cam, small(w, h, 1, false));
  int checked = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const dvec3 d = pixel_direction(cam, w, h, x, y);
      const dvec3 e(cam.eye);
      const dvec3 m = e + (-e.z / d.z) * d;
      if (std::abs(m.x) > 3 || std::abs(m.y) > 3) continue;
      const dvec3 rd(d.x, d.y, -d.z);
      const dvec3 wall = m + (10.0 / rd.z) * rd;
      if (std::abs(wall.x) < 1e-9) continue;
      const glm::vec3 want = wall.x < 0 ? glm::vec3(0.55f, 0, 0) : glm::vec3(0, 0.55f, 0);
      test::expect_vec3(r.image.at(x, y), want, 1e-6f);
      ++checked;
    }
  }
  EXPECT_GT(checked, 500);
}

// A glass slab (z in [-1, 0], ior 1.5, clear, Fresnel off) before a two-coloured wall at z = -3:
// every pixel shows the side of the wall that the refracted, laterally shifted ray reaches.
TEST(Reference, GlassSlabShiftsTheRayLaterally) {
  Scene s;
  s.source = "slab";
  Material glass = plain({0, 0, 0});
  glass.transmittance = 1.0f;
  glass.ior = 1.5f;
  glass.fresnel = false;
  glass.ambient = 0.0f;
  s.materials = {glass, plain({0.5f, 0, 0}), plain({0, 0.5f, 0})};
  test::add_box(s, {-50, -50, -1}, {50, 50, 0}, 0);
  const float split = 0.3f;
  test::add_triangle(s, {-60, -60, -3}, {split, -60, -3}, {split, 60, -3}, 1);
  test::add_triangle(s, {-60, -60, -3}, {split, 60, -3}, {-60, 60, -3}, 1);
  test::add_triangle(s, {split, -60, -3}, {60, -60, -3}, {60, 60, -3}, 2);
  test::add_triangle(s, {split, -60, -3}, {60, 60, -3}, {split, 60, -3}, 2);
  Light sun;
  sun.type = LightType::Directional;
  sun.direction = {0, 0, -1};
  s.lights = {sun};
  const Camera cam{{-1.5f, 0.0f, 2.0f}, {0.5f, 0.0f, -3.0f}, {0.0f, 1.0f, 0.0f}, 0.7f, 0.0f};
  const int w = 64, h = 32;
  const ReferenceResult r = render_reference(s, cam, small(w, h, 3, false));
  int shifted = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const dvec3 d = pixel_direction(cam, w, h, x, y);
      const dvec3 e(cam.eye);
      const dvec3 p0 = e + (-e.z / d.z) * d;  // enters the slab
      const double eta = 1.0 / 1.5, ci = -d.z;
      const dvec3 n(0, 0, 1);
      const dvec3 t = glm::normalize(eta * d + (eta * ci - std::sqrt(1 - eta * eta * (1 - ci * ci))) * n);
      const dvec3 p1 = p0 + (1.0 / -t.z) * t;  // leaves at z = -1, direction d again
      const dvec3 wall = p1 + (2.0 / -d.z) * d;
      const dvec3 straight = e + ((e.z + 3.0) / -d.z) * d;
      if (std::abs(wall.x - split) < 1e-6) continue;
      const glm::vec3 want = wall.x < split ? glm::vec3(0.55f, 0, 0) : glm::vec3(0, 0.55f, 0);
      test::expect_vec3(r.image.at(x, y), want, 1e-6f);
      if ((wall.x < split) != (straight.x < split)) ++shifted;
    }
  }
  EXPECT_GT(shifted, 20);  // pixels where an unbent ray would show the other colour
}

// The camera inside a glass block looks up at its top face: rays steeper than the critical angle
// (asin(1 / 1.5)) leave into the blue background, the others are totally reflected onto a red
// floor inside the glass.
TEST(Reference, TotalInternalReflectionBeyondTheCriticalAngle) {
  Scene s;
  s.source = "tir";
  Material glass = plain({0, 0, 0});
  glass.transmittance = 1.0f;
  glass.ior = 1.5f;
  glass.fresnel = false;
  glass.ambient = 0.0f;
  s.materials = {glass, plain({0.5f, 0, 0})};
  test::add_box(s, {-100, -100, -100}, {100, 1, 100}, 0);
  test::add_triangle(s, {-90, -1, -90}, {-90, -1, 90}, {90, -1, 90}, 1);
  test::add_triangle(s, {-90, -1, -90}, {90, -1, 90}, {90, -1, -90}, 1);
  s.background = {0, 0, 1};
  Light sun;
  sun.type = LightType::Directional;
  sun.direction = {0, -1, 0};
  s.lights = {sun};
  const Camera cam{{0.0f, 0.0f, 0.0f}, {0.0f, 1.0f, 0.0f}, {0.0f, 0.0f, -1.0f}, 2.0f, 0.0f};
  const int w = 48, h = 48;
  const ReferenceResult r = render_reference(s, cam, small(w, h, 1, false));
  int tir = 0, out = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const dvec3 d = pixel_direction(cam, w, h, x, y);
      const double k = 1.5 * 1.5 * (1 - d.y * d.y) - 1.0;
      if (std::abs(k) < 1e-9) continue;
      if (k > 0) {
        test::expect_vec3(r.image.at(x, y), {0.55f, 0, 0}, 1e-6f);
        ++tir;
      } else {
        test::expect_vec3(r.image.at(x, y), {0, 0, 1}, 1e-6f);
        ++out;
      }
    }
  }
  EXPECT_GT(tir, 100);
  EXPECT_GT(out, 100);
}

// A box floating over a plane under a tilted directional light: a floor pixel is in shadow
// exactly when the ray from its point towards the light passes through the box.
TEST(Reference, BoxShadowMatchesTheAnalyticRegion) {
  Scene s;
  s.source = "shadow";
  s.materials = {plain({0.7f, 0.7f, 0.7f}), plain({0.3f, 0.3f, 0.8f})};
  test::add_triangle(s, {-10, 0, -10}, {-10, 0, 10}, {10, 0, 10}, 0);
  test::add_triangle(s, {-10, 0, -10}, {10, 0, 10}, {10, 0, -10}, 0);
  const dvec3 lo(-1, 1, -0.5), hi(1, 2, 0.5);
  test::add_box(s, glm::vec3(lo), glm::vec3(hi), 1);
  Light sun;
  sun.type = LightType::Directional;
  sun.direction = glm::normalize(glm::vec3(0.5f, -1.0f, 0.3f));
  s.lights = {sun};
  const Camera cam{{0.0f, 8.0f, 6.0f}, {0.5f, 0.0f, 0.0f}, {0.0f, 1.0f, 0.0f}, 0.8f, 0.0f};
  const int w = 96, h = 64;
  const ReferenceResult r = render_reference(s, cam, small(w, h, 0, true));
  const dvec3 to_light = -dvec3(sun.direction);
  int shadowed = 0, lit = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const size_t i = size_t(y) * w + x;
      if (r.primary_prim[i] > 1 || r.primary_prim[i] < 0) continue;  // floor pixels only
      const dvec3 d = pixel_direction(cam, w, h, x, y);
      const dvec3 e(cam.eye);
      const dvec3 p = e + (-e.y / d.y) * d;
      double t0 = 0, t1 = 1e30;
      for (int a = 0; a < 3; ++a) {
        double tn = (lo[a] - p[a]) / to_light[a], tf = (hi[a] - p[a]) / to_light[a];
        if (tn > tf) std::swap(tn, tf);
        t0 = std::max(t0, tn);
        t1 = std::min(t1, tf);
      }
      if (std::abs(t1 - t0) < 1e-6) continue;  // grazing an edge of the box
      const bool in_shadow = t0 < t1;
      EXPECT_EQ(r.primary_mask[i], in_shadow ? 0u : 1u) << x << "," << y;
      const float want = in_shadow ? 0.07f : float(0.7 * (0.1 + glm::dot(dvec3(0, 1, 0), to_light)));
      test::expect_vec3(r.image.at(x, y), glm::vec3(want), 1e-6f);
      (in_shadow ? shadowed : lit)++;
    }
  }
  EXPECT_GT(shadowed, 100);
  EXPECT_GT(lit, 1000);
}

TEST(Reference, NonFiniteVertexIsAClearError) {
  Scene s = test::box_grid_scene();
  s.mesh.positions[4].y = NAN;
  test::expect_bad_input([&] { render_reference(s, *s.camera, small(8, 8, 0, true)); },
                         {"box-grid", "triangle 1", "non-finite"});
}

TEST(Reference, EmptySceneIsBackground) {
  Scene s;
  s.source = "empty";
  s.materials = {plain({1, 1, 1})};
  s.background = {0.2f, 0.3f, 0.4f};
  const ReferenceResult r = render_reference(s, Camera{}, small(8, 8, 2, true));
  for (const glm::vec3& p : r.image.pixels) test::expect_vec3(p, {0.2f, 0.3f, 0.4f});
  for (int32_t p : r.primary_prim) EXPECT_EQ(p, -1);
}

}  // namespace
}  // namespace mobirt
