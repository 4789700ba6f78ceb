#include "app/options.h"

#include <cerrno>
#include <cstdlib>
#include <type_traits>

#include "core/error.h"

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

}  // namespace mobirt::cli
