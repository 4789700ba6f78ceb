#include "app/options.h"

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <type_traits>

#include "core/error.h"
#include "render/renderer.h"

namespace mobirt::cli {
namespace {

template <typename T>
T parse_real(const std::string& option, const std::string& value, T lo, T hi, const std::string& help) {
  char* end = nullptr;
  T v;
  if constexpr (std::is_same_v<T, float>) {
    v = std::strtof(value.c_str(), &end);
  } else {
    v = std::strtod(value.c_str(), &end);
  }
  if (value.empty() || *end != '\0' || !(v >= lo && v <= hi)) {
    usage_error(option + " " + value + ": expected a number in [" + std::to_string(lo) + ", " +
                    std::to_string(hi) + "]",
                help);
  }
  return v;
}

}  // namespace

void usage_error(const std::string& message, const std::string& help) {
  throw Error(ErrorKind::BadInput, message + " (see " + help + ")");
}

int parse_int(const std::string& option, const std::string& value, int lo, int hi, const std::string& help) {
  char* end = nullptr;
  errno = 0;
  const long v = std::strtol(value.c_str(), &end, 10);
  if (value.empty() || *end != '\0' || errno != 0 || v < lo || v > hi) {
    usage_error(option + " " + value + ": expected an integer in [" + std::to_string(lo) + ", " +
                    std::to_string(hi) + "]",
                help);
  }
  return int(v);
}

float parse_float(const std::string& option, const std::string& value, float lo, float hi, const std::string& help) {
  return parse_real(option, value, lo, hi, help);
}

double parse_number(const std::string& option, const std::string& value, double lo, double hi,
                    const std::string& help) {
  return parse_real(option, value, lo, hi, help);
}

// One of `choices` (names in the order of their values), or a usage error listing them.
template <typename E, size_t N>
E parse_choice(const std::string& option, const std::string& value, const std::pair<const char*, E> (&choices)[N],
               const std::string& help) {
  std::string names;
  for (const auto& [name, choice] : choices) {
    if (value == name) return choice;
    names += names.empty() ? name : std::string(", ") + name;
  }
  usage_error(option + " " + value + ": expected one of " + names, help);
}

bool parse_render_setting(const std::string& a, const std::function<std::string()>& value, RenderSettings& settings,
                          const std::string& help) {
  if (a == "--size") {
    const std::string v = value();
    int w = 0, h = 0;
    char extra = 0;
    if (std::sscanf(v.c_str(), "%dx%d%c", &w, &h, &extra) != 2 || w < 1 || h < 1 || w > 16384 || h > 16384) {
      usage_error("--size " + v + ": expected WxH with 1 <= W, H <= 16384, e.g. 400x240", help);
    }
    settings.width = w;
    settings.height = h;
  } else if (a == "--depth") {
    settings.depth = parse_int(a, value(), 0, 64, help);
  } else if (a == "--no-shadows") {
    settings.shadows = false;
  } else if (a == "--min-weight") {
    settings.secondary.min_weight = parse_float(a, value(), 0.0f, 1.0f, help);
  } else if (a == "--stack") {
    settings.stack_depth = parse_int(a, value(), 0, MOBIRT_MAX_STACK_DEPTH, help);
  } else if (a == "--max-steps") {
    settings.max_steps = parse_int(a, value(), 1, 1 << 24, help);
  } else if (a == "--bins") {
    settings.kd.bins = parse_int(a, value(), 2, 1024, help);
  } else if (a == "--build") {
    const std::string v = value();
    if (!parse_kd_build_mode(v, settings.kd.build)) {
      usage_error("--build " + v + ": expected one of fast, quality", help);
    }
  } else if (a == "--leaf-size") {
    settings.kd.max_leaf_prims = parse_int(a, value(), 1, 1 << 20, help);
  } else if (a == "--max-depth") {
    settings.kd.max_depth = parse_int(a, value(), -1, 128, help);
  } else if (a == "--epsilon") {
    settings.shadow_rays.offset.epsilon = parse_float(a, value(), 0.0f, 1.0f, help);
    settings.secondary.offset.epsilon = settings.shadow_rays.offset.epsilon;
  } else if (a == "--offset") {
    static constexpr std::pair<const char*, OffsetMode> modes[] = {
        {"fixed", OffsetMode::Fixed}, {"scaled", OffsetMode::Scaled}, {"normal-ulp", OffsetMode::NormalUlp}};
    settings.shadow_rays.offset.mode = parse_choice(a, value(), modes, help);
    settings.secondary.offset.mode = settings.shadow_rays.offset.mode;
  } else if (a == "--intersect") {
    static constexpr std::pair<const char*, IntersectTest> tests[] = {
        {"mt", IntersectTest::MollerTrumbore}, {"watertight", IntersectTest::Watertight}};
    settings.shadow_rays.ray_test.test = parse_choice(a, value(), tests, help);
  } else if (a == "--precision") {
    static constexpr std::pair<const char*, Precision> precisions[] = {{"highp", Precision::High},
                                                                       {"mediump", Precision::Medium}};
    settings.shadow_rays.ray_test.precision = parse_choice(a, value(), precisions, help);
  } else if (a == "--colour" || a == "--color") {
    static constexpr std::pair<const char*, ColourDepth> depths[] = {{"8", ColourDepth::Bits8},
                                                                     {"16", ColourDepth::Bits16}};
    settings.colour = parse_choice(a, value(), depths, help);
  } else {
    return false;
  }
  return true;
}

}  // namespace mobirt::cli
