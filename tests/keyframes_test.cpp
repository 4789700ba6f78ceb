// Keyframe sampling (scene/keyframes.h), free of glTF files: known answers for STEP, LINEAR, slerp
// and CUBICSPLINE, clamping outside the key range, glTF's cubic tangent convention (tangents per
// second, scaled by the interval), and slerp between antipodal quaternions.
#include <glm/gtc/quaternion.hpp>
#include <gtest/gtest.h>

#include <cmath>
#include <utility>
#include <vector>

#include "scene/keyframes.h"

namespace mobirt {
namespace {

KeyframeTrack track(std::vector<double> times, std::vector<double> values, Interpolation interpolation,
                    size_t width) {
  KeyframeTrack t;
  t.times = std::move(times);
  t.values = std::move(values);
  t.interpolation = interpolation;
  t.width = width;
  return t;
}

double at(const KeyframeTrack& t, double time) {
  double v = 0.0;
  sample_keyframes(t, time, false, &v);
  return v;
}

glm::dquat quat_at(const KeyframeTrack& t, double time) {
  double v[4];
  sample_keyframes(t, time, true, v);
  return glm::dquat(v[3], v[0], v[1], v[2]);
}

// q and -q are the same rotation.
void expect_same_rotation(const glm::dquat& q, const glm::dquat& want) {
  EXPECT_NEAR(std::abs(glm::dot(q, want)), 1.0, 1e-12) << "q = (" << q.x << ", " << q.y << ", " << q.z << ", " << q.w
                                                       << "), want (" << want.x << ", " << want.y << ", " << want.z
                                                       << ", " << want.w << ")";
  EXPECT_NEAR(glm::length(q), 1.0, 1e-12);
}

glm::dquat about_z(double degrees) { return glm::angleAxis(glm::radians(degrees), glm::dvec3(0.0, 0.0, 1.0)); }

TEST(Keyframes, StepHoldsEachKeyUntilTheNext) {
  const KeyframeTrack t = track({1.0, 2.0, 4.0}, {10.0, 20.0, 40.0}, Interpolation::Step, 1);
  EXPECT_EQ(at(t, 1.0), 10.0);
  EXPECT_EQ(at(t, 1.999), 10.0);
  EXPECT_EQ(at(t, 2.0), 20.0);  // a key takes effect at its own time
  EXPECT_EQ(at(t, 3.9), 20.0);
  EXPECT_EQ(at(t, 4.0), 40.0);
}

TEST(Keyframes, LinearKnownAnswersPerComponent) {
  // Two components per key, keys unevenly spaced.
  const KeyframeTrack t = track({0.0, 1.0, 3.0}, {0.0, 10.0, 2.0, 20.0, 6.0, 0.0}, Interpolation::Linear, 2);
  double v[2];
  sample_keyframes(t, 0.25, false, v);
  EXPECT_DOUBLE_EQ(v[0], 0.5);
  EXPECT_DOUBLE_EQ(v[1], 12.5);
  sample_keyframes(t, 2.0, false, v);  // halfway through the second, longer interval
  EXPECT_DOUBLE_EQ(v[0], 4.0);
  EXPECT_DOUBLE_EQ(v[1], 10.0);
  sample_keyframes(t, 1.0, false, v);  // exactly on a key
  EXPECT_DOUBLE_EQ(v[0], 2.0);
  EXPECT_DOUBLE_EQ(v[1], 20.0);
}

TEST(Keyframes, ClampedOutsideTheKeyRange) {
  for (Interpolation mode : {Interpolation::Step, Interpolation::Linear}) {
    const KeyframeTrack t = track({1.0, 2.0}, {5.0, 7.0}, mode, 1);
    EXPECT_EQ(at(t, 0.0), 5.0);
    EXPECT_EQ(at(t, -100.0), 5.0);
    EXPECT_EQ(at(t, 2.5), 7.0);
    EXPECT_EQ(at(t, 1e9), 7.0);
  }
  // CUBICSPLINE clamps to the value, never to a tangent: (in, value, out) per key.
  const KeyframeTrack c = track({1.0, 2.0}, {100.0, 5.0, 200.0, 300.0, 7.0, 400.0}, Interpolation::CubicSpline, 1);
  EXPECT_EQ(at(c, 0.5), 5.0);
  EXPECT_EQ(at(c, 3.0), 7.0);
  // A single key is constant everywhere.
  const KeyframeTrack one = track({2.0}, {3.0}, Interpolation::Linear, 1);
  EXPECT_EQ(at(one, 0.0), 3.0);
  EXPECT_EQ(at(one, 2.0), 3.0);
  EXPECT_EQ(at(one, 5.0), 3.0);
}

TEST(Keyframes, EqualKeyTimesJumpToTheLaterKey) {
  const KeyframeTrack t = track({0.0, 1.0, 1.0, 2.0}, {0.0, 10.0, 20.0, 30.0}, Interpolation::Linear, 1);
  EXPECT_NEAR(at(t, 0.999), 9.99, 1e-9);
  EXPECT_EQ(at(t, 1.0), 20.0);
  EXPECT_DOUBLE_EQ(at(t, 1.5), 25.0);
}

TEST(Keyframes, CubicSplineHermiteKnownAnswers) {
  // Values only (zero tangents): smoothstep between the two values.
  const KeyframeTrack flat = track({0.0, 1.0}, {0.0, 0.0, 0.0, 0.0, 1.0, 0.0}, Interpolation::CubicSpline, 1);
  EXPECT_DOUBLE_EQ(at(flat, 0.5), 0.5);
  EXPECT_DOUBLE_EQ(at(flat, 0.25), 3 * 0.0625 - 2 * 0.015625);  // 3u^2 - 2u^3
  // The keys' own values are met exactly.
  EXPECT_EQ(at(flat, 0.0), 0.0);
  EXPECT_EQ(at(flat, 1.0), 1.0);
}

TEST(Keyframes, CubicTangentsArePerSecondAndScaledByTheInterval) {
  // glTF 2.0 Appendix C: p = h00 v_k + h10 td b_k + h01 v_k+1 + h11 td a_k+1, with the key's
  // out-tangent b_k last in key k and the in-tangent a_k+1 first in key k + 1. Values 0, an
  // out-tangent of 1 per second over an interval of 2 s: p(u) = 2 (u^3 - 2u^2 + u).
  const KeyframeTrack out = track({0.0, 2.0}, {0.0, 0.0, 1.0, 0.0, 0.0, 0.0}, Interpolation::CubicSpline, 1);
  EXPECT_DOUBLE_EQ(at(out, 1.0), 2.0 * (0.125 - 0.5 + 0.5));
  // The slope at the key is the tangent, per second (not per unit of u).
  const double h = 1e-6;
  EXPECT_NEAR((at(out, h) - at(out, 0.0)) / h, 1.0, 1e-5);
  // The in-tangent of the second key: p(u) = 2 (u^3 - u^2) a_1, slope a_1 at the end.
  const KeyframeTrack in = track({0.0, 2.0}, {0.0, 0.0, 0.0, 3.0, 0.0, 0.0}, Interpolation::CubicSpline, 1);
  EXPECT_DOUBLE_EQ(at(in, 1.0), 2.0 * (0.125 - 0.25) * 3.0);
  EXPECT_NEAR((at(in, 2.0) - at(in, 2.0 - h)) / h, 3.0, 1e-5);
  // The first key's in-tangent and the last key's out-tangent are never used.
  const KeyframeTrack unused = track({0.0, 2.0}, {99.0, 0.0, 1.0, 0.0, 0.0, -99.0}, Interpolation::CubicSpline, 1);
  EXPECT_EQ(at(unused, 1.0), at(out, 1.0));
}

TEST(Keyframes, LinearRotationsSlerpAtConstantSpeed) {
  const glm::dquat a = about_z(0.0), b = about_z(90.0);
  const KeyframeTrack t =
      track({0.0, 1.0}, {a.x, a.y, a.z, a.w, b.x, b.y, b.z, b.w}, Interpolation::Linear, 4);
  expect_same_rotation(quat_at(t, 0.25), about_z(22.5));
  expect_same_rotation(quat_at(t, 0.5), about_z(45.0));
  expect_same_rotation(quat_at(t, 0.9), about_z(81.0));
  expect_same_rotation(quat_at(t, 2.0), b);  // clamped
}

TEST(Keyframes, SlerpTakesTheShorterArc) {
  // The second key is -(90 degrees about z), the same rotation: halfway is 45 degrees, not 135.
  const glm::dquat b = -about_z(90.0);
  const KeyframeTrack t = track({0.0, 1.0}, {0.0, 0.0, 0.0, 1.0, b.x, b.y, b.z, b.w}, Interpolation::Linear, 4);
  expect_same_rotation(quat_at(t, 0.5), about_z(45.0));
  // 270 degrees about z is -90 degrees the short way.
  expect_same_rotation(slerp_shortest(about_z(0.0), about_z(270.0), 0.5), about_z(-45.0));
}

TEST(Keyframes, SlerpOfAntipodalQuaternionsStaysPut) {
  // q and -q: no rotation between them, at every u (a naive slerp divides by sin(pi) = 0).
  const glm::dquat q = about_z(30.0);
  for (double u : {0.0, 0.25, 0.5, 0.75, 1.0}) {
    const glm::dquat r = slerp_shortest(q, -q, u);
    EXPECT_TRUE(std::isfinite(r.x) && std::isfinite(r.w)) << "u = " << u;
    expect_same_rotation(r, q);
  }
  // Nearly equal quaternions (the lerp branch) stay unit and between the two.
  const glm::dquat near = slerp_shortest(about_z(10.0), about_z(10.001), 0.5);
  expect_same_rotation(near, about_z(10.0005));
}

TEST(Keyframes, CubicRotationsAreNormalised) {
  // Values identity and 90 degrees about z, zero tangents: the blend is not unit length before
  // normalisation; the result must be.
  const glm::dquat a = about_z(0.0), b = about_z(90.0);
  const KeyframeTrack t = track({0.0, 1.0},
                                {0, 0, 0, 0, a.x, a.y, a.z, a.w, 0, 0, 0, 0, 0, 0, 0, 0, b.x, b.y, b.z, b.w, 0, 0, 0, 0},
                                Interpolation::CubicSpline, 4);
  const glm::dquat mid = quat_at(t, 0.5);
  EXPECT_NEAR(glm::length(mid), 1.0, 1e-12);
  expect_same_rotation(mid, about_z(45.0));  // equal weights of a and b: halfway
  // A blend of exactly zero gives the identity rather than NaN.
  const KeyframeTrack zero = track({0.0, 1.0},
                                   {0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, -1, 0, 0, 0, 0},
                                   Interpolation::CubicSpline, 4);
  expect_same_rotation(quat_at(zero, 0.5), glm::dquat(1.0, 0.0, 0.0, 0.0));
}

}  // namespace
}  // namespace mobirt
