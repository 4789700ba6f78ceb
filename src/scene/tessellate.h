// Triangles for the shapes scene files describe by parameters: NFF spheres, cylinders and cones,
// and planar polygons (NFF p/pp, PLY faces), appended to a TriangleMesh.
//
// The NFF reader hands spheres, cylinders and cones over whole, as analytic primitives
// (Scene::shapes), unless asked for triangles (--primitives tessellated); tessellate_shapes turns
// a scene's shapes into triangles for the engines that only take triangles (Embree, the driver's
// ray queries).
#pragma once

#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "scene/scene.h"

namespace mobirt {

// How finely curved surfaces are cut. `segments` is the number of facets around a sphere, a
// cylinder or a cone (>= 3); a sphere has segments / 2 (at least 2) rings from pole to pole.
// Normals are the analytic ones at each vertex, so shading is smooth; only the silhouette is
// polygonal, off the true surface by at most r * (1 - cos(pi / segments)): 0.12 % of the radius
// at the default 64. Measured on the SPD sphereflake (balls_s2, 256x256, depth 2, the
// reference tracer, against 192 segments): 8 -> 24.7 dB, 16 -> 29.9, 32 -> 35.5, 64 -> 42.0 dB;
// mirror balls reflecting each other magnify the silhouettes, hence 64 (361,090 triangles there).
struct Tessellation {
  int segments = 64;
};

// Triangles a sphere, and a cylinder or cone, of `t` add to a mesh (for limits checked before
// anything is allocated).
size_t sphere_triangle_count(const Tessellation& t);
size_t cone_triangle_count(const Tessellation& t);

// A sphere around `center`; a negative radius turns it inside out (normals point inwards and the
// winding is reversed: NFF's "only the inside is visible"). Latitude-longitude grid, the poles
// closed by triangle fans.
void tessellate_sphere(TriangleMesh& mesh, const glm::vec3& center, float radius, uint32_t material,
                       const Tessellation& t);

// The side of a truncated cone (a cylinder when the radii are equal) from `base` to `apex`, without
// end caps (NFF: "the surface exists without endcaps"). Radii may be zero at one end (a pointed
// cone: the triangles there collapse to one per segment). Negative radii (both): inside visible.
// Normals are the cone's analytic normals, tilted by the slope.
void tessellate_cone(TriangleMesh& mesh, const glm::vec3& base, float base_radius, const glm::vec3& apex,
                     float apex_radius, uint32_t material, const Tessellation& t);

// The scene's analytic shapes (Scene::shapes) as triangles appended to its mesh, `shapes` emptied:
// shape k's triangles follow the mesh's own, in order. A scene without shapes is left as it is.
void tessellate_shapes(Scene& scene, const Tessellation& t = {});

// Triangulates a planar polygon (the vertices in order, either winding, convex or concave, no
// holes) by ear clipping in the polygon's plane: the Newell normal picks the plane, the two axes
// of the largest normal component become 2-D coordinates. Returns index triples into `polygon`,
// each triangle wound like the polygon. A convex polygon is fanned from vertex 0 without the ear
// search. A self-intersecting polygon, which has no valid ear at some step, gets the remaining
// vertices clipped anyway (the covered area is then approximate, never a crash). Fewer than 3
// vertices, or no area: no triangles.
std::vector<uint32_t> triangulate_polygon(const std::vector<glm::vec3>& polygon);

// The most vertices a polygon of a scene file may have. Ear clipping takes quadratic time on
// concave polygons: 1.3 s for a 16,000-vertex gear outline, 24 s at 65,536 (one core).
constexpr size_t kMaxPolygonVertices = 16384;

// The Newell normal of a polygon (unit length; zero when the polygon has no area). Its direction
// follows the winding by the right-hand rule.
glm::vec3 polygon_normal(const std::vector<glm::vec3>& polygon);

}  // namespace mobirt
