#include "scene/gltf_animation.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "scene/validate.h"

namespace mobirt::gltf {

void read_animations(const AccessorReader& reader, int only, bool warn_overrides, GltfRig& rig) {
  const tinygltf::Model& model = reader.model();
  const std::string& file = reader.file();
  const size_t nanim = model.animations.size();
  if (only >= 0 && static_cast<size_t>(only) >= nanim) {
    reader.fail("animation " + str(only) + " does not exist (the file has " + str(nanim) +
                " animations)");
  }
  std::set<size_t> claimed;        // node * 4 + path
  std::vector<size_t> overridden;  // animations with channels dropped
  for (size_t a = 0; a < nanim; ++a) {
    if (only >= 0 && a != static_cast<size_t>(only)) continue;
    const tinygltf::Animation& anim = model.animations[a];
    const std::string aname = element("animations", a);
    std::map<int, size_t> sampler_map;  // the animation's sampler -> rig.samplers
    for (size_t c = 0; c < anim.channels.size(); ++c) {
      const tinygltf::AnimationChannel& ch = anim.channels[c];
      const std::string cname = aname + "." + element("channels", c);
      if (ch.target_node < 0) continue;  // no target node: the channel is ignored (glTF 2.0)
      if (static_cast<size_t>(ch.target_node) >= model.nodes.size()) {
        reader.fail(cname + ": target node " + str(ch.target_node) + " does not exist (the file has " +
                    str(model.nodes.size()) + " nodes)");
      }
      const size_t node = static_cast<size_t>(ch.target_node);
      ChannelPath path;
      size_t width;
      int want_type;
      if (ch.target_path == "translation") {
        path = ChannelPath::Translation, width = 3, want_type = TINYGLTF_TYPE_VEC3;
      } else if (ch.target_path == "rotation") {
        path = ChannelPath::Rotation, width = 4, want_type = TINYGLTF_TYPE_VEC4;
      } else if (ch.target_path == "scale") {
        path = ChannelPath::Scale, width = 3, want_type = TINYGLTF_TYPE_VEC3;
      } else if (ch.target_path == "weights") {
        path = ChannelPath::Weights, width = rig.weight_count[node],
        want_type = TINYGLTF_TYPE_SCALAR;
        if (width == 0) {
          scene_warning(file, cname + ": animates the morph weights of " +
                                   element("nodes", node) +
                                   ", which has no mesh with morph targets: ignored");
          continue;
        }
      } else {
        scene_warning(file, cname + ": target path '" + ch.target_path + "' is not supported: "
                                 "ignored");
        continue;
      }
      // Played together, the first channel that drives a property of a node wins.
      const size_t claim = node * 4 + static_cast<size_t>(path);
      if (!claimed.insert(claim).second) {
        if (overridden.empty() || overridden.back() != a) overridden.push_back(a);
        continue;
      }
      if (ch.sampler < 0 || static_cast<size_t>(ch.sampler) >= anim.samplers.size()) {
        reader.fail(cname + ": sampler " + str(ch.sampler) + " does not exist (the animation has " +
                    str(anim.samplers.size()) + " samplers)");
      }
      size_t sampler_index;
      if (auto it = sampler_map.find(ch.sampler); it != sampler_map.end()) {
        sampler_index = it->second;
        if (rig.samplers[sampler_index].width != width) {
          reader.fail(cname + ": sampler " + str(ch.sampler) + " is shared by targets of different sizes");
        }
      } else {
        const tinygltf::AnimationSampler& src = anim.samplers[static_cast<size_t>(ch.sampler)];
        const std::string sname = aname + "." + element("samplers", static_cast<size_t>(ch.sampler));
        KeyframeTrack s;
        s.width = width;
        if (src.interpolation.empty() || src.interpolation == "LINEAR") {
          s.interpolation = Interpolation::Linear;
        } else if (src.interpolation == "STEP") {
          s.interpolation = Interpolation::Step;
        } else if (src.interpolation == "CUBICSPLINE") {
          s.interpolation = Interpolation::CubicSpline;
        } else {
          reader.fail(sname + ": interpolation '" + src.interpolation +
                      "' must be LINEAR, STEP or CUBICSPLINE");
        }
        const tinygltf::Accessor& in = reader.accessor(src.input, sname + ".input");
        if (in.type != TINYGLTF_TYPE_SCALAR || in.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT) {
          reader.fail(element("accessors", static_cast<size_t>(src.input)) + " (" + sname +
                      ".input): " + type_name(in.type) + " of " + component_name(in.componentType) +
                      ", expected SCALAR of FLOAT (key times in seconds)");
        }
        s.times = reader.read_accessor(src.input, sname + ".input");
        if (s.times.empty()) reader.fail(sname + ".input: no key times");
        for (size_t k = 0; k < s.times.size(); ++k) {
          if (!std::isfinite(s.times[k]) || s.times[k] < 0.0 ||
              (k > 0 && s.times[k] < s.times[k - 1])) {
            reader.fail(sname + ".input: key time " + str(k) + " (" + std::to_string(s.times[k]) +
                        ") is negative, not finite or smaller than the one before");
          }
        }
        const tinygltf::Accessor& out = reader.accessor(src.output, sname + ".output");
        if (out.type != want_type) {
          reader.fail(element("accessors", static_cast<size_t>(src.output)) + " (" + sname +
                      ".output): type " + type_name(out.type) + ", expected " + type_name(want_type) +
                      " for " + ch.target_path);
        }
        const bool float_or_normalized =
            out.componentType == TINYGLTF_COMPONENT_TYPE_FLOAT ||
            (out.normalized && path != ChannelPath::Translation && path != ChannelPath::Scale);
        if (!float_or_normalized) {
          reader.fail(element("accessors", static_cast<size_t>(src.output)) + " (" + sname +
                      ".output): component type " + component_name(out.componentType) +
                      ", expected FLOAT (or normalized integers for rotation and weights)");
        }
        s.values = reader.read_accessor(src.output, sname + ".output");
        const size_t per_key = s.interpolation == Interpolation::CubicSpline ? 3 : 1;
        const size_t want = s.times.size() * per_key * (path == ChannelPath::Weights ? width : 1);
        if (out.count != want) {
          reader.fail(element("accessors", static_cast<size_t>(src.output)) + " (" + sname +
                      ".output): " + str(out.count) + " elements, expected " + str(want) + " (" +
                      str(s.times.size()) + " key times" + (per_key == 3 ? " x 3 for CUBICSPLINE" : "") +
                      (path == ChannelPath::Weights ? " x " + str(width) + " morph targets" : "") + ")");
        }
        for (double v : s.values) {
          if (!std::isfinite(v)) reader.fail(sname + ".output: a value is not finite");
        }
        if (path == ChannelPath::Rotation) {
          for (size_t k = 0; k < s.times.size(); ++k) {
            const double* q = &s.values[(k * per_key + (per_key == 3 ? 1 : 0)) * 4];
            if (q[0] == 0.0 && q[1] == 0.0 && q[2] == 0.0 && q[3] == 0.0) {
              reader.fail(sname + ".output: key " + str(k) + " is a zero quaternion");
            }
          }
        }
        rig.duration = std::max(rig.duration, s.times.back());
        sampler_index = rig.samplers.size();
        rig.samplers.push_back(std::move(s));
        sampler_map[ch.sampler] = sampler_index;
      }
      if (path != ChannelPath::Weights) {
        if (!model.nodes[node].matrix.empty() && !rig.animated_node[node]) {
          scene_warning(file, cname + ": " + element("nodes", node) +
                                   " has a matrix, which glTF forbids for animated nodes; it is "
                                   "split into translation, rotation and scale");
        }
        rig.animated_node[node] = 1;
      }
      rig.channels.push_back({node, path, sampler_index});
    }
  }
  if (!overridden.empty() && warn_overrides) {
    std::string list;
    for (size_t a : overridden) {
      if (!list.empty()) list.append(", ");
      list.append(element("animations", a));
    }
    scene_warning(file, list + (overridden.size() == 1 ? " drives" : " drive") +
                             " node properties that an earlier animation drives already; all "
                             "animations play together and the earlier wins (choose one "
                             "animation to see it alone)");
  }
}

}  // namespace mobirt::gltf
