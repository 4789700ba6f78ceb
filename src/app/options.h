// The mobirt command line on one table: the render settings the commands share (options.cpp,
// kSettings) and each command's own options, parsed by CLI11, with --help generated from both.
// Every error is an Error(BadInput) whose message ends with "(see HELP)", HELP naming where the
// command's options are described, e.g. "mobirt --help" or "mobirt accuracy --help".
#pragma once

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "app/scene_setup.h"
#include "backend/backend.h"
#include "backend/vulkan/vulkan_backend.h"
#include "render/renderer.h"

namespace CLI {
class App;
}

namespace mobirt::cli {

[[noreturn]] void usage_error(const std::string& message, const std::string& help);

// VALUE of OPTION as an integer in [lo, hi].
int parse_int(const std::string& option, const std::string& value, int lo, int hi, const std::string& help);

// VALUE of OPTION as a number in [lo, hi], read in float (strtof) or double (strtod) precision.
float parse_float(const std::string& option, const std::string& value, float lo, float hi, const std::string& help);
double parse_number(const std::string& option, const std::string& value, double lo, double hi,
                    const std::string& help);

// --size WxH with 1 <= W, H <= 16384.
std::pair<int, int> parse_size(const std::string& option, const std::string& value, const std::string& help);

// One option's value as given, with the checked conversions the table's lines use.
struct Value {
  const std::string& option;  // the option's name, as errors name it
  const std::string& text;
  const std::string& help;
  int integer(int lo, int hi) const { return parse_int(option, text, lo, hi, help); }
  float real(float lo, float hi) const { return parse_float(option, text, lo, hi, help); }
  double number(double lo, double hi) const { return parse_number(option, text, lo, hi, help); }
  // One of `choices` (names in the order of their values), or a usage error listing them.
  template <typename E, size_t N>
  E choice(const std::pair<const char*, E> (&choices)[N]) const {
    std::string names;
    for (const auto& [name, c] : choices) {
      if (text == name) return c;
      names += names.empty() ? name : std::string(", ") + name;
    }
    usage_error(option + " " + text + ": expected one of " + names, help);
  }
};

// The commands, as the table says which of them take a shared setting.
enum Command : unsigned { kRender = 1, kAccuracy = 2, kBench = 4, kInfo = 8 };

// What the shared settings set: the renderer's settings, the backend, and the scene's edits.
struct CommonOptions {
  CommonOptions() { settings.worker = WorkerPriority::Idle; }  // --worker's default: idle
  RenderSettings settings;
  VulkanOptions backend;  // with Vulkan's own: the pipeline cache (render, bench)
  std::string backend_name = "vulkan";  // --backend
  SceneEdits edits;                     // --light, --camera, --background
  std::optional<double> time;           // --time
  std::string mtl;                      // --mtl
  bool analytic = true;                 // --primitives: NFF spheres and cones analytic or tessellated
  bool size_given = false;              // --size given: it wins over the file's own image size
};

// The kd-tree build's settings as the commands' JSON records them (bins, build mode, the leaf size,
// cluster rule and depth limit in force, the empty bonus), so that a run says which tree it made.
nlohmann::json kd_settings_json(const KdBuildOptions& kd);

// One command's command line: its own options (listed first, under "Options") and the shared
// settings of the table that `command` takes (under "Render options").
class CommandLine {
 public:
  // `usage` is the help's first line; `about` the text after it; `help` what errors point to.
  CommandLine(Command command, const std::string& usage, const std::string& about, std::string help,
              CommonOptions& common);
  ~CommandLine();

  // An option with a value (`value_name` in --help) and a flag; `apply` runs at each occurrence,
  // in the order given on the command line.
  void option(const std::string& names, const std::string& value_name, const std::string& description,
              std::function<void(const Value&)> apply);
  void flag(const std::string& names, const std::string& description, std::function<void()> apply);

  // Parses `args` (those after the command's name). Returns false when --help was given: the
  // help is printed then. The arguments that are not options are left in positionals().
  bool parse(const std::vector<std::string>& args);
  const std::vector<std::string>& positionals() const { return positionals_; }
  // The one positional argument, the scene: a usage error when there is none or more than one.
  std::string scene() const;

  std::string help_text() const;
  const std::string& help() const { return help_; }

 private:
  std::string name_;
  std::string help_;
  std::unique_ptr<CLI::App> app_;
  std::vector<std::string> positionals_;
};

}  // namespace mobirt::cli
