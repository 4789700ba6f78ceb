// Closed surfaces of a triangle soup, and the faces a shadow ray can do without.
//
// A segment from any point to a light that lies outside a closed, consistently wound surface that
// does not cross itself crosses that surface an even number of times past its start if the start
// is outside, an odd number if inside, and in both cases its last crossing leaves the surface
// towards the light: through a face turned towards the light. Every crossing of a face turned away
// from the light is followed by one of a face turned towards it, further along (the winding number
// along the segment is 0 or 1 and ends at 0). So whether the segment is blocked does not change
// when the faces turned away are left out (Haines and Greenberg's light buffer lists,
// src/accel/light_buffer.h). For a point light outside a closed mesh that is about half of its
// faces: shorter lists, fewer tests per shadow ray, a cheaper build.
//
// find_closed_parts() welds the soup's corners once (those within kWeld, about two millionths, of
// their own largest coordinate: a generated sphere's seam and poles), finds the parts joined
// through shared edges, and keeps those that are closed two-manifolds wound one way (every
// directed edge met once each way; triangles with two corners welded together are left out of
// the topology and stay in the lists) and enclose a volume. Posing moves the vertices, not the
// topology: pose_closed_parts() checks once a frame that the corners are finite and the welded
// ones still meet (a part torn apart counts as open that frame) and takes the winding from the
// part's signed volume as posed (a mirrored pose turns it); light_windings() then keeps, per
// light, every face of a part whose box the light is not well outside of.
//
// Not checked: a part that passes through itself with a fold turned inside out (winding -1 inside
// the fold) breaks the argument; models do not do that, a bad skin or morph could. And the front
// faces are then the only blockers: a segment through a shared edge that the float triangle test
// misses on both sides (Moller-Trumbore's crack, README *Accuracy*) is no longer caught by a back
// face behind it. The renderer leaves faces out of the light buffers only under highp (its raster
// passes, faces_turned_away, draw watertight and leave them out at any precision).
#pragma once

#include <glm/glm.hpp>

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace mobirt {

inline constexpr uint32_t kOpenPart = 0xFFFFFFFFu;
// AnimatedScene analyses meshes up to this size (about 30 ms per 10,000 triangles, once per scene);
// light buffers are built by default up to a quarter of it (kAutoShadowCellsTriangles).
inline constexpr size_t kClosedPartsMaxTriangles = size_t(1) << 17;

struct ClosedParts {
  size_t triangles = 0;               // of the soup analysed
  std::vector<uint32_t> part;         // per triangle: its closed part, or kOpenPart
  std::vector<float> orientation;     // per closed part: +1 wound outwards (positive volume), -1 inwards
  // The welds: corners corners[first[v] .. first[v + 1]) (3 t + k) were welded into one vertex (v
  // a vertex with more than one corner; corners of open parts included).
  std::vector<uint32_t> corners, first;
  std::vector<float> weld_tolerance;  // per weld group: its corners' spread at analysis
  size_t parts() const { return orientation.size(); }
};

// The closed parts of the triangles `positions` (three vertices each).
ClosedParts find_closed_parts(std::span<const glm::vec3> positions);

// The closed parts as posed in one frame, measured once for all of its lights: each part's box, and
// its winding now (+1 outwards, -1 inwards: the sign of its volume now), 0 where a corner is not
// finite or a weld no longer holds (the part counts as open this frame).
struct PosedParts {
  const ClosedParts* of = nullptr;  // null where the analysis is of another soup: nothing left out
  std::vector<glm::vec3> lo, hi;
  std::vector<int8_t> winding;
  float largest = 0.0f;  // the largest coordinate magnitude of the parts' boxes
};
PosedParts pose_closed_parts(const ClosedParts& parts, std::span<const glm::vec3> positions);

// winding[t] for triangle t of `positions` (the soup find_closed_parts analysed, posed anew): the
// winding of its closed part as posed where that part is valid this frame and `light` lies outside
// its box by a ten-thousandth of the largest coordinate (the light's included), so that the
// triangle may be left out of the light's shadow lists if it faces away from the light
// (faces_away); 0 elsewhere: it stays. Sized to the triangle count; all 0 where `posed` is of
// another soup. `posed` is pose_closed_parts() of these positions.
void light_windings(const PosedParts& posed, std::span<const glm::vec3> positions, glm::vec3 light,
                    std::vector<int8_t>& winding);
// The same for one light: pose_closed_parts(), then light_windings().
void light_windings(const ClosedParts& parts, std::span<const glm::vec3> positions, glm::vec3 light,
                    std::vector<int8_t>& winding);

// Whether a triangle of winding w (light_windings, not 0) with corners c[0..2] relative to the light
// faces away from it by more than a rounding of its float corners: its plane has the light on its
// inner side. (A triangle within a rounding of edge-on stays.)
inline bool faces_away(const glm::dvec3 (&c)[3], int8_t w) {
  const glm::dvec3 n = glm::cross(c[1] - c[0], c[2] - c[0]) * double(w);
  const double s = -glm::dot(n, c[0]);  // n . (light - c0), the light at the origin
  return s < 0.0 && s * s > 1e-10 * glm::dot(n, n) * glm::dot(c[0], c[0]);
}

// The faces a ray from a viewpoint never meets first, for a raster pass of the nearest triangles
// (the primary hits, Renderer::start_raster, and the mirrored scene, --mirrors): away[t] = 1 where
// triangle t of `positions` lies on a closed part, as posed, whose box `eye` is outside of, and
// faces away from `eye` (light_windings and faces_away, with the eye for the light). A ray from the
// eye enters such a part through a face turned towards the eye before it meets one turned away
// (the header's argument), so leaving those out of the draw changes no pixel's nearest triangle,
// but at a tie on a silhouette edge, or where two faces towards the eye meet at corners welded
// within the tolerance yet not bit for bit the same (the raster may leave a crack between them that
// a face turned away behind it used to fill).
// `rays_from` (optional): where the rays really come from when it is not `eye`. A mirror's
// reflected rays are drawn from the eye's mirror image, but start on the mirror, at points the eye
// sees first: outside every closed part whose box the real eye is outside of, so only those parts
// count. `reach`: how far from the eye the rays start (a camera's near distance: its primary rays
// begin there, and the raster's near plane clips there); a part whose box comes within it of the
// eye (or of `rays_from`) keeps every face, since a ray may start inside it. Sized to the triangle
// count; all 0 where `posed` is of another soup.
void faces_turned_away(const PosedParts& posed, std::span<const glm::vec3> positions, glm::vec3 eye,
                       std::vector<uint8_t>& away, const glm::vec3* rays_from = nullptr, float reach = 0.0f);

}  // namespace mobirt
