#include "app/options.h"

#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <sstream>
#include <type_traits>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "scene/overrides.h"

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

glm::vec3 parse_colour(const Value& v) {
  glm::vec3 c;
  char extra = 0;
  if (std::sscanf(v.text.c_str(), "%f,%f,%f%c", &c.x, &c.y, &c.z, &extra) != 3 ||
      !(c.x >= 0 && c.y >= 0 && c.z >= 0 && c.x < 1e30f && c.y < 1e30f && c.z < 1e30f)) {
    usage_error(v.option + " " + v.text + ": expected three non-negative numbers R,G,B", v.help);
  }
  return c;
}

// The render settings the commands share: one line each, in the order --help lists them. A
// setting that takes no value (value name nullptr) is a flag. Adding a setting is adding a line.
struct Setting {
  const char* names;       // CLI11 names: "--bins", or "--colour,--color" (the first one is shown)
  const char* value_name;  // shown in --help; nullptr: a flag
  unsigned commands;       // the commands that take it
  const char* description;
  void (*apply)(CommonOptions&, const Value&);
};

constexpr unsigned kViews = kRender | kAccuracy;    // settings of one view of one scene
constexpr unsigned kFrames = kViews | kBench;       // how any frame is made
constexpr unsigned kDevice = kFrames | kInfo;       // the device the passes run on

const Setting kSettings[] = {
    {"--size", "WxH", kViews, "image size in pixels (default 400x240)",
     [](CommonOptions& o, const Value& v) {
       std::tie(o.settings.width, o.settings.height) = parse_size(v.option, v.text, v.help);
       o.size_given = true;
     }},
    {"--depth", "N", kViews,
     "bounces of the ray tree: 0 = ray casting; reflection and refraction\n"
     "rays are made only for materials that reflect or refract (default 2)",
     [](CommonOptions& o, const Value& v) { o.settings.depth = v.integer(0, 64); }},
    {"--no-shadows", nullptr, kViews, "no shadow rays: every light lights every surface that faces it",
     [](CommonOptions& o, const Value&) { o.settings.shadows = false; }},
    {"--general", nullptr, kFrames,
     "general passes sized for 8 (or 16) lights and 48 textures on 3 atlas pages\n"
     "instead of passes specialised to the scene (same image; for comparisons)",
     [](CommonOptions& o, const Value&) { o.settings.specialize = false; }},
    {"--always-rebuild", nullptr, kViews,
     "rebuild the kd-tree every frame even when the triangles did not move",
     [](CommonOptions& o, const Value&) { o.settings.always_rebuild = true; }},
    {"--min-weight", "W", kFrames, "secondary rays whose weight is below W are not traced (default 1/512)",
     [](CommonOptions& o, const Value& v) { o.settings.secondary.min_weight = v.real(0.0f, 1.0f); }},
    {"--stack", "N", kFrames,
     "short-stack entries of the traversal shader, 0 = pure kd-restart\n"
     "(default 6, at most 32)",
     [](CommonOptions& o, const Value& v) { o.settings.stack_depth = v.integer(0, MOBIRT_MAX_STACK_DEPTH); }},
    {"--max-steps", "N", kFrames,
     "loop cap of one traversal in the shader; rays that reach it are traced\n"
     "on the CPU instead, so the cap costs time, never pixels (default 2048)",
     [](CommonOptions& o, const Value& v) { o.settings.max_steps = v.integer(1, 1 << 24); }},
    {"--cpu-walks", "N", kFrames,
     "a secondary generation of at most N rays is walked on the CPU (the\n"
     "same hits and shadow masks) instead of a traversal pass, whose fixed\n"
     "cost and 8-wide lanes a few incoherent rays do not pay for; 0 = always\n"
     "a pass (default 8192)",
     [](CommonOptions& o, const Value& v) { o.settings.cpu_walks = v.integer(0, 1 << 24); }},
    {"--bins", "N", kFrames, "SAH bins per axis of the kd-tree build (default 32)",
     [](CommonOptions& o, const Value& v) { o.settings.kd.bins = v.integer(2, 1024); }},
    {"--build", "MODE", kFrames,
     "kd-tree build: fast (straddling triangles split by the plane, their\n"
     "parts' boxes cut to the node's; nodes of up to 3 references stay\n"
     "leaves) or quality (exact split clipping, pbrt's SAH, leaves of 1)\n"
     "(default fast)",
     [](CommonOptions& o, const Value& v) {
       static constexpr std::pair<const char*, KdBuildMode> modes[] = {{"fast", KdBuildMode::Fast},
                                                                       {"quality", KdBuildMode::Quality}};
       o.settings.kd.build = v.choice(modes);
     }},
    {"--leaf-size", "N", kFrames,
     "largest leaf the build makes without trying to split (default: the\n"
     "build's: fast 3, quality 1)",
     [](CommonOptions& o, const Value& v) { o.settings.kd.max_leaf_prims = v.integer(1, 1 << 20); }},
    {"--cluster-refs", "N", kFrames,
     "nodes of at most N references take no split that keeps them all on\n"
     "one side and duplicates some into the other (a vertex's fan of\n"
     "triangles); 0 = pbrt's SAH alone (default: the build's: fast 6,\n"
     "quality 0)",
     [](CommonOptions& o, const Value& v) { o.settings.kd.cluster_refs = v.integer(0, 1 << 20); }},
    {"--empty-bonus", "B", kFrames,
     "SAH discount of a split that cuts off empty space, of every tree\n"
     "built: a smaller bonus makes more nodes, a slower build and a few per\n"
     "cent shorter walks (default: pbrt's 0.5, and 0.2 for a fast per-frame\n"
     "tree built for a frame's walks, --tree walks, which bounce frames gain\n"
     "from)",
     [](CommonOptions& o, const Value& v) { o.settings.kd.empty_bonus = v.real(0.0f, 0.9f); }},
    {"--max-depth", "N", kFrames, "kd-tree depth limit, -1 = 8 + 1.3 log2(triangles) (default -1)",
     [](CommonOptions& o, const Value& v) { o.settings.kd.max_depth = v.integer(-1, 128); }},
    {"--deep-levels", "N", kFrames,
     "levels past the depth limit in which nodes of more than --deep-refs\n"
     "references keep splitting (default: the build's: fast 4, quality 0)",
     [](CommonOptions& o, const Value& v) { o.settings.kd.deep_levels = v.integer(0, 32); }},
    {"--deep-refs", "N", kFrames,
     "past the depth limit, nodes of more than N references split (default 10)",
     [](CommonOptions& o, const Value& v) { o.settings.kd.deep_refs = v.integer(0, 1 << 20); }},
    {"--offset", "MODE", kFrames,
     "how shadow, mirror and refracted rays leave a surface, along its normal:\n"
     "fixed (--epsilon in scene units), scaled (--epsilon x the scene's\n"
     "size, never below 2 ulps of the hit point) or normal-ulp (Wachter and\n"
     "Binder 2019: 256 x the normal in ulps of each coordinate; ignores\n"
     "--epsilon) (default scaled)",
     [](CommonOptions& o, const Value& v) {
       static constexpr std::pair<const char*, OffsetMode> modes[] = {
           {"fixed", OffsetMode::Fixed}, {"scaled", OffsetMode::Scaled}, {"normal-ulp", OffsetMode::NormalUlp}};
       o.settings.shadow_rays.offset.mode = v.choice(modes);
       o.settings.secondary.offset.mode = o.settings.shadow_rays.offset.mode;
     }},
    {"--epsilon", "E", kFrames, "the offset of --offset fixed or scaled (default 1e-6)",
     [](CommonOptions& o, const Value& v) {
       o.settings.shadow_rays.offset.epsilon = v.real(0.0f, 1.0f);
       o.settings.secondary.offset.epsilon = o.settings.shadow_rays.offset.epsilon;
     }},
    {"--intersect", "TEST", kFrames,
     "ray/triangle test of the traversal pass (and of the CPU's): mt\n"
     "(Moller-Trumbore) or watertight (Woop et al. 2013: no ray slips\n"
     "between triangles sharing an edge) (default mt)",
     [](CommonOptions& o, const Value& v) {
       static constexpr std::pair<const char*, IntersectTest> tests[] = {
           {"mt", IntersectTest::MollerTrumbore}, {"watertight", IntersectTest::Watertight}};
       o.settings.shadow_rays.ray_test.test = v.choice(tests);
     }},
    {"--precision", "P", kFrames,
     "float precision of the intersection arithmetic: highp (fp32) or\n"
     "mediump (fp16, emulated by rounding the rays, the vertices and every\n"
     "intermediate result) (default highp)",
     [](CommonOptions& o, const Value& v) {
       static constexpr std::pair<const char*, Precision> precisions[] = {{"highp", Precision::High},
                                                                          {"mediump", Precision::Medium}};
       o.settings.shadow_rays.ray_test.precision = v.choice(precisions);
     }},
    {"--colour,--color", "8|16", kFrames,
     "bits per colour channel the shading pass returns: 8 (one pass) or 16\n"
     "(two passes: high and low bytes) (default 8)",
     [](CommonOptions& o, const Value& v) {
       static constexpr std::pair<const char*, ColourDepth> depths[] = {{"8", ColourDepth::Bits8},
                                                                        {"16", ColourDepth::Bits16}};
       o.settings.colour = v.choice(depths);
     }},
    {"--data", "READS", kFrames,
     "how the Vulkan traversal pass reads nodes, leaf entries and\n"
     "triangles: texel-buffers (uniform texel buffers), images (2D\n"
     "textures, as OpenGL ES 2.0 always does), storage-buffers (read-only;\n"
     "breaks the ES 2.0 model, to measure) or device-addresses (the same\n"
     "buffers through buffer references, no texture calls in llvmpipe;\n"
     "breaks the model too, to measure) (default texel-buffers)",
     [](CommonOptions& o, const Value& v) {
       static constexpr std::pair<const char*, DataReads> reads[] = {
           {"texel-buffers", DataReads::TexelBuffers},
           {"images", DataReads::Images},
           {"storage-buffers", DataReads::StorageBuffers},
           {"device-addresses", DataReads::DeviceAddresses}};
       o.settings.data = v.choice(reads);
     }},
    {"--primary", "HITS", kFrames,
     "how the primary rays' closest hits are found: trace (through the\n"
     "kd-tree, as every generation: the paper's pipeline), raster (the\n"
     "triangles drawn with a depth test, shadow rays traced from them; no\n"
     "kd-tree at all without secondary rays where every shadow ray tests\n"
     "a light buffer (--shadow-cells); scenes with analytic shapes are\n"
     "traced) or auto (raster up to 0.5 triangles per pixel, and past it\n"
     "when that spares the frame a kd-tree it would build: --always-rebuild\n"
     "or an animation's --frames, no ray that walks one; trace elsewhere)\n"
     "(default auto)",
     [](CommonOptions& o, const Value& v) {
       static constexpr std::pair<const char*, PrimaryHits> hits[] = {
           {"trace", PrimaryHits::Trace}, {"raster", PrimaryHits::Raster}, {"auto", PrimaryHits::Auto}};
       o.settings.primary = v.choice(hits);
     }},
    {"--mirrors", "HITS", kFrames,
     "how the first bounce's mirror rays off a flat mirror (the plane of\n"
     "reflective, flat-shaded triangles that sends the most) find their\n"
     "closest hits: trace (through the kd-tree, as every ray) or raster (the\n"
     "scene mirrored in that plane drawn from the camera, their shadow rays\n"
     "traced from those hits; the other rays walk), auto (raster where that\n"
     "plane sends mirror rays from at least a quarter of the pixels and the\n"
     "mesh has at most half a triangle a pixel) (default auto)",
     [](CommonOptions& o, const Value& v) {
       static constexpr std::pair<const char*, MirrorHits> hits[] = {
           {"trace", MirrorHits::Trace}, {"raster", MirrorHits::Raster}, {"auto", MirrorHits::Auto}};
       o.settings.mirrors = v.choice(hits);
     }},
    {"--tree", "FIT", kFrames,
     "what an animation's per-frame kd-tree is built for (render --frames,\n"
     "bench; a single frame always gets the full tree): walks (the walks\n"
     "of the tree two frames before: where most rays are drawn or test\n"
     "light buffers, the shallow tree those few walks pay for) or full (for\n"
     "unboundedly many rays: the SAH alone, as the paper) (default walks)",
     [](CommonOptions& o, const Value& v) {
       static constexpr std::pair<const char*, TreeFit> fits[] = {{"walks", TreeFit::Walks}, {"full", TreeFit::Full}};
       o.settings.tree = v.choice(fits);
     }},
    {"--shading", "PASSES", kFrames,
     "how a frame's hits are shaded: frame (one shading pass over every\n"
     "generation's hits after the last, its fixed cost paid once a frame)\n"
     "or generation (one pass per generation as it is decoded); the same\n"
     "image either way (default frame)",
     [](CommonOptions& o, const Value& v) {
       static constexpr std::pair<const char*, ShadingPasses> passes[] = {{"frame", ShadingPasses::Frame},
                                                                         {"generation", ShadingPasses::Generation}};
       o.settings.shading = v.choice(passes);
     }},
    {"--worker", "idle|normal", kFrames,
     "scheduling class of the pipelined frame loop's worker (render --frames,\n"
     "bench), which poses the next frame and builds its kd-tree: idle\n"
     "(SCHED_IDLE: it runs only where a CPU would idle, and never holds\n"
     "up the driver's pinned rasterizer threads) or normal (default idle)",
     [](CommonOptions& o, const Value& v) {
       static constexpr std::pair<const char*, WorkerPriority> classes[] = {{"idle", WorkerPriority::Idle},
                                                                            {"normal", WorkerPriority::Normal}};
       o.settings.worker = v.choice(classes);
     }},
    {"--shadow-cells", "N|auto", kFrames,
     "point and spot lights' shadow rays test the triangles of one cell of\n"
     "a light buffer (N x N cells per cube face around the light) instead\n"
     "of walking the kd-tree; 0 walks it; auto: 64 up to 32,768 triangles\n"
     "under highp, else 0 (default auto)",
     [](CommonOptions& o, const Value& v) { o.settings.shadow_cells = v.text == "auto" ? -1 : v.integer(0, 1024); }},
    {"--light", "SPEC", kViews,
     "replaces the scene's lights (repeat for several):\n"
     "  \"point pos=X,Y,Z [color=R,G,B] [intensity=I] [range=R]\"\n"
     "  \"spot pos=X,Y,Z dir=X,Y,Z [inner=DEG] [outer=DEG] [color=..] [intensity=..] [range=..]\"\n"
     "  \"directional dir=X,Y,Z [color=R,G,B] [intensity=I]\"",
     [](CommonOptions& o, const Value& v) { o.edits.lights.push_back(parse_light(v.text)); }},
    {"--camera", "SPEC", kViews,
     "replaces the scene's camera: \"EX,EY,EZ:TX,TY,TZ:UX,UY,UZ:FOVDEG\"\n"
     "(look-from, look-at, up, vertical field of view in degrees)",
     [](CommonOptions& o, const Value& v) { o.edits.camera = parse_camera(v.text); }},
    {"--background", "R,G,B", kViews, "colour of rays that miss (default 0,0,0)",
     [](CommonOptions& o, const Value& v) { o.edits.background = parse_colour(v); }},
    {"--time", "T", kViews, "render the animation at T seconds (default 0)",
     [](CommonOptions& o, const Value& v) { o.time = v.number(-1e6, 1e6); }},
    {"--mtl", "FILE", kViews, "an OBJ's material library instead of the one it names (mtllib)",
     [](CommonOptions& o, const Value& v) { o.mtl = v.text; }},
    {"--primitives", "FORM", kFrames | kInfo,
     "NFF spheres, cylinders and cones: analytic (kd-tree primitives\n"
     "intersected exactly) or tessellated (64 facets around, 32 rings)\n"
     "(default analytic)",
     [](CommonOptions& o, const Value& v) {
       static constexpr std::pair<const char*, bool> forms[] = {{"analytic", true}, {"tessellated", false}};
       o.analytic = v.choice(forms);
     }},
    {"--backend", "gles|vulkan", kRender | kInfo,
     "the API the GPU passes run on: Vulkan, or OpenGL ES 2.0 through EGL\n"
     "without a window (default vulkan)",
     [](CommonOptions& o, const Value& v) { o.backend_name = v.text; }},
    {"--device", "D", kDevice, "Vulkan device: index or part of its name (default: lavapipe)",
     [](CommonOptions& o, const Value& v) { o.backend.device = v.text; }},
    {"--validation", nullptr, kDevice, "enable the Khronos validation layer; any message is an error",
     [](CommonOptions& o, const Value&) { o.backend.validation = true; }},
    {"--pin-threads", "on|off", kDevice,
     "pin Mesa's rasterizer threads (llvmpipe-N) one per CPU, so that a\n"
     "pass never runs two of them on one CPU while another idles (default on)",
     [](CommonOptions& o, const Value& v) {
       static constexpr std::pair<const char*, bool> modes[] = {{"on", true}, {"off", false}};
       o.backend.pin_threads = v.choice(modes);
     }},
    {"--gpu-timestamps", "auto|on|off", kDevice,
     "time each Vulkan pass on the device's clock (timestamp queries) or on\n"
     "the CPU's (its submission until its fence); lavapipe waits for the\n"
     "work at every timestamp, about 0.15 ms a pass; auto: on for a GPU,\n"
     "off for a CPU device (default auto)",
     [](CommonOptions& o, const Value& v) {
       static constexpr std::pair<const char*, GpuTimestamps> modes[] = {
           {"auto", GpuTimestamps::Auto}, {"on", GpuTimestamps::On}, {"off", GpuTimestamps::Off}};
       o.backend.timestamps = v.choice(modes);
     }},
};

// --help as mobirt has always printed it: the usage line and text, then each group of options
// with "-o, --output FILE" in a 26-character column and the description beside it.
class HelpFormatter : public CLI::Formatter {
 public:
  HelpFormatter() { column_width(26); }
  std::string make_help(const CLI::App* app, std::string, CLI::AppFormatMode mode) const override {
    return app->get_description() + "\n" + make_groups(app, mode);
  }
  // CLI11 puts a blank line between groups already.
  std::string make_group(std::string group, bool, std::vector<const CLI::Option*> opts) const override {
    std::string out = group + ":\n";
    for (const CLI::Option* opt : opts) out += make_option(opt, false);
    return out;
  }
  std::string make_option_name(const CLI::Option* opt, bool) const override {
    std::string name;
    for (const std::string& s : opt->get_snames()) name += "-" + s + ", ";
    if (opt->get_lnames().empty()) return name.substr(0, name.size() - 2);
    return name + "--" + opt->get_lnames().front();  // aliases such as --color stay unlisted
  }
  std::string make_option_opts(const CLI::Option* opt) const override {
    return opt->get_option_text().empty() ? "" : " " + opt->get_option_text();
  }
};

const char* command_name(Command c) {
  switch (c) {
    case kRender: return "render";
    case kAccuracy: return "accuracy";
    case kBench: return "bench";
    case kInfo: return "info";
  }
  return "mobirt";
}

// Whether CLI11 reads ARG as an option rather than a value (negative numbers are values).
bool looks_like_option(const std::string& arg) {
  return arg.size() > 1 && arg[0] == '-' && !std::isdigit(static_cast<unsigned char>(arg[1]));
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

std::pair<int, int> parse_size(const std::string& option, const std::string& value, const std::string& help) {
  int w = 0, h = 0;
  char extra = 0;
  if (std::sscanf(value.c_str(), "%dx%d%c", &w, &h, &extra) != 2 || w < 1 || h < 1 || w > 16384 || h > 16384) {
    usage_error(option + " " + value + ": expected WxH with 1 <= W, H <= 16384, e.g. 400x240", help);
  }
  return {w, h};
}

CommandLine::CommandLine(Command command, const std::string& usage, const std::string& about, std::string help,
                         CommonOptions& common)
    : name_(command_name(command)),
      help_(std::move(help)),
      app_(std::make_unique<CLI::App>(usage + "\n\n" + about)) {
  app_->allow_extras();  // unknown options and positionals: reported below in mobirt's words
  app_->set_help_flag();
  app_->formatter(std::make_shared<HelpFormatter>());
  app_->add_flag_callback("-h,--help", [] { throw CLI::CallForHelp(); }, "this help")->trigger_on_parse();
  const std::string group = command == kInfo ? "Options" : "Render options";
  for (const Setting& s : kSettings) {
    if (!(s.commands & command)) continue;
    const std::string option = CLI::detail::split_names(s.names).front();
    auto apply = [&common, apply = s.apply, option, help = help_](const std::string& text) {
      apply(common, Value{option, text, help});
    };
    CLI::Option* o =
        s.value_name ? app_->add_option(
                           s.names, [apply](const CLI::results_t& r) { for (const std::string& t : r) apply(t); return true; },
                           s.description)
                     : app_->add_flag_callback(s.names, [apply] { apply(""); }, s.description);
    o->option_text(s.value_name ? s.value_name : "")->group(group)->trigger_on_parse();
  }
}

CommandLine::~CommandLine() = default;

void CommandLine::option(const std::string& names, const std::string& value_name, const std::string& description,
                         std::function<void(const Value&)> apply) {
  const std::string option = CLI::detail::split_names(names).front();
  app_->add_option(names,
                   [apply = std::move(apply), option, this](const CLI::results_t& r) {
                     for (const std::string& t : r) apply(Value{option, t, help_});
                     return true;
                   },
                   description)
      ->option_text(value_name)
      ->group("Options")
      ->trigger_on_parse();
}

void CommandLine::flag(const std::string& names, const std::string& description, std::function<void()> apply) {
  app_->add_flag_callback(names, std::move(apply), description)->group("Options")->trigger_on_parse();
}

std::string CommandLine::scene() const {
  if (positionals_.empty()) usage_error(name_ + ": no scene given", help_);
  if (positionals_.size() > 1) {
    usage_error(name_ + ": more than one scene given ('" + positionals_[0] + "' and '" + positionals_[1] + "')", help_);
  }
  return positionals_[0];
}

std::string CommandLine::help_text() const { return app_->help(); }

bool CommandLine::parse(const std::vector<std::string>& args) {
  std::vector<std::string> reversed(args.rbegin(), args.rend());  // CLI11 takes them last first
  try {
    app_->parse(reversed);
  } catch (const CLI::CallForHelp&) {
    std::cout << help_text();
    return false;
  } catch (const CLI::ArgumentMismatch& e) {
    // An option without its value: name it as the user typed it.
    for (size_t i = 0; i < args.size(); ++i) {
      const CLI::Option* o = app_->get_option_no_throw(args[i]);
      if (o && o->get_type_size() != 0 && (i + 1 == args.size() || looks_like_option(args[i + 1]))) {
        usage_error(args[i] + " needs a value", help_);
      }
    }
    usage_error(name_ + ": " + e.what(), help_);
  } catch (const CLI::ParseError& e) {
    usage_error(name_ + ": " + e.what(), help_);
  }
  positionals_.clear();
  for (const std::string& a : app_->remaining()) {
    if (looks_like_option(a)) usage_error(name_ + ": unknown option " + a, help_);
    positionals_.push_back(a);
  }
  return true;
}

nlohmann::json kd_settings_json(const KdBuildOptions& kd) {
  // The bonus of a full tree and of one built for a frame's walks (kd_empty_bonus).
  KdBuildOptions full = kd, walks = kd;
  full.rays = 0.0;
  walks.rays = 1.0;
  return {{"bins", kd.bins},
          {"build", kd_build_mode_name(kd.build)},
          {"leaf_size", kd_leaf_size(kd)},
          {"cluster_refs", kd_cluster_refs(kd)},
          {"empty_bonus", kd_empty_bonus(full)},
          {"walks_empty_bonus", kd_empty_bonus(walks)},
          {"max_depth", kd.max_depth},
          {"deep_levels", kd_deep_levels(kd)},
          {"deep_refs", kd.deep_refs},
          {"build_ref_cost", kd_build_ref_cost(kd)},
          {"rays_leaf_limit", kd.rays_leaf_limit}};
}

}  // namespace mobirt::cli
