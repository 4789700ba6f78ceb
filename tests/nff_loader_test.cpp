// NFF: every entity of NFF.TXT parsed with known values, the tessellation of spheres and cones,
// ear clipping of concave polygons, bad files with FILE:LINE errors, the camera and headlight a
// scene without them gets, and every SPD scene of ../shared/scenes/spd loaded and rendered.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include <glm/gtc/constants.hpp>

#include "backend/backend.h"
#include "core/error.h"
#include "render/cpu_render.h"
#include "reference/reference.h"
#include "render/renderer.h"
#include "scene/loader.h"
#include "scene/tessellate.h"
#include "scene/view_defaults.h"
#include "test_support.h"
#include "vulkan_fixture.h"

namespace mobirt {
namespace {

namespace fs = std::filesystem;
using test::expect_bad_input;
using test::expect_vec3;

std::string write_file(const std::string& name, const std::string& text) {
  const fs::path path = test::temp_dir() / name;
  std::ofstream(path, std::ios::binary) << text;
  return path.string();
}

const char* const kEveryEntity = R"(# every entity of NFF.TXT
v
from 1 -10 2
at 0 0 0.5
up 0 0 1
angle 40
hither 0.25
resolution 320 200
b 0.1 0.2 0.3
l 0 0 10
l 5 5 5 1 0.5 0.25   # a coloured light
f 1 0.5 0.25 0.8 0.3 20 0.4 1.33
p 4
0 0 0
1 0 0
1 1 0
0 1 0
pp 3
0 0 1 0 0 1
1 0 1 0 0 1
0 1 1 0.6 0 0.8
f 0 1 0 1 0 100000 0 0
s 3 0 0 0.5
c
0 3 0 0.5
0 3 2 0.5
c
0 6 0 1
0 6 1 0
)";

// Spheres and cones as analytic primitives (the default): one Shape each, radii as given.
TEST(NffLoader, SpheresAndConesAreAnalyticShapesByDefault) {
  const Scene s = load_scene(write_file("every-analytic.nff", kEveryEntity));
  EXPECT_EQ(s.mesh.triangle_count(), 3u);  // p 4 and pp 3
  ASSERT_EQ(s.shapes.size(), 3u);
  EXPECT_EQ(s.primitive_count(), 6u);
  const Shape& sphere = s.shapes[0];
  EXPECT_EQ(sphere.kind, ShapeKind::Sphere);
  expect_vec3(sphere.base, {3, 0, 0});
  EXPECT_FLOAT_EQ(sphere.base_radius, 0.5f);
  EXPECT_FALSE(sphere.inside);
  const Shape& cylinder = s.shapes[1];
  EXPECT_EQ(cylinder.kind, ShapeKind::Cone);
  expect_vec3(cylinder.base, {0, 3, 0});
  expect_vec3(cylinder.apex, {0, 3, 2});
  EXPECT_FLOAT_EQ(cylinder.base_radius, 0.5f);
  EXPECT_FLOAT_EQ(cylinder.apex_radius, 0.5f);
  const Shape& cone = s.shapes[2];
  expect_vec3(cone.apex, {0, 6, 1});
  EXPECT_FLOAT_EQ(cone.base_radius, 1.0f);
  EXPECT_FLOAT_EQ(cone.apex_radius, 0.0f);
  for (const Shape& shape : s.shapes) EXPECT_EQ(shape.material, 1u);
  // The scene's box holds the shapes: the cylinder reaches z = 2, the sphere x = 3.5.
  EXPECT_GE(s.bounds().hi.z, 2.0f);
  EXPECT_GE(s.bounds().hi.x, 3.5f);
}

TEST(NffLoader, EveryEntityWithKnownValues) {
  const Tessellation tess;
  const std::string path = write_file("every.nff", kEveryEntity);
  LoadOptions tessellated;
  tessellated.analytic = false;
  const Scene s = load_scene(path, tessellated);
  EXPECT_EQ(s.source, path);
  ASSERT_TRUE(s.camera);
  expect_vec3(s.camera->eye, {1, -10, 2});
  expect_vec3(s.camera->target, {0, 0, 0.5f});
  expect_vec3(s.camera->up, {0, 0, 1});
  expect_vec3(s.up, {0, 0, 1});
  EXPECT_FLOAT_EQ(s.camera->znear, 0.25f);
  // 40 degrees between the centres of rows 0 and 199: edges at 2 atan(tan(20 deg) * 200 / 199).
  EXPECT_NEAR(s.camera->yfov, 2.0 * std::atan(std::tan(glm::radians(20.0)) * 200.0 / 199.0), 1e-6);
  ASSERT_TRUE(s.image_size);
  EXPECT_EQ(s.image_size->x, 320);
  EXPECT_EQ(s.image_size->y, 200);
  expect_vec3(s.background, {0.1f, 0.2f, 0.3f});

  ASSERT_EQ(s.lights.size(), 2u);
  const float share = std::sqrt(2.0f) / 4.0f;  // SPD: sqrt(n) / (2 n)
  EXPECT_EQ(s.lights[0].type, LightType::Point);
  expect_vec3(s.lights[0].position, {0, 0, 10});
  expect_vec3(s.lights[0].color, {1, 1, 1});
  // Brightness `share` at the look-at point despite the inverse-square falloff.
  EXPECT_NEAR(s.lights[0].intensity, share * 9.5f * 9.5f, 1e-3);
  expect_vec3(s.lights[1].color, {1, 0.5f, 0.25f});
  EXPECT_NEAR(s.lights[1].intensity, share * (25.0f + 25.0f + 4.5f * 4.5f), 1e-3);

  ASSERT_EQ(s.materials.size(), 2u);
  const Material& m = s.materials[0];
  expect_vec3(m.diffuse, {0.8f, 0.4f, 0.2f});
  expect_vec3(m.specular, {0.3f, 0.3f, 0.3f});
  EXPECT_FLOAT_EQ(m.shininess, 20.0f);
  EXPECT_FLOAT_EQ(m.reflectance, 0.3f);
  EXPECT_FLOAT_EQ(m.transmittance, 0.4f);
  EXPECT_FLOAT_EQ(m.ior, 1.33f);
  EXPECT_FALSE(m.fresnel);
  EXPECT_FLOAT_EQ(m.ambient, share);
  const Material& green = s.materials[1];
  expect_vec3(green.diffuse, {0, 1, 0});
  EXPECT_FLOAT_EQ(green.shininess, 1024.0f);  // clamped as MTL's Ns
  EXPECT_FLOAT_EQ(green.reflectance, 0.0f);
  EXPECT_FLOAT_EQ(green.ior, 1.0f);           // 0 in the file: no bending

  // p 4 -> 2 triangles, pp 3 -> 1, then a sphere, a cylinder and a pointed cone (one triangle
  // per segment: the apex row collapses).
  const size_t sphere = sphere_triangle_count(tess);
  const size_t cyl = cone_triangle_count(tess);
  const size_t cone = cone_triangle_count(tess) / 2;
  ASSERT_EQ(s.mesh.triangle_count(), 2 + 1 + sphere + cyl + cone);
  EXPECT_EQ(s.degenerate_triangles, 0u);
  for (size_t t = 0; t < 3; ++t) EXPECT_EQ(s.mesh.material_ids[t], 0u);
  for (size_t t = 3; t < s.mesh.triangle_count(); ++t) EXPECT_EQ(s.mesh.material_ids[t], 1u);
  // The polygon faces +z (counter-clockwise seen from above) with its flat normal.
  for (size_t v = 0; v < 6; ++v) {
    expect_vec3(s.mesh.normals[v], {0, 0, 1});
    EXPECT_FLOAT_EQ(s.mesh.positions[v].z, 0.0f);
  }
  // The patch keeps its vertices' normals.
  expect_vec3(s.mesh.positions[6], {0, 0, 1});
  expect_vec3(s.mesh.normals[8], {0.6f, 0, 0.8f});
  // Sphere: every vertex on the surface, normals outward and radial.
  for (size_t v = 9; v < 9 + 3 * sphere; ++v) {
    const glm::vec3 d = s.mesh.positions[v] - glm::vec3(3, 0, 0);
    EXPECT_NEAR(glm::length(d), 0.5f, 1e-5f);
    expect_vec3(s.mesh.normals[v], d / 0.5f, 1e-4f);
  }
  // Cylinder: radius 0.5 around x = 0, y = 3, normals horizontal and outward.
  for (size_t v = 9 + 3 * sphere; v < 9 + 3 * (sphere + cyl); ++v) {
    const glm::vec3 p = s.mesh.positions[v];
    const glm::vec2 r(p.x, p.y - 3.0f);
    EXPECT_NEAR(glm::length(r), 0.5f, 1e-5f);
    EXPECT_GE(p.z, -1e-6f);
    EXPECT_LE(p.z, 2.0f + 1e-6f);
    expect_vec3(s.mesh.normals[v], glm::vec3(r / 0.5f, 0.0f), 1e-4f);
  }
  // Cone of base radius 1, height 1: the normals lean 45 degrees towards the apex.
  for (size_t v = 9 + 3 * (sphere + cyl); v < s.mesh.positions.size(); ++v) {
    EXPECT_NEAR(s.mesh.normals[v].z, std::sqrt(0.5f), 1e-4f);
  }
}

// Winding: every triangle's geometric normal agrees with its vertex normals (the outside is the
// front), and a negative radius turns both inward.
TEST(NffLoader, SpheresAndConesFaceOutwardsOrInwardsForNegativeRadii) {
  for (const float sign : {1.0f, -1.0f}) {
    TriangleMesh mesh;
    const Tessellation tess{12};
    tessellate_sphere(mesh, {1, 2, 3}, sign * 2.0f, 0, tess);
    tessellate_cone(mesh, {0, 0, 0}, sign * 1.0f, {1, 1, 1}, sign * 0.5f, 0, tess);
    ASSERT_EQ(mesh.triangle_count(), sphere_triangle_count(tess) + cone_triangle_count(tess));
    for (size_t t = 0; t < mesh.triangle_count(); ++t) {
      const glm::vec3* p = &mesh.positions[3 * t];
      const glm::vec3 g = glm::cross(p[1] - p[0], p[2] - p[0]);
      ASSERT_GT(glm::length(g), 0.0f) << "triangle " << t;
      const glm::vec3 n = mesh.normals[3 * t] + mesh.normals[3 * t + 1] + mesh.normals[3 * t + 2];
      EXPECT_GT(glm::dot(g, n), 0.0f) << "triangle " << t << " is wound against its normals";
      const glm::vec3 centroid = (p[0] + p[1] + p[2]) / 3.0f;
      if (t < sphere_triangle_count(tess)) {
        EXPECT_GT(sign * glm::dot(n, centroid - glm::vec3(1, 2, 3)), 0.0f) << "sphere triangle " << t;
      }
    }
  }
  // The tessellated sphere's area approaches 4 pi r^2 as the segments grow.
  auto area = [](int segments) {
    TriangleMesh mesh;
    tessellate_sphere(mesh, {0, 0, 0}, 1.0f, 0, Tessellation{segments});
    double a = 0.0;
    for (size_t t = 0; t < mesh.triangle_count(); ++t) {
      const glm::vec3* p = &mesh.positions[3 * t];
      a += 0.5 * glm::length(glm::cross(p[1] - p[0], p[2] - p[0]));
    }
    return a;
  };
  EXPECT_NEAR(area(64), 4.0 * glm::pi<double>(), 0.01 * 4.0 * glm::pi<double>());
  EXPECT_LT(std::abs(area(64) - 4.0 * glm::pi<double>()), std::abs(area(16) - 4.0 * glm::pi<double>()));
}

// Shoelace area of a 2-D polygon (x, y of each point).
double shoelace(const std::vector<glm::dvec2>& p) {
  double a = 0.0;
  for (size_t i = 0; i < p.size(); ++i) {
    const glm::dvec2 q = p[i], r = p[(i + 1) % p.size()];
    a += q.x * r.y - r.x * q.y;
  }
  return 0.5 * a;
}

bool inside_polygon(const std::vector<glm::dvec2>& p, glm::dvec2 q) {
  bool in = false;
  for (size_t i = 0, j = p.size() - 1; i < p.size(); j = i++) {
    if ((p[i].y > q.y) != (p[j].y > q.y) &&
        q.x < (p[j].x - p[i].x) * (q.y - p[i].y) / (p[j].y - p[i].y) + p[i].x) {
      in = !in;
    }
  }
  return in;
}

// Checks a triangulation of a simple 2-D polygon placed in 3-D by `frame` (columns: the plane's
// x and y axes and its normal): area preserved, every triangle inside, wound like the polygon.
void check_triangulation(const std::vector<glm::dvec2>& poly, const glm::mat3& frame, const std::string& what) {
  std::vector<glm::vec3> points;
  for (const glm::dvec2& q : poly) points.push_back(frame * glm::vec3(float(q.x), float(q.y), 0.0f) + glm::vec3(5, -3, 2));
  const std::vector<uint32_t> tris = triangulate_polygon(points);
  ASSERT_EQ(tris.size(), 3 * (poly.size() - 2)) << what;
  const double want = shoelace(poly);
  double got = 0.0;
  for (size_t t = 0; t < tris.size(); t += 3) {
    const std::vector<glm::dvec2> tri = {poly[tris[t]], poly[tris[t + 1]], poly[tris[t + 2]]};
    const double a = shoelace(tri);
    EXPECT_GE(a * want, -1e-9) << what << ": triangle " << t / 3 << " wound against the polygon";
    got += a;
    if (std::abs(a) > 1e-9) {
      const glm::dvec2 centroid = (tri[0] + tri[1] + tri[2]) / 3.0;
      EXPECT_TRUE(inside_polygon(poly, centroid)) << what << ": triangle " << t / 3 << " lies outside";
    }
  }
  EXPECT_NEAR(got, want, 1e-6 * std::abs(want)) << what << ": area not preserved";
}

// A gear outline as the SPD's gears draw it: 144 vertices, teeth sticking out of a disc.
std::vector<glm::dvec2> gear(int teeth) {
  std::vector<glm::dvec2> p;
  for (int t = 0; t < teeth; ++t) {
    const double a0 = glm::two_pi<double>() * t / teeth, step = glm::two_pi<double>() / teeth / 4.0;
    const double radii[4] = {0.9, 1.0, 1.0, 0.9};
    for (int k = 0; k < 4; ++k) p.push_back(radii[k] * glm::dvec2(std::cos(a0 + k * step), std::sin(a0 + k * step)));
  }
  return p;
}

TEST(NffLoader, ConcavePolygonsKeepTheirAreaAndStayInside) {
  const std::vector<glm::dvec2> l_shape = {{0, 0}, {3, 0}, {3, 1}, {1, 1}, {1, 3}, {0, 3}};
  std::vector<glm::dvec2> star;
  for (int i = 0; i < 10; ++i) {
    const double a = glm::two_pi<double>() * i / 10, r = i % 2 ? 0.4 : 1.0;
    star.push_back({r * std::cos(a), r * std::sin(a)});
  }
  std::vector<glm::dvec2> comb = {{0, 0}, {10, 0}};
  for (int i = 9; i >= 0; --i) {  // teeth hanging from the top edge, right to left
    comb.push_back({i + 1.0, 3});
    comb.push_back({i + 0.5, 0.5});
  }
  comb.push_back({0, 3});
  std::vector<glm::dvec2> collinear = {{0, 0}, {1, 0}, {2, 0}, {2, 2}, {1, 1}, {0, 2}};
  const std::vector<std::pair<std::string, std::vector<glm::dvec2>>> cases = {
      {"L", l_shape}, {"star", star}, {"comb", comb}, {"gear", gear(36)}, {"collinear", collinear}};
  // The plane of the polygon: z = 0, tilted, and mirrored (clockwise seen from its normal).
  const glm::mat3 flat(1.0f);
  const float c = std::cos(0.7f), s = std::sin(0.7f);
  const glm::mat3 tilted = glm::mat3(1, 0, 0, 0, c, s, 0, -s, c) * glm::mat3(c, 0, -s, 0, 1, 0, s, 0, c);
  const glm::mat3 on_side(0, 0, 1, 0, 1, 0, 1, 0, 0);  // x -> z: the polygon lies in the yz plane
  for (const auto& [name, poly] : cases) {
    check_triangulation(poly, flat, name);
    check_triangulation(poly, tilted, name + " tilted");
    check_triangulation(poly, on_side, name + " in the yz plane");
    std::vector<glm::dvec2> reversed(poly.rbegin(), poly.rend());
    check_triangulation(reversed, flat, name + " clockwise");
  }
  EXPECT_EQ(gear(36).size(), 144u);
  // No area, too few vertices: nothing.
  EXPECT_TRUE(triangulate_polygon({{0, 0, 0}, {1, 0, 0}, {2, 0, 0}}).empty());
  EXPECT_TRUE(triangulate_polygon({{0, 0, 0}, {1, 0, 0}}).empty());
  // A self-intersecting bow tie (lobes of unequal area) still ends in 2 triangles; it does not
  // loop. One of equal lobes has no area (its Newell normal vanishes): nothing.
  EXPECT_EQ(triangulate_polygon({{0, 0, 0}, {2, 2, 0}, {2, 0, 0}, {0, 1, 0}}).size(), 6u);
  EXPECT_TRUE(triangulate_polygon({{0, 0, 0}, {1, 1, 0}, {1, 0, 0}, {0, 1, 0}}).empty());
}

TEST(NffLoader, CommentsAndLayout) {
  // '#' starts a comment anywhere; an entity's numbers may share lines or span them.
  const Scene s = load_scene(write_file("layout.nff",
                                        "# header\n"
                                        "f 1 1 1 1 0 1 0 1 # white\n"
                                        "p 3 0 0 0  1 0 0\n"
                                        "  0 1 0\n"
                                        "s 0 0 5 -1\n"));
  EXPECT_EQ(s.mesh.triangle_count(), 1u);
  ASSERT_EQ(s.shapes.size(), 1u);
  EXPECT_FALSE(s.camera);
  EXPECT_FALSE(s.image_size);
  EXPECT_TRUE(s.lights.empty());
  expect_vec3(s.up, {0, 1, 0});
  // The inside-out sphere faces its centre.
  EXPECT_TRUE(s.shapes[0].inside);
  EXPECT_FLOAT_EQ(s.shapes[0].base_radius, 1.0f);
  expect_vec3(shape_normal(s.shapes[0], glm::vec3(0, 0, 6)), {0, 0, -1});
  // Geometry before any 'f' gets the default material.
  const Scene d = load_scene(write_file("nofill.nff", "s 0 0 0 1\n"));
  ASSERT_EQ(d.materials.size(), 1u);
  expect_vec3(d.materials[0].diffuse, Material{}.diffuse);
}

TEST(NffLoader, TessellationIsAParameter) {
  const std::string path = write_file("ball.nff", "s 0 0 0 1\n");
  LoadOptions coarse;
  coarse.analytic = false;
  coarse.tessellation.segments = 8;
  LoadOptions fine = coarse;
  fine.tessellation.segments = 64;
  EXPECT_EQ(load_scene(path, coarse).mesh.triangle_count(), 2u * 8u * 3u);
  EXPECT_EQ(load_scene(path, fine).mesh.triangle_count(), 2u * 64u * 31u);
}

TEST(NffLoader, BadFilesNameTheFileAndTheLine) {
  const std::vector<std::pair<std::string, std::vector<std::string>>> cases = {
      {"f 1 1 1 1 0 1 0 1\nq 1 2 3\n", {"bad.nff:2:", "unknown entity 'q'"}},
      {"s 0 0 0\n", {"bad.nff:1:", "unexpected end of file", "radius"}},
      {"\n\ns 0 0 x 1\n", {"bad.nff:3:", "expected a finite number", "'x'"}},
      {"s 0 0 1e999 1\n", {"bad.nff:1:", "finite number"}},
      {"s 0 0 0 0\n", {"bad.nff:1:", "radius 0"}},
      {"p 2\n0 0 0\n1 0 0\n", {"bad.nff:1:", "integer in [3, 16384]", "'2'"}},
      {"p 4000000000\n0 0 0\n", {"bad.nff:1:", "integer in [3, 16384]"}},
      {"p 4\n0 0 0\n1 0 0\n1 1 0\n", {"bad.nff:4:", "unexpected end of file", "vertex 4 of 4"}},
      {"pp 3\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0\n", {"bad.nff:4:", "normal"}},
      {"c\n0 0 0 1\n0 0 0 1\n", {"bad.nff:1:", "base and apex are the same point"}},
      {"c\n0 0 0 1\n0 0 1 -1\n", {"bad.nff:1:", "differ in sign"}},
      {"v\nfrom 0 0 0\nat 0 0 1\nup 0 1 0\nresolution 10 10\ns 0 0 2 1\n", {"bad.nff:1:", "angle is missing"}},
      {"v\nfrom 0 0 0\nat 0 0 1\nup 0 0 1\nangle 45\ns 0 0 2 1\n", {"bad.nff:1:", "parallel"}},
      {"v\nfrom 0 0 0\nat 0 0 1\nup 0 1 0\nangle 180\n", {"bad.nff:5:", "(0, 180)"}},
      {"v\nfrom 0 0 0\nat 0 0 1\nup 0 1 0\nangle 45\nresolution 0 10\n", {"bad.nff:6:", "image width"}},
      {"l 0 0 0 1 -1 1\ns 0 0 0 1\n", {"bad.nff:1:", "negative"}},
      {"f 1 1 1\n", {"bad.nff:1:", "unexpected end of file", "Kd"}},
      {"", {"bad.nff", "no triangles"}},
      {std::string("\x01\x02\xff garbage", 12), {"bad.nff:1:", "unknown entity '?\?\?'"}},
  };
  for (const auto& [text, parts] : cases) {
    SCOPED_TRACE(text);
    const std::string path = write_file("bad.nff", text);
    expect_bad_input([&] { load_scene(path); }, parts);
  }
  // Over the 24-bit limit: refused before tessellating anything.
  LoadOptions fine;
  fine.analytic = false;
  fine.tessellation.segments = 8192;
  const std::string path = write_file("bad.nff", "f 1 1 1 1 0 1 0 1\ns 0 0 0 1\n");
  expect_bad_input([&] { load_scene(path, fine); }, {"bad.nff:2:", "16777215 primitives"});
}

// ---- a scene without a camera or lights -----------------------------------------------------

TEST(ViewDefaults, FramingCameraHonoursTheUpAxis) {
  Scene s;
  s.mesh.positions = {{-1, -1, 0}, {1, -1, 0}, {0, 1, 2}};
  const Camera y = framing_camera(s, 1.5f);
  const Camera box = frame_box(s.bounds(), 0.7854f, 1.5f);
  expect_vec3(y.eye, box.eye);  // +Y up: exactly the old fallback
  expect_vec3(y.up, {0, 1, 0});
  s.up = {0, 0, 1};
  const Camera z = framing_camera(s, 1.5f);
  expect_vec3(z.up, {0, 0, 1});
  expect_vec3(z.target, box.target);
  EXPECT_NEAR(glm::length(z.eye - z.target), glm::length(box.eye - box.target), 1e-4f);
  // Seen from above its own up axis, as the +Y scene is from above +Y.
  EXPECT_NEAR(glm::dot(glm::normalize(z.eye - z.target), s.up),
              glm::dot(glm::normalize(box.eye - box.target), glm::vec3(0, 1, 0)), 1e-5f);
  s.up = {0, -1, 0};  // upside down: still a valid frame
  const Camera down = framing_camera(s, 1.5f);
  expect_vec3(down.up, {0, -1, 0});
  EXPECT_GT(glm::length(glm::cross(down.target - down.eye, down.up)), 0.1f);
  s.camera = Camera{};
  s.camera->eye = {7, 7, 7};
  expect_vec3(default_camera(s, 1.0f).eye, {7, 7, 7});
}

TEST(ViewDefaults, HeadlightOnlyWithoutLights) {
  Scene s;
  Camera view;
  view.eye = {0, 3, 4};
  view.target = {0, 0, 0};
  ASSERT_TRUE(add_headlight(s, view));
  ASSERT_EQ(s.lights.size(), 1u);
  EXPECT_EQ(s.lights[0].type, LightType::Point);
  expect_vec3(s.lights[0].position, view.eye);
  EXPECT_FLOAT_EQ(s.lights[0].intensity, 25.0f);  // irradiance 1 at the target, 5 away
  EXPECT_FALSE(add_headlight(s, view));
  EXPECT_EQ(s.lights.size(), 1u);
}

TEST(ViewDefaults, TheCommandLineLightsAnUnlitSceneAndSaysSo) {
  const std::string path = write_file("unlit.nff", "f 1 1 1 1 0 1 0 1\np 4\n-1 -1 0\n1 -1 0\n1 1 0\n-1 1 0\n");
  const fs::path out = fs::path(path).parent_path() / "unlit.png";
  const test::CommandResult r = test::run_mobirt("render " + path + " --size 32x24 --depth 0 -o " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("no lights: a headlight at the camera lit it"), std::string::npos) << r.output;
  const Image image = read_image(out.string());
  EXPECT_GT(image.at(16, 12).x, 0.5f) << "the quad faces the headlight";
}

TEST(NffCommandLine, TheFilesResolutionIsTheDefaultImageSize) {
  const std::string path = write_file("sized.nff",
                                      "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 0\nresolution 40 30\n"
                                      "l 0 0 5\nf 1 1 1 1 0 1 0 1\ns 0 0 0 1\n");
  const fs::path dir = fs::path(path).parent_path();
  test::CommandResult r = test::run_mobirt("render " + path + " --depth 0 -o " + (dir / "own.png").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find("headlight"), std::string::npos) << "the file has a light";
  const Image own = read_image((dir / "own.png").string());
  EXPECT_EQ(own.width, 40);
  EXPECT_EQ(own.height, 30);
  EXPECT_GT(own.at(20, 15).x, 0.2f) << "the lit sphere fills the centre";
  r = test::run_mobirt("render " + path + " --depth 0 --size 20x10 -o " + (dir / "given.png").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const Image given = read_image((dir / "given.png").string());
  EXPECT_EQ(given.width, 20);
  EXPECT_EQ(given.height, 10);
}

// Truncated, malformed and over-limit NFF and PLY files: one line, exit 2, no output file.
TEST(NffCommandLine, BadNffAndPlyFilesEndInOneLineWithoutOutput) {
  const std::vector<std::pair<std::string, std::string>> files = {
      {"truncated.nff", "f 1 1 1 1 0 1 0 1\np 4\n0 0 0\n1 0 0\n"},
      {"malformed.nff", "s 0 0 zero 1\n"},
      {"over-limit.nff", "p 20000\n0 0 0\n"},
      {"truncated.ply", "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
                        "property float y\nproperty float z\nend_header\n\1\2\3"},
      {"malformed.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                        "property float z\nend_header\n0 zero 0\n"},
      {"over-limit.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                         "property float z\nelement face 1\nproperty list uint int vertex_indices\nend_header\n"
                         "0 0 0\n1 0 0\n0 1 0\n70000 0 1 2\n"},
  };
  const fs::path dir = test::temp_dir();
  for (const auto& [name, text] : files) {
    SCOPED_TRACE(name);
    std::ofstream(dir / name, std::ios::binary) << text;
    const fs::path out = dir / "out.png";
    const test::CommandResult r = test::run_mobirt("render " + (dir / name).string() + " -o " + out.string());
    EXPECT_EQ(r.exit_code, 2) << r.output;
    EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
    EXPECT_EQ(r.output.rfind("mobirt: error: " + (dir / name).string(), 0), 0u) << r.output;
    EXPECT_FALSE(fs::exists(out));
  }
}

// ---- the SPD scenes ---------------------------------------------------------------------------

std::vector<fs::path> spd_scenes() {
  std::vector<fs::path> files;
  const fs::path dir = test::shared_scenes() / "spd";
  if (test::shared_scenes().empty() || !fs::is_directory(dir)) return files;
  for (const auto& entry : fs::directory_iterator(dir)) {
    if (entry.path().extension() == ".nff") files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  return files;
}

// How many lines of the file start with `word` followed by white space.
size_t count_entities(const fs::path& path, const std::string& word) {
  std::ifstream in(path);
  size_t n = 0;
  for (std::string line; std::getline(in, line);) n += line.rfind(word + " ", 0) == 0;
  return n;
}

class SpdScenes : public test::VulkanTest {};  // and a GLES backend beside it

TEST_F(SpdScenes, EveryNffLoadsWithItsCameraLightsAndMaterialsAndRenders) {
  const std::vector<fs::path> files = spd_scenes();
  if (files.empty()) GTEST_SKIP() << "../shared/scenes/spd is absent";
  const std::unique_ptr<Backend> gles = create_gles_backend(test::validated_options());
  for (const fs::path& file : files) {
    SCOPED_TRACE(file.string());
    const Scene s = load_scene(file.string());
    ASSERT_TRUE(s.camera) << "every SPD scene has a view";
    ASSERT_TRUE(s.image_size);
    EXPECT_EQ(s.image_size->x, 512);
    expect_vec3(s.background, {0.078f, 0.361f, 0.753f});
    EXPECT_EQ(s.lights.size(), count_entities(file, "l"));
    EXPECT_EQ(s.materials.size(), count_entities(file, "f"));
    EXPECT_GE(s.mesh.triangle_count(), count_entities(file, "p") + count_entities(file, "pp"));
    EXPECT_EQ(s.shapes.size(), count_entities(file, "s") + count_entities(file, "c"));
    EXPECT_LT(s.degenerate_triangles, s.mesh.triangle_count() / 100 + 1);

    RenderSettings settings;
    settings.width = 64;
    settings.height = 48;
    settings.depth = 1;
    Renderer renderer(*backend, settings);
    const Image image = renderer.render(s, *s.camera);
    size_t geometry = 0;
    for (int y = 0; y < image.height; ++y) {
      for (int x = 0; x < image.width; ++x) {
        const glm::vec3 p = image.at(x, y);
        ASSERT_TRUE(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z));
        geometry += glm::length(p - s.background) > 0.02f;
      }
    }
    EXPECT_GT(geometry, size_t(image.width * image.height / 20)) << "the camera sees the scene";
    const ImageDiff d = compare_images(image, render_on_cpu(s, *s.camera, settings));
    EXPECT_GE(d.psnr, 40.0) << "GPU against the CPU frame";
    // And against the double-precision reference, both clamped to what is shown (mobirt accuracy).
    auto shown = [](Image im) {
      for (glm::vec3& p : im.pixels) p = glm::clamp(p, 0.0f, 1.0f);
      return im;
    };
    const ReferenceResult ref = render_reference(s, *s.camera, reference_settings(settings));
    const ImageDiff r = compare_images(shown(image), shown(ref.image));
    EXPECT_GE(r.psnr, 45.0) << "GPU against the reference";
    // The GLES backend renders the same image (parity as for the glTF scenes).
    Renderer gles_renderer(*gles, settings);
    const ImageDiff g = compare_images(gles_renderer.render(s, *s.camera), image, 1.0f / 255.0f);
    EXPECT_GE(g.psnr, 45.0) << "GLES against Vulkan";
    EXPECT_LE(g.share_over, 0.005) << "GLES against Vulkan: pixels off by more than 1/255";
    const std::vector<std::string> messages = gles->take_debug_messages();
    EXPECT_TRUE(messages.empty()) << "GLES debug messages:\n" << test::join(messages);
    std::printf("%s: %zu triangles, %zu shapes, %.1f dB against the CPU frame, %.1f dB against the reference, "
                "%.1f dB GLES against Vulkan\n", file.filename().c_str(), s.mesh.triangle_count(), s.shapes.size(),
                d.psnr, r.psnr, g.psnr);
  }
}

}  // namespace
}  // namespace mobirt
