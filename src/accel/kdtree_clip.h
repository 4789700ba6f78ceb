// Split clipping for the kd-tree build (kdtree_build.cpp): the bounds of the parts of a triangle
// inside a node box on each side of a split plane, computed in double precision (Sutherland-
// Hodgman) and rounded outwards to float, so that a reference's box is the tightest float box
// that contains its part of the triangle.
#pragma once

#include <glm/glm.hpp>

namespace mobirt::kdclip {

// An axis-aligned box with indexable bounds (glm's operator[] is a switch).
struct Box {
  float lo[3];
  float hi[3];
};

// The triangle v[0..2] clipped against `box` (inclusive), then split by the plane
// x[axis] = split: `below` gets the bounds of the part with x[axis] <= split, `above` of the part
// with x[axis] >= split, each rounded outwards to float. Returns bit 1 when the below part is not
// empty, bit 2 when the above part is not (0: the triangle misses the box).
int clip_and_split(const glm::vec3* v, const Box& box, int axis, float split, Box& below, Box& above);

// The whole triangle v[0..2] split by the plane x[axis] = split, without clipping it to a box
// first: bounds that contain clip_and_split's with a box that contains the triangle (its edge
// crossings computed in float and padded by a few ulps of the edge's coordinates, where
// clip_and_split rounds a double crossing to the tightest floats). Intersected with a reference's
// box, a conservative (looser) stand-in for clip_and_split at a fraction of its cost: 3 edges
// against one plane instead of up to 6 planes of polygon clipping.
int split_triangle(const glm::vec3* v, int axis, float split, Box& below, Box& above);
// split_triangle in plain scalar code: what it computes on CPUs without SSE2, and its test's oracle
// (the two give the same bits).
int split_triangle_scalar(const glm::vec3* v, int axis, float split, Box& below, Box& above);

// The whole triangle split by the plane with clip_and_split's exact bounds (its crossings in
// double, rounded outwards to the tightest floats): what clip_and_split does for a triangle inside
// its box. The _scalar twin as above.
int split_triangle_exact(const glm::vec3* v, int axis, float split, Box& below, Box& above);
int split_triangle_exact_scalar(const glm::vec3* v, int axis, float split, Box& below, Box& above);

}  // namespace mobirt::kdclip
