// Parsing of option values shared by the mobirt commands. Every error is an Error(BadInput) whose
// message ends with "(see HELP)", HELP naming where the command's options are described, e.g.
// "mobirt --help" or "mobirt accuracy --help".
#pragma once

#include <functional>
#include <string>

namespace mobirt {
struct RenderSettings;
}

namespace mobirt::cli {

[[noreturn]] void usage_error(const std::string& message, const std::string& help);

// VALUE of OPTION as an integer in [lo, hi].
int parse_int(const std::string& option, const std::string& value, int lo, int hi, const std::string& help);

// VALUE of OPTION as a number in [lo, hi], read in float (strtof) or double (strtod) precision.
float parse_float(const std::string& option, const std::string& value, float lo, float hi, const std::string& help);
double parse_number(const std::string& option, const std::string& value, double lo, double hi,
                    const std::string& help);

// The render settings the commands share (--size, --depth, --no-shadows, --min-weight, --stack,
// --max-steps, --bins, --leaf-size, --max-depth, --epsilon, --offset, --intersect, --precision,
// --colour) into `settings`; `value` takes the option's value. Returns false when `option` is
// none of them.
bool parse_render_setting(const std::string& option, const std::function<std::string()>& value,
                          RenderSettings& settings, const std::string& help);

}  // namespace mobirt::cli
