// Eric Haines' Neutral File Format (NFF, the SPD's format; NFF.TXT version 3.9): a small reader.
// The file is read as whitespace-separated fields with line numbers kept for messages; an
// entity's data may continue on following lines, as the spec's own layout (one vertex a line)
// does.

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "scene/loader.h"
#include "scene/tessellate.h"
#include "scene/validate.h"

namespace mobirt {

namespace {

// The 24-bit hit index bounds any scene; checked before a primitive is tessellated so that a
// small file cannot ask for gigabytes.
constexpr size_t kMaxTriangles = (size_t(1) << 24) - 1;
constexpr int kMaxResolution = 16384;

// A field as it may appear in a message: printable, at most 40 characters.
std::string printable(const std::string& field) {
  std::string out;
  for (char ch : field.substr(0, 40)) out += std::isprint(static_cast<unsigned char>(ch)) ? ch : '?';
  return field.size() > 40 ? out + "..." : out;
}

class NffReader {
 public:
  NffReader(const std::string& path, std::string text, const LoadOptions& options)
      : path_(path), text_(std::move(text)), tess_{options.tessellation}, analytic_(options.analytic) {}

  Scene read() {
    scene_.source = path_;
    std::string word;
    while (next(word)) {
      entity_line_ = field_line_;
      if (word == "v") {
        view();
      } else if (word == "b") {
        scene_.background = vec3("the background colour R G B");
      } else if (word == "l") {
        light();
      } else if (word == "f") {
        fill();
      } else if (word == "c") {
        cone();
      } else if (word == "s") {
        sphere();
      } else if (word == "p" || word == "pp") {
        polygon(word == "pp");
      } else {
        fail(field_line_, "unknown entity '" + printable(word) +
                              "': NFF has v, b, l, f, c, s, p, pp and # comments (see NFF.TXT)");
      }
    }
    finish_lights();
    validate_scene(scene_);
    return std::move(scene_);
  }

 private:
  [[noreturn]] void fail(int line, const std::string& message) const {
    throw input_error(path_ + ":" + std::to_string(line), message);
  }

  // The next field, skipping white space and comments ('#' to the end of the line).
  bool next(std::string& out) {
    while (pos_ < text_.size()) {
      const char ch = text_[pos_];
      if (ch == '\n') {
        ++line_;
        ++pos_;
      } else if (ch == '#') {
        while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
      } else if (std::isspace(static_cast<unsigned char>(ch))) {
        ++pos_;
      } else {
        break;
      }
    }
    if (pos_ >= text_.size()) return false;
    const size_t start = pos_;
    while (pos_ < text_.size() && text_[pos_] != '#' && !std::isspace(static_cast<unsigned char>(text_[pos_]))) {
      ++pos_;
    }
    out.assign(text_, start, pos_ - start);
    field_line_ = line_;
    return true;
  }

  // True when another field follows on the current line (optional fields such as a light's colour).
  bool more_on_line() const {
    for (size_t i = pos_; i < text_.size(); ++i) {
      if (text_[i] == '\n' || text_[i] == '#') return false;
      if (!std::isspace(static_cast<unsigned char>(text_[i]))) return true;
    }
    return false;
  }

  std::string field(const std::string& what) {
    std::string word;
    if (!next(word)) {
      fail(field_line_, "unexpected end of file: expected " + what + " (the entity begins on line " +
                            std::to_string(entity_line_) + ")");
    }
    return word;
  }

  float number(const std::string& what) {
    const std::string word = field(what);
    errno = 0;
    char* end = nullptr;
    const double v = std::strtod(word.c_str(), &end);
    if (end != word.c_str() + word.size() || !std::isfinite(v) || errno == ERANGE ||
        std::abs(v) > double(std::numeric_limits<float>::max())) {
      fail(field_line_, "expected a finite number (" + what + "), got '" + printable(word) + "'");
    }
    return static_cast<float>(v);
  }

  long integer(const std::string& what, long lo, long hi) {
    const std::string word = field(what);
    errno = 0;
    char* end = nullptr;
    const long v = std::strtol(word.c_str(), &end, 10);
    if (end != word.c_str() + word.size() || errno == ERANGE || v < lo || v > hi) {
      fail(field_line_, "expected an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "] (" + what +
                            "), got '" + printable(word) + "'");
    }
    return v;
  }

  glm::vec3 vec3(const std::string& what) {
    glm::vec3 v;
    for (int i = 0; i < 3; ++i) v[i] = number(what);
    return v;
  }

  // "v" then from, at, up, angle, hither, resolution, each a keyword and its values (hither and
  // resolution may be left out).
  void view() {
    if (saw_view_) fail(entity_line_, "a second view 'v' (the first is on line " + std::to_string(view_line_) + ")");
    saw_view_ = true;
    view_line_ = entity_line_;
    Camera camera;
    bool from = false, at = false, up = false, angle = false;
    float angle_deg = 45.0f;
    while (true) {
      const size_t save_pos = pos_;
      const int save_line = line_;
      std::string word;
      if (!next(word)) break;
      if (word == "from") {
        camera.eye = vec3("the eye position 'from X Y Z'");
        from = true;
      } else if (word == "at") {
        camera.target = vec3("the look-at point 'at X Y Z'");
        at = true;
      } else if (word == "up") {
        camera.up = vec3("the up vector 'up X Y Z'");
        up = true;
      } else if (word == "angle") {
        angle_deg = number("the field of view 'angle DEGREES'");
        if (!(angle_deg > 0.0f && angle_deg < 180.0f)) fail(field_line_, "the view angle must lie in (0, 180) degrees");
        angle = true;
      } else if (word == "hither") {
        camera.znear = number("the hither distance 'hither D'");
        if (camera.znear < 0.0f) fail(field_line_, "the hither distance must not be negative");
      } else if (word == "resolution") {
        const int w = int(integer("the image width 'resolution W H'", 1, kMaxResolution));
        const int h = int(integer("the image height 'resolution W H'", 1, kMaxResolution));
        scene_.image_size = glm::ivec2(w, h);
      } else {
        pos_ = save_pos;  // the next entity
        line_ = save_line;
        break;
      }
    }
    if (!from || !at || !up || !angle) {
      fail(entity_line_, std::string("the view 'v' needs from, at, up and angle; ") +
                             (!from ? "from" : !at ? "at" : !up ? "up" : "angle") + " is missing");
    }
    const glm::vec3 view = camera.target - camera.eye;
    const float up_len = glm::length(camera.up);
    if (!(glm::length(view) > 0.0f)) fail(entity_line_, "the view's from and at are the same point");
    if (!(up_len > 0.0f) || glm::length(glm::cross(glm::normalize(view), camera.up / up_len)) < 1e-6f) {
      fail(entity_line_, "the view's up vector is zero or parallel to the viewing direction");
    }
    camera.up /= up_len;
    // NFF's angle spans the centres of the outer pixel rows; mobirt's yfov spans the image's edges.
    const int rows = scene_.image_size ? scene_.image_size->y : 0;
    const double half = 0.5 * glm::radians(double(angle_deg));
    camera.yfov = rows > 1 ? float(2.0 * std::atan(std::tan(half) * rows / (rows - 1.0))) : float(2.0 * half);
    scene_.camera = camera;
    scene_.up = camera.up;
  }

  void light() {
    Light light;
    light.type = LightType::Point;
    light.position = vec3("the light position X Y Z");
    if (more_on_line()) {
      light.color = vec3("the light colour R G B");
      if (light.color.x < 0.0f || light.color.y < 0.0f || light.color.z < 0.0f) {
        fail(field_line_, "a light colour must not be negative");
      }
    }
    scene_.lights.push_back(light);
  }

  // f R G B Kd Ks Shine T ior: the mapping is README's materials table.
  void fill() {
    const glm::vec3 rgb = vec3("the fill colour R G B");
    const float kd = number("Kd"), ks = number("Ks"), shine = number("Shine"), t = number("T");
    const float ior = number("the index of refraction");
    Material m;
    m.name = "f (line " + std::to_string(entity_line_) + ")";
    m.diffuse = glm::clamp(rgb * kd, 0.0f, 1.0f);
    m.specular = glm::vec3(std::clamp(ks, 0.0f, 1.0f));
    m.shininess = std::clamp(shine, 1.0f, 1024.0f);
    m.reflectance = std::clamp(ks, 0.0f, 1.0f);
    m.transmittance = std::clamp(t, 0.0f, 1.0f);
    m.ior = ior >= 1.0f ? ior : 1.0f;
    m.fresnel = false;  // NFF gives the rays' weights as fixed fractions
    scene_.materials.push_back(m);
    material_ = uint32_t(scene_.materials.size() - 1);
  }

  uint32_t material() {
    if (material_ == kNone) {  // geometry before any 'f': mobirt's default material
      scene_.materials.push_back(Material{});
      scene_.materials.back().name = "default";
      material_ = uint32_t(scene_.materials.size() - 1);
    }
    return material_;
  }

  void reserve(size_t triangles, const char* what) {
    if (triangles > kMaxTriangles - scene_.primitive_count()) {
      fail(entity_line_, std::string(what) + " would take the scene past " + std::to_string(kMaxTriangles) +
                             " primitives, the most the 24-bit hit index holds");
    }
  }

  void sphere() {
    const glm::vec3 c = vec3("the sphere's centre X Y Z");
    const float r = number("the sphere's radius");
    if (r == 0.0f) fail(entity_line_, "a sphere of radius 0");
    reserve(analytic_ ? 1 : sphere_triangle_count(tess_), "this sphere");
    if (!analytic_) {
      tessellate_sphere(scene_.mesh, c, r, material(), tess_);
      return;
    }
    Shape sphere;
    sphere.base = c;
    sphere.base_radius = std::abs(r);
    sphere.inside = r < 0.0f;
    sphere.material = material();
    scene_.shapes.push_back(sphere);
  }

  void cone() {
    const glm::vec3 base = vec3("the cone's base X Y Z");
    const float rb = number("the cone's base radius");
    const glm::vec3 apex = vec3("the cone's apex X Y Z");
    const float ra = number("the cone's apex radius");
    if (base == apex) fail(entity_line_, "the cone's base and apex are the same point");
    if ((rb < 0.0f && ra > 0.0f) || (rb > 0.0f && ra < 0.0f)) {
      fail(entity_line_, "the cone's radii differ in sign (both negative: only the inside is visible)");
    }
    if (rb == 0.0f && ra == 0.0f) fail(entity_line_, "the cone's radii are both 0");
    reserve(analytic_ ? 1 : cone_triangle_count(tess_), "this cone");
    if (!analytic_) {
      tessellate_cone(scene_.mesh, base, rb, apex, ra, material(), tess_);
      return;
    }
    Shape cone;
    cone.kind = ShapeKind::Cone;
    cone.base = base;
    cone.base_radius = std::abs(rb);
    cone.apex = apex;
    cone.apex_radius = std::abs(ra);
    cone.inside = rb < 0.0f || ra < 0.0f;
    cone.material = material();
    scene_.shapes.push_back(cone);
  }

  void polygon(bool patch) {
    const char* what = patch ? "the patch's vertex count" : "the polygon's vertex count";
    const size_t n = size_t(integer(what, 3, long(kMaxPolygonVertices)));
    reserve(n - 2, patch ? "this patch" : "this polygon");
    std::vector<glm::vec3> points(n), normals(n);
    for (size_t i = 0; i < n; ++i) {
      const std::string v = "vertex " + std::to_string(i + 1) + " of " + std::to_string(n);
      points[i] = vec3(v + (patch ? " (X Y Z NX NY NZ)" : " (X Y Z)"));
      if (patch) normals[i] = vec3(v + "'s normal");
    }
    const std::vector<uint32_t> tris = triangulate_polygon(points);
    if (tris.empty()) {  // no area: kept as one degenerate triangle, counted, never shown
      for (uint32_t k = 0; k < 3; ++k) emit(points, normals, patch, k, glm::vec3(0.0f));
      scene_.mesh.material_ids.push_back(material());
      return;
    }
    const glm::vec3 flat = polygon_normal(points);
    const uint32_t mat = material();
    for (size_t t = 0; t < tris.size(); t += 3) {
      for (size_t k = 0; k < 3; ++k) emit(points, normals, patch, tris[t + k], flat);
      scene_.mesh.material_ids.push_back(mat);
    }
  }

  void emit(const std::vector<glm::vec3>& points, const std::vector<glm::vec3>& normals, bool patch, uint32_t i,
            const glm::vec3& flat) {
    scene_.mesh.positions.push_back(points[i]);
    scene_.mesh.normals.push_back(patch ? normals[i] : flat);
  }

  // NFF lights have "a non-zero intensity of no particular value" and no falloff; the SPD's
  // README suggests sqrt(n) / (2 n) for each of n lights and for the ambient term. mobirt's point
  // lights fall off with the squared distance, so each gets that value times its squared distance
  // to the view's look-at point (the scene's centre without a view): the SPD's brightness there.
  void finish_lights() {
    if (scene_.lights.empty()) return;
    const float n = float(scene_.lights.size());
    const float share = std::sqrt(n) / (2.0f * n);
    const glm::vec3 focus = scene_.camera ? scene_.camera->target : scene_.bounds().center();
    for (Light& l : scene_.lights) {
      const glm::vec3 d = l.position - focus;
      l.intensity = share * std::max(glm::dot(d, d), 1e-12f);
    }
    for (Material& m : scene_.materials) m.ambient = share;
  }

  static constexpr uint32_t kNone = ~0u;
  std::string path_;
  std::string text_;
  Tessellation tess_;
  bool analytic_ = true;
  Scene scene_;
  size_t pos_ = 0;
  int line_ = 1;
  int field_line_ = 1;   // line of the field read last
  int entity_line_ = 1;  // line of the entity being read
  bool saw_view_ = false;
  int view_line_ = 0;
  uint32_t material_ = kNone;
};

}  // namespace

Scene load_nff(const std::string& path, const LoadOptions& options) {
  check_scene_file(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw input_error(path, "cannot be opened for reading");
  std::ostringstream bytes;
  bytes << in.rdbuf();
  return NffReader(path, bytes.str(), options).read();
}

}  // namespace mobirt
