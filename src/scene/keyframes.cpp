#include "scene/keyframes.h"

#include <algorithm>
#include <cmath>

namespace mobirt {

glm::dquat slerp_shortest(glm::dquat a, glm::dquat b, double u) {
  double d = glm::dot(a, b);
  if (d < 0.0) {
    b = -b;
    d = -d;
  }
  if (d > 0.9995) return glm::normalize(a * (1.0 - u) + b * u);
  const double theta = std::acos(std::min(d, 1.0));
  const double s = std::sin(theta);
  return a * (std::sin((1.0 - u) * theta) / s) + b * (std::sin(u * theta) / s);
}

void sample_keyframes(const KeyframeTrack& s, double t, bool quaternion, double* out) {
  const size_t w = s.width;
  const size_t n = s.times.size();
  const bool cubic = s.interpolation == Interpolation::CubicSpline;
  const size_t stride = cubic ? 3 * w : w;
  const size_t value = cubic ? w : 0;  // offset of the value inside a key
  auto key = [&](size_t k) { return &s.values[k * stride + value]; };
  if (n == 1 || t <= s.times[0]) {
    std::copy(key(0), key(0) + w, out);
    return;
  }
  if (t >= s.times[n - 1]) {
    std::copy(key(n - 1), key(n - 1) + w, out);
    return;
  }
  const size_t k =
      static_cast<size_t>(std::upper_bound(s.times.begin(), s.times.end(), t) - s.times.begin()) -
      1;  // times[k] <= t < times[k + 1]
  const double t0 = s.times[k];
  const double td = s.times[k + 1] - t0;
  const double u = td > 0.0 ? (t - t0) / td : 1.0;
  const double* a = key(k);
  const double* b = key(k + 1);
  switch (s.interpolation) {
    case Interpolation::Step:
      std::copy(a, a + w, out);
      return;
    case Interpolation::Linear:
      if (quaternion) {
        const glm::dquat q = slerp_shortest(glm::dquat(a[3], a[0], a[1], a[2]),
                                            glm::dquat(b[3], b[0], b[1], b[2]), u);
        out[0] = q.x, out[1] = q.y, out[2] = q.z, out[3] = q.w;
      } else {
        for (size_t c = 0; c < w; ++c) out[c] = a[c] + (b[c] - a[c]) * u;
      }
      return;
    case Interpolation::CubicSpline: {
      // glTF 2.0 Appendix C: p(u) = (2u^3 - 3u^2 + 1) v_k + (u^3 - 2u^2 + u) td b_k
      //                             + (-2u^3 + 3u^2) v_k+1 + (u^3 - u^2) td a_k+1
      const double u2 = u * u;
      const double u3 = u2 * u;
      const double h00 = 2.0 * u3 - 3.0 * u2 + 1.0;
      const double h10 = (u3 - 2.0 * u2 + u) * td;
      const double h01 = -2.0 * u3 + 3.0 * u2;
      const double h11 = (u3 - u2) * td;
      const double* out_tangent = a + w;  // b_k
      const double* in_tangent = b - w;   // a_k+1
      for (size_t c = 0; c < w; ++c) {
        out[c] = h00 * a[c] + h10 * out_tangent[c] + h01 * b[c] + h11 * in_tangent[c];
      }
      if (quaternion) {
        const double len = std::sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2] +
                                     out[3] * out[3]);
        if (len > 0.0) {
          for (size_t c = 0; c < 4; ++c) out[c] /= len;
        } else {
          out[0] = out[1] = out[2] = 0.0, out[3] = 1.0;
        }
      }
      return;
    }
  }
}

}  // namespace mobirt
