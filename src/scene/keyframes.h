// Keyframe sampling, free of any file format: the step, linear (slerp for rotations) and cubic
// Hermite interpolation of glTF 2.0 animation samplers (Appendix C), clamped outside the key range.
#pragma once

#include <glm/gtc/quaternion.hpp>

#include <cstddef>
#include <vector>

namespace mobirt {

enum class Interpolation { Linear, Step, CubicSpline };

// One keyframe track: `width` numbers per key. CubicSpline keys hold three groups of `width`
// numbers each, in glTF's order: in-tangent a_k, value v_k, out-tangent b_k. Tangents are
// derivatives per second: they are scaled by the length of the interval being interpolated.
struct KeyframeTrack {
  std::vector<double> times;   // key times in seconds, non-decreasing, at least one
  std::vector<double> values;  // times.size() x width numbers (CubicSpline: x 3)
  Interpolation interpolation = Interpolation::Linear;
  size_t width = 0;
};

// The track's value at time t into out[0 .. width). Before the first key: the first value; after
// the last: the last value (never a tangent). At a key time shared by two keys, the later key.
// `quaternion`: the values are unit quaternions (x, y, z, w); Linear slerps along the shorter
// arc, CubicSpline normalises the result (a zero result gives the identity).
void sample_keyframes(const KeyframeTrack& track, double t, bool quaternion, double* out);

// Spherical interpolation from a (u = 0) to b (u = 1) along the shorter arc: b is negated when
// a . b < 0 (q and -q are the same rotation). Nearly equal quaternions are lerped and normalised.
glm::dquat slerp_shortest(glm::dquat a, glm::dquat b, double u);

}  // namespace mobirt
