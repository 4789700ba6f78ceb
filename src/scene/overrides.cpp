#include "scene/overrides.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <set>
#include <sstream>

#include <glm/gtc/constants.hpp>

#include "core/error.h"

namespace mobirt {

namespace {

const char* const kLightSyntax =
    "expected --light \"point pos=X,Y,Z [color=R,G,B] [intensity=I] [range=R]\", "
    "\"spot pos=X,Y,Z dir=X,Y,Z [inner=DEG] [outer=DEG] [color=R,G,B] [intensity=I] [range=R]\" "
    "or \"directional dir=X,Y,Z [color=R,G,B] [intensity=I]\"";
const char* const kCameraSyntax =
    "expected --camera \"EX,EY,EZ:TX,TY,TZ[:UX,UY,UZ][:FOVDEG]\" (eye, target, optional up, "
    "optional vertical field of view in degrees)";

[[noreturn]] void light_error(const std::string& spec, const std::string& message) {
  throw Error(ErrorKind::BadInput, "--light '" + spec + "': " + message + "; " + kLightSyntax);
}

[[noreturn]] void camera_error(const std::string& spec, const std::string& message) {
  throw Error(ErrorKind::BadInput, "--camera '" + spec + "': " + message + "; " + kCameraSyntax);
}

// One finite number, the whole of `text`.
bool parse_number(const std::string& text, float& out) {
  if (text.empty() || std::isspace(static_cast<unsigned char>(text[0]))) return false;
  errno = 0;
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (end != text.c_str() + text.size() || errno == ERANGE || !std::isfinite(v)) return false;
  if (std::abs(v) > static_cast<double>(std::numeric_limits<float>::max())) return false;
  out = static_cast<float>(v);
  return true;
}

std::vector<std::string> split(const std::string& text, char sep) {
  std::vector<std::string> parts;
  size_t start = 0;
  while (true) {
    const size_t end = text.find(sep, start);
    parts.push_back(text.substr(start, end == std::string::npos ? std::string::npos : end - start));
    if (end == std::string::npos) break;
    start = end + 1;
  }
  return parts;
}

// "X,Y,Z" -> three finite numbers, or false.
bool parse_vec3(const std::string& text, glm::vec3& out) {
  const std::vector<std::string> parts = split(text, ',');
  if (parts.size() != 3) return false;
  for (int i = 0; i < 3; ++i) {
    if (!parse_number(parts[static_cast<size_t>(i)], out[i])) return false;
  }
  return true;
}

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

}  // namespace

Light parse_light(const std::string& spec) {
  std::istringstream words(spec);
  std::string type_word;
  if (!(words >> type_word)) light_error(spec, "empty light");
  Light light;
  const std::string type = lower(type_word);
  std::set<std::string> allowed;
  if (type == "point") {
    light.type = LightType::Point;
    allowed = {"pos", "color", "intensity", "range"};
  } else if (type == "spot") {
    light.type = LightType::Spot;
    allowed = {"pos", "dir", "inner", "outer", "color", "intensity", "range"};
  } else if (type == "directional") {
    light.type = LightType::Directional;
    allowed = {"dir", "color", "intensity"};
  } else {
    light_error(spec, "unknown light type '" + type_word + "' (point, spot or directional)");
  }

  std::set<std::string> seen;
  float inner_deg = 0.0f;
  float outer_deg = 45.0f;
  std::string word;
  while (words >> word) {
    const size_t eq = word.find('=');
    if (eq == std::string::npos || eq == 0) {
      light_error(spec, "'" + word + "' is not key=value");
    }
    const std::string key = lower(word.substr(0, eq));
    const std::string value = word.substr(eq + 1);
    if (!allowed.count(key)) {
      light_error(spec, "'" + key + "' is not a parameter of a " + type + " light");
    }
    if (!seen.insert(key).second) light_error(spec, key + " is given twice");
    if (key == "pos" || key == "dir" || key == "color") {
      glm::vec3 v;
      const char* what = key == "color" ? "R,G,B" : "X,Y,Z";
      if (!parse_vec3(value, v)) {
        light_error(spec, key + " needs three numbers " + what + ", got '" + value + "'");
      }
      if (key == "pos") {
        light.position = v;
      } else if (key == "dir") {
        const float len = glm::length(v);
        if (!(len > 0.0f) || !std::isfinite(len)) light_error(spec, "dir must not be zero");
        light.direction = v / len;
      } else {
        if (v.x < 0.0f || v.y < 0.0f || v.z < 0.0f) {
          light_error(spec, "color components must not be negative");
        }
        light.color = v;
      }
    } else {
      float v;
      if (!parse_number(value, v)) {
        light_error(spec, key + " needs one finite number, got '" + value + "'");
      }
      if (key == "intensity" || key == "range") {
        if (v < 0.0f) light_error(spec, key + " must not be negative");
        (key == "intensity" ? light.intensity : light.range) = v;
      } else if (key == "inner") {
        inner_deg = v;
      } else {
        outer_deg = v;
      }
    }
  }
  if (light.type != LightType::Directional && !seen.count("pos")) {
    light_error(spec, "a " + type + " light needs pos=X,Y,Z");
  }
  if (light.type != LightType::Point && !seen.count("dir")) {
    light_error(spec, "a " + type + " light needs dir=X,Y,Z");
  }
  if (light.type == LightType::Spot) {
    if (!(inner_deg >= 0.0f && inner_deg < outer_deg && outer_deg <= 90.0f)) {
      light_error(spec, "the cone angles must satisfy 0 <= inner < outer <= 90 degrees");
    }
    light.inner_cone = glm::radians(inner_deg);
    light.outer_cone = glm::radians(outer_deg);
  }
  return light;
}

Camera parse_camera(const std::string& spec) {
  const std::vector<std::string> parts = split(spec, ':');
  if (parts.size() < 2 || parts.size() > 4) {
    camera_error(spec, "needs 2 to 4 parts separated by ':', got " + std::to_string(parts.size()));
  }
  Camera camera;
  camera.znear = 0.0f;
  if (!parse_vec3(parts[0], camera.eye)) {
    camera_error(spec, "the eye needs three numbers EX,EY,EZ, got '" + parts[0] + "'");
  }
  if (!parse_vec3(parts[1], camera.target)) {
    camera_error(spec, "the target needs three numbers TX,TY,TZ, got '" + parts[1] + "'");
  }
  camera.up = glm::vec3(0.0f, 1.0f, 0.0f);
  float fov_deg = 45.0f;
  bool have_up = false;
  bool have_fov = false;
  for (size_t i = 2; i < parts.size(); ++i) {
    const std::string& part = parts[i];
    const size_t commas = static_cast<size_t>(std::count(part.begin(), part.end(), ','));
    if (commas == 2 && !have_up && !have_fov) {
      if (!parse_vec3(part, camera.up)) {
        camera_error(spec, "the up vector needs three numbers UX,UY,UZ, got '" + part + "'");
      }
      have_up = true;
    } else if (commas == 0 && !have_fov && i + 1 == parts.size()) {
      if (!parse_number(part, fov_deg)) {
        camera_error(spec, "the field of view needs one number in degrees, got '" + part + "'");
      }
      have_fov = true;
    } else {
      camera_error(spec, "part " + std::to_string(i + 1) + " '" + part +
                             "' is neither an up vector UX,UY,UZ nor a final field of view");
    }
  }
  if (!(fov_deg > 0.0f && fov_deg < 180.0f)) {
    camera_error(spec, "the field of view must lie in (0, 180) degrees");
  }
  camera.yfov = glm::radians(fov_deg);
  const glm::vec3 view = camera.target - camera.eye;
  const float view_len = glm::length(view);
  if (!(view_len > 0.0f) || !std::isfinite(view_len)) {
    camera_error(spec, "the eye and the target must differ");
  }
  const float up_len = glm::length(camera.up);
  if (!(up_len > 0.0f) || !std::isfinite(up_len)) camera_error(spec, "the up vector is zero");
  camera.up /= up_len;
  if (glm::length(glm::cross(view / view_len, camera.up)) < 1e-6f) {
    camera_error(spec, "the up vector is parallel to the view direction");
  }
  return camera;
}

void apply_overrides(Scene& scene, const std::vector<Light>& lights,
                     const std::optional<Camera>& camera) {
  if (!lights.empty()) scene.lights = lights;
  if (camera) scene.camera = *camera;
}

}  // namespace mobirt
