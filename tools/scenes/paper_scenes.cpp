#include "paper_scenes.h"

#include "geometry.h"
#include "gltf_writer.h"
#include "textures.h"

#include <glm/gtc/quaternion.hpp>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

namespace mobirt::scenes {

namespace {

namespace fs = std::filesystem;
using glm::vec2;
using glm::vec3;

const vec3 kX(1, 0, 0), kY(0, 1, 0), kZ(0, 0, 1);

glm::quat axis_angle(float angle, const vec3& axis) { return glm::angleAxis(angle, glm::normalize(axis)); }

vec3 mix(const vec3& a, const vec3& b, float t) { return a + (b - a) * t; }

float fract(float x) { return x - std::floor(x); }

vec3 hsv(float h, float s, float v) {
  const vec3 k = glm::abs(glm::fract(vec3(h) + vec3(0.0f, 2.0f / 3.0f, 1.0f / 3.0f)) * 6.0f - vec3(3.0f));
  return v * mix(vec3(1.0f), glm::clamp(k - vec3(1.0f), 0.0f, 1.0f), s);
}

// The direction a texel (u, v) of an equirectangular texture lands on, as sphere() maps it.
vec3 sphere_dir(float u, float v) {
  const float theta = kPi * v, phi = 2.0f * kPi * u;
  return vec3(std::sin(theta) * std::cos(phi), std::cos(theta), -std::sin(theta) * std::sin(phi));
}

// Scales texture coordinates (for tiling with REPEAT or MIRRORED_REPEAT samplers).
Mesh scale_uv(Mesh m, const vec2& s) {
  for (vec2& uv : m.uvs) uv *= s;
  return m;
}

// Keyframe times 0, dt, ..., period (the last key repeats the first pose, so the loop is seamless).
std::vector<float> key_times(float period, int keys) {
  std::vector<float> t;
  for (int i = 0; i <= keys; ++i) t.push_back(period * float(i) / float(keys));
  return t;
}

Channel translation_channel(int node, const std::vector<float>& times, const std::function<vec3(float)>& f) {
  Channel c{node, "translation", times, {}};
  for (float t : times) c.values.emplace_back(f(t), 0.0f);
  return c;
}

// Rotation keys, each on the same hemisphere as the one before so that slerp takes the short way.
Channel rotation_channel(int node, const std::vector<float>& times, const std::function<glm::quat(float)>& f) {
  Channel c{node, "rotation", times, {}};
  glm::quat previous(1, 0, 0, 0);
  for (float t : times) {
    glm::quat q = glm::normalize(f(t));
    if (glm::dot(q, previous) < 0.0f) q = -q;
    previous = q;
    c.values.emplace_back(q.x, q.y, q.z, q.w);
  }
  return c;
}

void write_text(const fs::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
  if (!out) {
    std::fprintf(stderr, "make_scenes: cannot write %s\n", path.string().c_str());
    std::exit(1);
  }
}

// ---- textures shared by several scenes ------------------------------------------------------------

// A checkerboard of n x m checks with a thin darker grout line and a little noise.
Image checker(int w, int h, int n, int m, const vec3& a, const vec3& b, uint32_t seed) {
  Image img(w, h);
  img.fill([&](float u, float v) {
    const int cx = int(u * float(n)), cy = int(v * float(m));
    vec3 c = ((cx + cy) & 1) ? b : a;
    const float gu = fract(u * float(n)), gv = fract(v * float(m));
    const float edge = std::min(std::min(gu, 1.0f - gu), std::min(gv, 1.0f - gv));
    c *= 0.8f + 0.2f * smoothstep(0.0f, 0.04f, edge);
    c *= 0.9f + 0.1f * fractal_noise(u * 8.0f, v * 8.0f, 8, 8, 3, seed);
    return c;
  });
  return img;
}

// An eye / ball marking: a disc of `color` around +Z on an equirectangular sphere texture.
Image eye_texture(int w, int h, const vec3& white, const vec3& iris, const vec3& pupil, float iris_deg,
                  float pupil_deg) {
  Image img(w, h);
  img.fill([&](float u, float v) {
    const float angle = std::acos(glm::clamp(glm::dot(sphere_dir(u, v), kZ), -1.0f, 1.0f)) * 180.0f / kPi;
    if (angle < pupil_deg) return pupil;
    if (angle < iris_deg) return mix(iris, iris * 0.55f, (angle - pupil_deg) / (iris_deg - pupil_deg));
    return white;
  });
  return img;
}

// ---- toaster ----------------------------------------------------------------------------------------

struct ToasterTextures {
  int floor, enamel, label, key, eye, legs;
};

ToasterTextures toaster_textures(Gltf& g, const fs::path& dir) {
  const fs::path tex = dir / "textures";
  checker(256, 256, 4, 4, vec3(0.92f, 0.9f, 0.85f), vec3(0.25f, 0.32f, 0.45f), 11).write_png(tex / "toaster_floor.png");

  // Enamel: near-white paint with soft mottling and two pin-stripes; tinted per toy by the material.
  Image enamel(256, 128);
  enamel.fill([](float u, float v) {
    const float n = fractal_noise(u * 16.0f, v * 8.0f, 16, 8, 4, 21);
    vec3 c = vec3(0.97f, 0.96f, 0.93f) * (0.88f + 0.12f * n);
    const float stripe = std::fabs(v - 0.62f);
    if (stripe < 0.035f && stripe > 0.018f) c = vec3(0.25f, 0.22f, 0.2f);
    return c;
  });
  enamel.write_png(tex / "toaster_enamel.png");

  Image label(256, 64);
  label.fill([](float u, float v) {
    const float border = std::min(std::min(u, 1.0f - u) * 4.0f, std::min(v, 1.0f - v));
    return border < 0.06f ? vec3(0.55f, 0.42f, 0.12f) : mix(vec3(0.98f, 0.93f, 0.72f), vec3(0.9f, 0.78f, 0.45f), v);
  });
  label.text("MOBIRT", (256 - Image::text_width("MOBIRT", 6)) / 2, (64 - 42) / 2, 6, vec3(0.6f, 0.08f, 0.06f));
  label.write_png(tex / "toaster_label.png");

  Image key(128, 64);
  key.fill([](float u, float v) {
    const float band = fract(u * 8.0f);
    const vec3 brass(0.95f, 0.75f, 0.3f);
    return brass * (0.55f + 0.45f * std::sin(kPi * v)) * (band < 0.5f ? 1.0f : 0.85f);
  });
  key.write_png(tex / "toaster_key.png");

  eye_texture(128, 64, vec3(0.98f), vec3(0.2f, 0.55f, 0.9f), vec3(0.03f), 32.0f, 14.0f)
      .write_png(tex / "toaster_eye.png");

  Image legs(64, 128);
  legs.fill([](float u, float v) {
    const float ring = fract(v * 6.0f);
    const float brushed = fractal_noise(u * 4.0f, v * 64.0f, 4, 64, 2, 31);
    return vec3(0.7f, 0.72f, 0.75f) * (0.8f + 0.2f * brushed) * (ring < 0.15f ? 0.6f : 1.0f);
  });
  legs.write_png(tex / "toaster_legs.png");

  ToasterTextures t{};
  t.floor = g.texture("toaster_floor", "textures/toaster_floor.png", kRepeat, kRepeat);
  t.enamel = g.texture("toaster_enamel", "textures/toaster_enamel.png", kMirroredRepeat, kClampToEdge);
  t.label = g.texture("toaster_label", "textures/toaster_label.png", kClampToEdge, kClampToEdge);
  t.key = g.texture("toaster_key", "textures/toaster_key.png", kRepeat, kClampToEdge);
  t.eye = g.texture("toaster_eye", "textures/toaster_eye.png", kRepeat, kClampToEdge);
  t.legs = g.texture("toaster_legs", "textures/toaster_legs.png", kMirroredRepeat, kRepeat);
  return t;
}

}  // namespace

void make_toaster(const fs::path& dir) {
  Gltf g;
  const ToasterTextures t = toaster_textures(g, dir);
  auto textured = [&](const std::string& name, const vec3& color, float metallic, float roughness, int texture) {
    MaterialDesc d;
    d.name = name;
    d.color = color;
    d.metallic = metallic;
    d.roughness = roughness;
    d.texture = texture;
    return g.material(d);
  };
  // metallic 0.6, roughness 0.15: reflectance 0.51.
  const int floor_mat = textured("checker floor (reflective)", vec3(1.0f), 0.6f, 0.15f, t.floor);
  const int bodies[3] = {textured("red enamel", vec3(0.9f, 0.22f, 0.16f), 0.0f, 0.35f, t.enamel),
                         textured("teal enamel", vec3(0.2f, 0.7f, 0.68f), 0.0f, 0.35f, t.enamel),
                         textured("yellow enamel", vec3(0.95f, 0.78f, 0.2f), 0.0f, 0.35f, t.enamel)};
  const int label_mat = textured("label", vec3(1.0f), 0.0f, 0.6f, t.label);
  const int key_mat = textured("brass key", vec3(1.0f), 0.8f, 0.3f, t.key);
  const int eye_mat = textured("eye", vec3(1.0f), 0.0f, 0.2f, t.eye);
  const int leg_mat = textured("chrome legs", vec3(1.0f), 0.9f, 0.25f, t.legs);
  const int slot_mat = g.material("slot", vec3(0.05f), 0.0f, 0.9f);

  g.object("floor", floor_plane(12.0f, 28, 6.0f), floor_mat, vec3(0.0f));

  // One toy, facing +Z: a boxy body on two legs with feet, two bread slots on top, a label and two
  // eyes on the front and a wind-up key on its right (+X) side.
  const Mesh body = scale_uv(rounded_box(vec3(1.0f, 0.75f, 0.62f), 0.25f, 40, 20), vec2(2.0f, 1.0f));
  const Mesh slot = box(vec3(0.68f, 0.04f, 0.09f));
  const Mesh label = panel(0.56f, 0.14f, 1, 1);
  const Mesh eye = sphere(0.1f, 16, 8);
  const Mesh leg = scale_uv(cylinder(0.055f, 0.3f, 16), vec2(1.0f, 1.0f));
  const Mesh foot = rounded_box(vec3(0.2f, 0.08f, 0.3f), 0.5f, 12, 6);
  Mesh spindle = cylinder(0.03f, 0.16f, 12);
  Mesh lobe = torus(0.1f, 0.028f, 24, 8);
  const float leg_h = 0.28f, body_y = leg_h + 0.375f;

  struct Toy {
    vec3 center;
    float radius, direction, phase;
  };
  // Phases chosen so that in the rest pose (time 0) all three look roughly towards the camera.
  const Toy toys[3] = {{vec3(-1.75f, 0.0f, 0.3f), 0.35f, 1.0f, -0.4f},
                       {vec3(0.05f, 0.0f, -1.0f), 0.4f, -1.0f, kPi + 0.4f},
                       {vec3(1.8f, 0.0f, 0.3f), 0.3f, 1.0f, 0.5f}};
  const float period = 3.0f;
  const std::vector<float> times = key_times(period, 36);
  std::vector<Channel> channels;
  for (int i = 0; i < 3; ++i) {
    const Toy& toy = toys[i];
    const std::string n = "toaster " + std::to_string(i + 1);
    // Pose: a point on a small circle, facing along it, hopping 4 times per loop and waddling.
    auto angle = [&](float time) { return toy.phase + toy.direction * 2.0f * kPi * time / period; };
    auto position = [&](float time) {
      const float a = angle(time);
      const float hop = 0.16f * std::fabs(std::sin(4.0f * kPi * time / period + toy.phase));
      return toy.center + vec3(toy.radius * std::cos(a), hop, toy.radius * std::sin(a));
    };
    auto rotation = [&](float time) {
      const float a = angle(time);
      const vec3 d = toy.direction * vec3(-std::sin(a), 0.0f, std::cos(a));
      const float yaw = std::atan2(d.x, d.z);
      const float waddle = 0.12f * std::sin(2.0f * kPi * 2.0f * time / period + toy.phase);
      return axis_angle(yaw, kY) * axis_angle(waddle, kZ);
    };
    const int root = g.group(n, position(0.0f), rotation(0.0f));
    g.object(n + " body", body, bodies[i], vec3(0.0f, body_y, 0.0f), glm::quat(1, 0, 0, 0), root);
    for (int s = 0; s < 2; ++s) {
      g.object(n + " slot " + std::to_string(s + 1), slot, slot_mat, vec3(0.0f, body_y + 0.36f, s ? 0.11f : -0.11f),
               glm::quat(1, 0, 0, 0), root);
    }
    g.object(n + " label", label, label_mat, vec3(0.0f, body_y - 0.13f, 0.314f), glm::quat(1, 0, 0, 0), root);
    for (int s = 0; s < 2; ++s) {
      const float x = s ? 0.22f : -0.22f;
      g.object(n + " eye " + std::to_string(s + 1), eye, eye_mat, vec3(x, body_y + 0.17f, 0.27f),
               glm::quat(1, 0, 0, 0), root);
      g.object(n + " leg " + std::to_string(s + 1), leg, leg_mat, vec3(x, 0.05f, 0.0f), glm::quat(1, 0, 0, 0), root);
      g.object(n + " foot " + std::to_string(s + 1), foot, bodies[i], vec3(x, 0.04f, 0.05f), glm::quat(1, 0, 0, 0),
               root);
    }
    // The key turns about X: its node spins, the spindle and the two lobes of the handle ride on it.
    const int key = g.group(n + " key", vec3(0.49f, body_y + 0.02f, 0.0f), glm::quat(1, 0, 0, 0), root);
    g.object(n + " key spindle", spindle, key_mat, vec3(0.0f), axis_angle(-0.5f * kPi, kZ), key);
    for (int s = 0; s < 2; ++s) {
      g.object(n + " key lobe " + std::to_string(s + 1), lobe, key_mat, vec3(0.2f, s ? 0.1f : -0.1f, 0.0f),
               axis_angle(0.5f * kPi, kX), key);
    }
    channels.push_back(translation_channel(root, times, position));
    channels.push_back(rotation_channel(root, times, rotation));
    channels.push_back(rotation_channel(key, times, [&](float time) {
      return axis_angle(-2.0f * 2.0f * kPi * time / period + toy.phase, kX);  // two turns per loop
    }));
  }
  g.animation("hop and turn", channels);

  g.point_light("key light", vec3(2.5f, 5.5f, 4.0f), vec3(1.0f, 0.97f, 0.92f), 55.0f);
  g.camera("camera", vec3(0.0f, 2.3f, 5.6f), vec3(0.0f, 0.55f, -0.1f), 38.0f, 400.0f / 240.0f);
  g.write(dir / "toaster.gltf", true);
  std::printf("toaster.gltf: %zu triangles\n", g.triangles());
}

// ---- marbles ----------------------------------------------------------------------------------------

namespace {

struct Marble {
  const char* name;
  const char* texture;
  int wrap_s, wrap_t;
  vec2 uv_scale;
  float radius;
  float metallic, roughness;
  vec3 at;          // rest position on the floor (y is ignored)
  char motion;      // 'x': rolls back and forth along X, 'b': bounces and spins, 's': spins in place
  float amplitude;  // roll distance or bounce height
  float phase;
};

Image marble_image(int index) {
  switch (index) {
    case 0: {  // diagonal candy stripes
      Image img(256, 128);
      img.fill([](float u, float v) {
        const float s = fract(u * 6.0f + v * 2.0f);
        return s < 0.33f ? vec3(0.9f, 0.15f, 0.2f) : s < 0.66f ? vec3(0.98f, 0.95f, 0.9f) : vec3(0.15f, 0.35f, 0.85f);
      });
      return img;
    }
    case 1:
      return checker(128, 64, 8, 4, vec3(0.1f, 0.6f, 0.25f), vec3(0.95f, 0.9f, 0.3f), 41);
    case 2: {  // marble veins
      Image img(256, 128);
      img.fill([](float u, float v) {
        const float n = fractal_noise(u * 8.0f, v * 4.0f, 8, 4, 5, 51);
        const float vein = std::fabs(std::sin((u * 3.0f + v * 2.0f + 2.5f * n) * kPi));
        return mix(vec3(0.25f, 0.2f, 0.35f), vec3(0.92f, 0.9f, 0.95f), std::pow(vein, 0.35f));
      });
      return img;
    }
    case 3: {  // polka dots
      Image img(256, 128);
      img.fill([](float u, float v) {
        const vec2 cell(fract(u * 12.0f) - 0.5f, fract(v * 6.0f) - 0.5f);
        return glm::length(cell) < 0.3f ? vec3(0.98f, 0.98f, 0.95f) : vec3(0.85f, 0.3f, 0.6f);
      });
      return img;
    }
    case 4: {  // rainbow: hue along u, light to dark along v
      Image img(512, 256);
      img.fill([](float u, float v) { return hsv(u, 0.8f, 1.0f - 0.6f * v); });
      return img;
    }
    case 5: {  // an "8" ball
      Image img = eye_texture(256, 128, vec3(0.06f), vec3(0.98f), vec3(0.98f), 34.0f, 30.0f);
      // The disc is centred on u = 0.75, v = 0.5 (direction +Z); the digit goes on it.
      img.text("8", 192 - Image::text_width("8", 3) / 2, 64 - 10, 3, vec3(0.05f));
      return img;
    }
    case 6: {  // a spiral
      Image img(128, 128);
      img.fill([](float u, float v) {
        const float x = u - 0.5f, y = v - 0.5f;
        const float r = std::sqrt(x * x + y * y), a = std::atan2(y, x);
        const float s = fract(a / (2.0f * kPi) * 3.0f + r * 6.0f);
        return s < 0.5f ? vec3(0.95f, 0.55f, 0.1f) : vec3(0.25f, 0.1f, 0.45f);
      });
      return img;
    }
    case 7: {  // latitude bands with noise (a tall image)
      Image img(64, 256);
      img.fill([](float u, float v) {
        const float n = fractal_noise(u * 4.0f, v * 16.0f, 4, 16, 3, 71);
        return hsv(0.55f + 0.1f * std::floor(v * 8.0f) / 8.0f, 0.6f, 0.5f + 0.5f * n);
      });
      return img;
    }
    default: {  // bricks
      Image img(256, 128);
      img.fill([](float u, float v) {
        const float row = v * 8.0f;
        const float shift = (int(row) & 1) ? 0.5f : 0.0f;
        const float bu = fract(u * 8.0f + shift), bv = fract(row);
        const bool mortar = bu < 0.06f || bv < 0.1f;
        const float n = fractal_noise(u * 32.0f, v * 16.0f, 32, 16, 2, 81);
        return mortar ? vec3(0.85f, 0.83f, 0.78f) : vec3(0.7f, 0.25f, 0.15f) * (0.75f + 0.25f * n);
      });
      return img;
    }
  }
}

}  // namespace

void make_marbles(const fs::path& dir) {
  Gltf g;
  const fs::path tex = dir / "textures";
  checker(256, 256, 2, 2, vec3(0.85f, 0.82f, 0.76f), vec3(0.35f, 0.3f, 0.28f), 91).write_png(tex / "marbles_floor.png");
  MaterialDesc floor_desc;
  floor_desc.name = "tiled floor";
  floor_desc.metallic = 0.3f;
  floor_desc.roughness = 0.25f;  // reflectance 0.225
  floor_desc.texture = g.texture("marbles_floor", "textures/marbles_floor.png", kRepeat, kRepeat);
  g.object("floor", floor_plane(20.0f, 16, 20.0f), g.material(floor_desc), vec3(0.0f, 0.0f, -4.0f));

  const Marble marbles[9] = {
      {"candy stripes", "marble_stripes", kRepeat, kClampToEdge, vec2(1, 1), 0.45f, 0.0f, 0.25f, vec3(0.0f, 0, 2.0f), 'x', 1.0f, 0.0f},
      {"checker", "marble_checker", kRepeat, kRepeat, vec2(2, 2), 0.4f, 0.5f, 0.1f, vec3(-0.5f, 0, 0.8f), 'x', 0.8f, 3.1f},
      {"veined", "marble_veins", kMirroredRepeat, kClampToEdge, vec2(2, 1), 0.45f, 0.0f, 0.2f, vec3(1.3f, 0, 0.8f), 'b', 0.9f, 0.0f},
      {"polka dots", "marble_dots", kRepeat, kRepeat, vec2(1, 1), 0.4f, 0.0f, 0.3f, vec3(-1.3f, 0, -0.6f), 'b', 0.7f, 1.6f},
      {"rainbow", "marble_rainbow", kClampToEdge, kClampToEdge, vec2(1, 1), 0.35f, 0.4f, 0.15f, vec3(0.6f, 0, -0.6f), 'x', 0.6f, 1.0f},
      {"eight ball", "marble_eight", kClampToEdge, kClampToEdge, vec2(1, 1), 0.5f, 0.0f, 0.15f, vec3(-0.6f, 0, -2.2f), 'x', 0.7f, 2.0f},
      {"spiral mirror", "marble_spiral", kMirroredRepeat, kMirroredRepeat, vec2(2, 2), 0.55f, 0.9f, 0.05f, vec3(1.4f, 0, -2.2f), 's', 0.0f, 0.0f},
      {"bands", "marble_bands", kClampToEdge, kRepeat, vec2(1, 1), 0.45f, 0.0f, 0.2f, vec3(-1.1f, 0, -3.8f), 'b', 1.2f, 0.8f},
      {"bricks", "marble_bricks", kRepeat, kRepeat, vec2(1, 1), 0.5f, 0.0f, 0.4f, vec3(0.8f, 0, -3.8f), 'x', 0.6f, 4.0f},
  };
  const float period = 4.0f;
  const std::vector<float> times = key_times(period, 60);
  std::vector<Channel> channels;
  for (int i = 0; i < 9; ++i) {
    const Marble& m = marbles[i];
    marble_image(i).write_png(tex / (std::string(m.texture) + ".png"));
    MaterialDesc d;
    d.name = m.name;
    d.metallic = m.metallic;
    d.roughness = m.roughness;
    d.texture = g.texture(m.texture, std::string("textures/") + m.texture + ".png", m.wrap_s, m.wrap_t);
    const int material = g.material(d);
    // A tilt so that the texture's poles do not line up with the rolling or spinning axis.
    const glm::quat tilt = axis_angle(0.4f + 0.3f * float(i), glm::normalize(vec3(1.0f, 0.3f, 0.5f)));
    auto position = [&](float time) {
      const float w = 2.0f * kPi * time / period;
      vec3 p(m.at.x, m.radius, m.at.z);
      if (m.motion == 'x') p.x += m.amplitude * std::sin(w + m.phase);
      if (m.motion == 'b') p.y += m.amplitude * std::fabs(std::sin(0.5f * 3.0f * w + m.phase));  // 3 bounces
      return p;
    };
    auto rotation = [&](float time) {
      const float w = 2.0f * kPi * time / period;
      if (m.motion == 'x') {
        // Rolling without slipping: turned by distance / radius about -Z when moving along +X.
        return axis_angle(-(position(time).x - m.at.x) / m.radius, kZ) * tilt;
      }
      return axis_angle((m.motion == 'b' ? 2.0f : 1.0f) * w, kY) * tilt;
    };
    const Mesh ball = scale_uv(sphere(m.radius, 32, 14), m.uv_scale);
    const int node = g.object(std::string("marble ") + m.name, ball, material, position(0.0f), rotation(0.0f));
    channels.push_back(translation_channel(node, times, position));
    channels.push_back(rotation_channel(node, times, rotation));
  }
  g.animation("roll and bounce", channels);

  g.point_light("key light", vec3(1.5f, 7.0f, 3.0f), vec3(1.0f, 0.97f, 0.92f), 70.0f);
  g.camera("camera", vec3(0.0f, 7.4f, 4.6f), vec3(0.0f, 0.0f, -0.9f), 48.0f, 240.0f / 400.0f);
  g.write(dir / "marbles.gltf", true);
  std::printf("marbles.gltf: %zu triangles\n", g.triangles());
}

// ---- fish -------------------------------------------------------------------------------------------

void make_fish(const fs::path& dir) {
  Gltf g;
  const fs::path tex = dir / "textures";

  Image wood(512, 128);
  wood.fill([](float u, float v) {
    const int plank = int(v * 4.0f);
    const float n = fractal_noise(u * 4.0f, v * 32.0f, 4, 32, 4, 101 + uint32_t(plank));
    const float grain = 0.5f + 0.5f * std::sin((v * 4.0f * 12.0f + n * 6.0f) * kPi);
    vec3 c = mix(vec3(0.55f, 0.33f, 0.17f), vec3(0.75f, 0.52f, 0.3f), 0.6f * grain + 0.4f * n);
    if (fract(v * 4.0f) < 0.04f) c *= 0.45f;
    return c;
  });
  wood.write_png(tex / "fish_wood.png");

  Image wall(256, 256);
  wall.fill([](float u, float v) {
    const float wave = 0.5f + 0.5f * std::sin((v * 10.0f + 0.6f * std::sin(u * 4.0f * kPi)) * 2.0f * kPi);
    vec3 c = mix(vec3(0.55f, 0.8f, 0.95f), vec3(0.15f, 0.35f, 0.7f), v);
    c = mix(c, vec3(0.95f, 0.97f, 1.0f), 0.35f * smoothstep(0.7f, 0.95f, wave));
    const float gu = fract(u * 8.0f);
    if (gu < 0.02f) c *= 0.7f;
    return c;
  });
  wall.text("FISH", (256 - Image::text_width("FISH", 4)) / 2, 20, 4, vec3(0.98f, 0.95f, 0.6f));
  wall.write_png(tex / "fish_wall.png");

  Image scales(256, 128);
  scales.fill([](float u, float v) {
    const float row = v * 16.0f;
    const float shift = (int(row) & 1) ? 0.5f : 0.0f;
    const vec2 cell(fract(u * 32.0f + shift) - 0.5f, fract(row));
    const float d = glm::length(vec2(cell.x, cell.y * 0.8f));
    const vec3 base = mix(vec3(1.0f, 0.55f, 0.1f), vec3(1.0f, 0.9f, 0.7f), smoothstep(0.6f, 0.95f, v));
    return base * (0.7f + 0.3f * smoothstep(0.55f, 0.2f, d));
  });
  scales.write_png(tex / "fish_scales.png");

  Image pebble(64, 64);
  pebble.fill([](float u, float v) {
    const float n = fractal_noise(u * 4.0f, v * 4.0f, 4, 4, 4, 111);
    return mix(vec3(0.35f, 0.35f, 0.38f), vec3(0.8f, 0.78f, 0.72f), n);
  });
  pebble.write_png(tex / "fish_pebble.png");

  auto textured = [&](const std::string& name, float metallic, float roughness, int texture) {
    MaterialDesc d;
    d.name = name;
    d.metallic = metallic;
    d.roughness = roughness;
    d.texture = texture;
    return g.material(d);
  };
  const int wood_mat = textured("wooden table", 0.2f, 0.3f, g.texture("fish_wood", "textures/fish_wood.png", kRepeat, kRepeat));
  const int wall_mat = textured("wall", 0.0f, 0.9f, g.texture("fish_wall", "textures/fish_wall.png", kClampToEdge, kClampToEdge));
  const int scale_mat = textured("goldfish scales", 0.0f, 0.3f,
                                 g.texture("fish_scales", "textures/fish_scales.png", kMirroredRepeat, kClampToEdge));
  const int pebble_mat = textured("pebble", 0.0f, 0.6f, g.texture("fish_pebble", "textures/fish_pebble.png", kRepeat, kMirroredRepeat));
  MaterialDesc water;
  water.name = "water (bowl)";
  water.color = vec3(0.85f, 0.95f, 1.0f);
  water.roughness = 0.05f;
  water.transmission = 0.9f;
  water.ior = 1.33f;
  const int water_mat = g.material(water);
  MaterialDesc glass;
  glass.name = "glass (fish figurine)";
  glass.color = vec3(0.8f, 1.0f, 0.9f);
  glass.roughness = 0.05f;
  glass.transmission = 0.9f;
  glass.ior = 1.5f;
  const int glass_mat = g.material(glass);
  const int stand_mat = g.material("stand", vec3(0.15f, 0.15f, 0.18f), 0.7f, 0.3f);
  const int fin_mat = g.material("fins", vec3(1.0f, 0.45f, 0.1f), 0.0f, 0.5f);
  const int eye_mat = g.material("fish eye", vec3(0.02f), 0.0f, 0.1f);

  g.object("table", floor_plane(14.0f, 8, 3.0f), wood_mat, vec3(0.0f, 0.0f, 2.0f));
  g.object("wall", panel(14.0f, 7.0f, 8, 4), wall_mat, vec3(0.0f, 3.5f, -3.0f));
  g.object("bowl stand", cylinder(0.6f, 0.12f, 24), stand_mat, vec3(0.0f));
  const float bowl_r = 1.1f;
  const vec3 bowl_c(0.0f, 0.12f + bowl_r - 0.05f, 0.0f);
  g.object("bowl", sphere(bowl_r, 20, 12), water_mat, bowl_c);

  // A goldfish swimming along +X in its own frame: body, tail (wags), dorsal fin, two eyes.
  Mesh body = sphere(1.0f, 16, 8);
  scale(body, vec3(0.36f, 0.19f, 0.11f));
  body = scale_uv(body, vec2(2.0f, 1.0f));
  const Mesh tail = prism(vec2(0.0f, 0.0f), vec2(-0.26f, 0.17f), vec2(-0.26f, -0.17f), 0.025f);
  const Mesh fin = prism(vec2(-0.12f, 0.15f), vec2(0.12f, 0.15f), vec2(-0.16f, 0.3f), 0.02f);
  const Mesh fish_eye = sphere(0.035f, 8, 4);
  const float period = 4.0f, swim_r = 0.45f;
  // Circles the bowl's centre; at time 0 it is behind the centre, swimming to the right (side on).
  auto position = [&](float time) {
    const float a = 2.0f * kPi * time / period - 0.5f * kPi;
    return bowl_c + vec3(swim_r * std::cos(a), 0.08f * std::sin(2.0f * a), swim_r * std::sin(a));
  };
  auto rotation = [&](float time) {
    const float a = 2.0f * kPi * time / period - 0.5f * kPi;
    // The fish's +X follows the tangent of its circle.
    const vec3 d(-std::sin(a), 0.0f, std::cos(a));
    return axis_angle(std::atan2(-d.z, d.x), kY);
  };
  const int fish = g.group("goldfish", position(0.0f), rotation(0.0f));
  g.object("goldfish body", body, scale_mat, vec3(0.0f), glm::quat(1, 0, 0, 0), fish);
  const int tail_node = g.object("goldfish tail", tail, fin_mat, vec3(-0.32f, 0.0f, 0.0f), glm::quat(1, 0, 0, 0), fish);
  g.object("goldfish fin", fin, fin_mat, vec3(0.0f), glm::quat(1, 0, 0, 0), fish);
  for (int s = 0; s < 2; ++s) {
    g.object("goldfish eye " + std::to_string(s + 1), fish_eye, eye_mat, vec3(0.24f, 0.05f, s ? 0.075f : -0.075f),
             glm::quat(1, 0, 0, 0), fish);
  }
  const std::vector<float> times = key_times(period, 48);
  g.animation("swim", {translation_channel(fish, times, position), rotation_channel(fish, times, rotation),
                       rotation_channel(tail_node, times, [&](float time) {
                         return axis_angle(0.45f * std::sin(2.0f * kPi * 4.0f * time / period), kY);
                       })});

  // A glass fish figurine on the table, and two pebbles.
  Mesh glass_body = sphere(1.0f, 16, 8);
  scale(glass_body, vec3(0.5f, 0.3f, 0.16f));
  const int figurine = g.group("glass fish", vec3(1.85f, 0.42f, 0.9f), axis_angle(0.5f, kY));
  g.object("glass fish body", glass_body, glass_mat, vec3(0.0f), glm::quat(1, 0, 0, 0), figurine);
  g.object("glass fish tail", prism(vec2(-0.4f, 0.0f), vec2(-0.75f, 0.28f), vec2(-0.75f, -0.28f), 0.08f), glass_mat,
           vec3(0.0f), glm::quat(1, 0, 0, 0), figurine);
  Mesh stone = sphere(1.0f, 8, 4);
  scale(stone, vec3(0.22f, 0.1f, 0.16f));
  g.object("pebble 1", stone, pebble_mat, vec3(-1.6f, 0.09f, 1.0f), axis_angle(0.7f, kY));
  g.object("pebble 2", stone, pebble_mat, vec3(-1.25f, 0.09f, 1.5f), axis_angle(2.0f, kY));

  g.point_light("key light", vec3(-2.5f, 5.0f, 3.5f), vec3(1.0f, 0.97f, 0.92f), 55.0f);
  g.camera("camera", vec3(0.5f, 2.1f, 5.0f), vec3(0.25f, 1.0f, 0.0f), 40.0f, 400.0f / 240.0f);
  g.write(dir / "fish.gltf", true);
  std::printf("fish.gltf: %zu triangles\n", g.triangles());
}

// ---- Utah toasters material library -----------------------------------------------------------------

void make_utah_mtl(const fs::path& dir) {
  const fs::path tex = dir / "textures";
  // The tray (13_-_Default, Box01) spans -400..400 in x and z; its UVs run 0.03..0.97: 8 x 8 checks.
  checker(512, 512, 8, 8, vec3(0.9f, 0.88f, 0.82f), vec3(0.2f, 0.24f, 0.32f), 121).write_png(tex / "utah_floor.png");
  // Head: enamel with a darker band and rivets; the UVs cover the whole image.
  Image head(256, 256);
  head.fill([](float u, float v) {
    const float n = fractal_noise(u * 8.0f, v * 8.0f, 8, 8, 4, 131);
    vec3 c = vec3(0.98f, 0.96f, 0.92f) * (0.85f + 0.15f * n);
    if (std::fabs(v - 0.5f) < 0.05f) c *= 0.55f;
    const vec2 rivet(fract(u * 8.0f) - 0.5f, (v - 0.5f) * 8.0f);
    if (glm::length(rivet) < 0.18f) c = vec3(0.35f);
    return c;
  });
  head.write_png(tex / "utah_head.png");
  Image jaw(256, 64);
  jaw.fill([](float u, float v) {
    const float tooth = fract(u * 16.0f);
    return (tooth < 0.85f && v < 0.5f) ? vec3(0.97f, 0.95f, 0.88f) : vec3(0.75f, 0.76f, 0.8f);
  });
  jaw.write_png(tex / "utah_jaw.png");
  Image key(128, 128);
  key.fill([](float u, float v) {
    const float band = fract((u + v) * 6.0f);
    return vec3(0.95f, 0.78f, 0.3f) * (band < 0.5f ? 1.0f : 0.8f) * (0.8f + 0.2f * std::sin(kPi * v));
  });
  key.write_png(tex / "utah_key.png");
  Image legs(64, 128);
  legs.fill([](float u, float v) {
    const float ring = fract(v * 10.0f);
    return hsv(0.6f, 0.7f, 0.75f + 0.15f * fractal_noise(u * 8.0f, v * 8.0f, 8, 8, 2, 141)) *
           (ring < 0.2f ? 0.6f : 1.0f);
  });
  legs.write_png(tex / "utah_legs.png");

  write_text(dir / "utah-toasters.mtl",
             "# Materials for ../shared/scenes/utah-toasters/Toasters004.obj, written by\n"
             "# tools/make_scenes.cpp (mobirt_make_scenes). Use: mobirt render Toasters004.obj --mtl this file.\n"
             "# illum 3 + Ks: mirror reflection of weight max(Ks); map_Kd paths are relative to this file.\n"
             "\n"
             "# Box01: the tray the toys stand on (floor at y = -4, rim up to y = 61): reflective checkers.\n"
             "newmtl 13_-_Default\n"
             "Kd 0.9 0.9 0.9\nKs 0.5 0.5 0.5\nNs 200\nillum 3\nmap_Kd textures/utah_floor.png\n"
             "\n"
             "newmtl 1_-_Head\n"
             "Kd 0.85 0.2 0.15\nKs 0.3 0.3 0.3\nNs 60\nillum 2\nmap_Kd textures/utah_head.png\n"
             "\n"
             "# The jaw is chrome: a little mirror reflection.\n"
             "newmtl 2_-_Jaw\n"
             "Kd 0.8 0.8 0.82\nKs 0.35 0.35 0.35\nNs 300\nillum 3\nmap_Kd textures/utah_jaw.png\n"
             "\n"
             "newmtl 3_-_Eyes\n"
             "Kd 0.95 0.95 0.9\nKs 0.5 0.5 0.5\nNs 120\nillum 2\n"
             "\n"
             "newmtl 7_-_KeySpindle\n"
             "Kd 0.5 0.5 0.52\nKs 0.6 0.6 0.6\nNs 400\nillum 3\n"
             "\n"
             "newmtl 8_-_Key\n"
             "Kd 1 0.85 0.4\nKs 0.4 0.4 0.4\nNs 80\nillum 2\nmap_Kd textures/utah_key.png\n"
             "\n"
             "newmtl 9_-_Legs\n"
             "Kd 1 1 1\nKs 0.2 0.2 0.2\nNs 30\nillum 2\nmap_Kd textures/utah_legs.png\n");
}

}  // namespace mobirt::scenes
