#include "geometry.h"

#include <cmath>

namespace mobirt::scenes {

Mesh box(const glm::vec3& size) {
  Mesh m;
  const glm::vec3 h = 0.5f * size;
  for (int axis = 0; axis < 3; ++axis) {
    for (int sign = -1; sign <= 1; sign += 2) {
      glm::vec3 n(0.0f);
      n[axis] = float(sign);
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      glm::vec3 corner[4];
      const float su[4] = {-1, 1, 1, -1}, sv[4] = {-1, -1, 1, 1};
      for (int k = 0; k < 4; ++k) {
        corner[k][axis] = float(sign) * h[axis];
        corner[k][u] = su[k] * h[u];
        corner[k][v] = sv[k] * h[v];
      }
      uint32_t i[4];
      for (int k = 0; k < 4; ++k) {
        i[k] = m.vertex(corner[k], n, glm::vec2(0.5f * (su[k] + 1.0f), 0.5f * (1.0f - sv[k])));
      }
      // Counter-clockwise seen from outside.
      if (sign > 0) m.quad(i[0], i[1], i[2], i[3]); else m.quad(i[0], i[3], i[2], i[1]);
    }
  }
  return m;
}

Mesh sphere(float radius, int segments, int rings) {
  Mesh m;
  for (int r = 0; r <= rings; ++r) {
    const float theta = kPi * float(r) / float(rings);
    // The poles exactly on the axis and the seam's last column exactly the first (float sin(pi)
    // and sin(2 pi) are about 1e-7, not 0): a closed surface, which rounded_box's powers would
    // otherwise open into a crack along the seam and a hole at the bottom pole.
    const float st = r == rings ? 0.0f : std::sin(theta), ct = r == rings ? -1.0f : std::cos(theta);
    for (int s = 0; s <= segments; ++s) {
      const float phi = 2.0f * kPi * float(s) / float(segments);
      const float sp = s == segments ? 0.0f : std::sin(phi), cp = s == segments ? 1.0f : std::cos(phi);
      const glm::vec3 n(st * cp, ct, -st * sp);
      m.vertex(radius * n, n, glm::vec2(float(s) / float(segments), float(r) / float(rings)));
    }
  }
  const uint32_t row = uint32_t(segments + 1);
  for (int r = 0; r < rings; ++r) {
    for (int s = 0; s < segments; ++s) {
      const uint32_t a = uint32_t(r) * row + uint32_t(s), b = a + row;
      if (r != 0) m.indices.insert(m.indices.end(), {a, b, a + 1});
      if (r != rings - 1) m.indices.insert(m.indices.end(), {a + 1, b, b + 1});
    }
  }
  return m;
}

Mesh cylinder(float radius, float height, int segments) {
  Mesh m;
  for (int s = 0; s <= segments; ++s) {
    const float phi = 2.0f * kPi * float(s) / float(segments);
    const glm::vec3 n(std::cos(phi), 0.0f, -std::sin(phi));
    const float u = float(s) / float(segments);
    m.vertex(radius * n, n, glm::vec2(u, 1.0f));
    m.vertex(radius * n + glm::vec3(0, height, 0), n, glm::vec2(u, 0.0f));
  }
  for (int s = 0; s < segments; ++s) {
    const uint32_t a = uint32_t(2 * s);
    m.quad(a, a + 2, a + 3, a + 1);
  }
  for (int cap = 0; cap < 2; ++cap) {
    const float y = cap ? height : 0.0f;
    const glm::vec3 n(0, cap ? 1.0f : -1.0f, 0);
    const uint32_t center = m.vertex(glm::vec3(0, y, 0), n, glm::vec2(0.5f));
    for (int s = 0; s <= segments; ++s) {
      const float phi = 2.0f * kPi * float(s) / float(segments);
      m.vertex(glm::vec3(radius * std::cos(phi), y, -radius * std::sin(phi)), n,
               glm::vec2(0.5f + 0.5f * std::cos(phi), 0.5f + 0.5f * std::sin(phi)));
    }
    for (int s = 0; s < segments; ++s) {
      const uint32_t a = center + 1 + uint32_t(s);
      if (cap) m.indices.insert(m.indices.end(), {center, a, a + 1});
      else m.indices.insert(m.indices.end(), {center, a + 1, a});
    }
  }
  return m;
}

Mesh floor_plane(float size, int n, float tiles) {
  Mesh m;
  for (int j = 0; j <= n; ++j) {
    for (int i = 0; i <= n; ++i) {
      m.vertex(glm::vec3(size * (float(i) / float(n) - 0.5f), 0.0f, size * (float(j) / float(n) - 0.5f)),
               glm::vec3(0, 1, 0), tiles * glm::vec2(float(i) / float(n), float(j) / float(n)));
    }
  }
  const uint32_t row = uint32_t(n + 1);
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const uint32_t a = uint32_t(j) * row + uint32_t(i);
      m.quad(a, a + row, a + row + 1, a + 1);
    }
  }
  return m;
}

Mesh panel(float w, float h, int nx, int ny) {
  Mesh m;
  for (int j = 0; j <= ny; ++j) {
    for (int i = 0; i <= nx; ++i) {
      const float u = float(i) / float(nx), v = float(j) / float(ny);
      m.vertex(glm::vec3(w * (u - 0.5f), h * (0.5f - v), 0.0f), glm::vec3(0, 0, 1), glm::vec2(u, v));
    }
  }
  const uint32_t row = uint32_t(nx + 1);
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const uint32_t a = uint32_t(j) * row + uint32_t(i);
      m.quad(a, a + row, a + row + 1, a + 1);  // counter-clockwise seen from +Z
    }
  }
  return m;
}

namespace {
float signed_pow(float x, float e) { return x < 0.0f ? -std::pow(-x, e) : std::pow(x, e); }
}  // namespace

Mesh rounded_box(const glm::vec3& size, float e, int segments, int rings) {
  Mesh m = sphere(1.0f, segments, rings);
  const glm::vec3 h = 0.5f * size;
  for (size_t i = 0; i < m.positions.size(); ++i) {
    const glm::vec3 d = m.normals[i];
    const glm::vec3 p(signed_pow(d.x, e), signed_pow(d.y, e), signed_pow(d.z, e));
    // Gradient of |x|^(2/e) + |y|^(2/e) + |z|^(2/e), divided by the scale for the scaled shape.
    const float g = 2.0f / e - 1.0f;
    glm::vec3 n(signed_pow(p.x, g), signed_pow(p.y, g), signed_pow(p.z, g));
    n /= h;
    m.positions[i] = p * h;
    m.normals[i] = glm::length(n) > 0.0f ? glm::normalize(n) : d;
  }
  return m;
}

Mesh torus(float R, float r, int segments, int sides) {
  Mesh m;
  for (int s = 0; s <= segments; ++s) {
    const float phi = 2.0f * kPi * float(s) / float(segments);
    const glm::vec3 radial(std::cos(phi), 0.0f, -std::sin(phi));
    for (int k = 0; k <= sides; ++k) {
      const float psi = 2.0f * kPi * float(k) / float(sides);
      const glm::vec3 n = std::cos(psi) * radial + glm::vec3(0, std::sin(psi), 0);
      m.vertex(R * radial + r * n, n, glm::vec2(float(s) / float(segments), float(k) / float(sides)));
    }
  }
  const uint32_t row = uint32_t(sides + 1);
  for (int s = 0; s < segments; ++s) {
    for (int k = 0; k < sides; ++k) {
      const uint32_t a = uint32_t(s) * row + uint32_t(k), b = a + row;
      m.quad(a, b, b + 1, a + 1);
    }
  }
  return m;
}

Mesh prism(const glm::vec2& a, const glm::vec2& b, const glm::vec2& c, float depth) {
  Mesh m;
  const glm::vec2 p[3] = {a, b, c};
  const float z = 0.5f * depth;
  // Make (a, b, c) counter-clockwise seen from +Z.
  const float area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
  const int o[3] = {0, area >= 0.0f ? 1 : 2, area >= 0.0f ? 2 : 1};
  glm::vec2 lo = glm::min(a, glm::min(b, c)), hi = glm::max(a, glm::max(b, c));
  auto uv = [&](const glm::vec2& q) { return glm::vec2((q.x - lo.x) / (hi.x - lo.x), (hi.y - q.y) / (hi.y - lo.y)); };
  for (int side = 0; side < 2; ++side) {
    const float sz = side ? z : -z;
    const glm::vec3 n(0, 0, side ? 1.0f : -1.0f);
    uint32_t i[3];
    for (int k = 0; k < 3; ++k) i[k] = m.vertex(glm::vec3(p[o[k]], sz), n, uv(p[o[k]]));
    if (side) m.indices.insert(m.indices.end(), {i[0], i[1], i[2]});
    else m.indices.insert(m.indices.end(), {i[0], i[2], i[1]});
  }
  for (int k = 0; k < 3; ++k) {
    const glm::vec2 q0 = p[o[k]], q1 = p[o[(k + 1) % 3]];
    const glm::vec2 e = q1 - q0;
    const glm::vec3 n = glm::normalize(glm::vec3(e.y, -e.x, 0.0f));
    const uint32_t v0 = m.vertex(glm::vec3(q0, -z), n, glm::vec2(0, 1)), v1 = m.vertex(glm::vec3(q1, -z), n, glm::vec2(1, 1));
    const uint32_t v2 = m.vertex(glm::vec3(q1, z), n, glm::vec2(1, 0)), v3 = m.vertex(glm::vec3(q0, z), n, glm::vec2(0, 0));
    m.quad(v0, v1, v2, v3);
  }
  return m;
}

void append(Mesh& a, const Mesh& b) {
  const uint32_t base = uint32_t(a.positions.size());
  a.positions.insert(a.positions.end(), b.positions.begin(), b.positions.end());
  a.normals.insert(a.normals.end(), b.normals.begin(), b.normals.end());
  a.uvs.insert(a.uvs.end(), b.uvs.begin(), b.uvs.end());
  for (uint32_t i : b.indices) a.indices.push_back(base + i);
}

void scale(Mesh& m, const glm::vec3& s) {
  for (glm::vec3& p : m.positions) p *= s;
  for (glm::vec3& n : m.normals) n = glm::normalize(n / s);
}

}  // namespace mobirt::scenes
