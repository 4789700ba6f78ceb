// Animation parsing: the channels and samplers of a glTF file's animations, checked and turned into
// the rig's keyframe tracks (sampling itself is format-free: scene/keyframes.h).
#pragma once

#include "scene/gltf_accessors.h"
#include "scene/gltf_rig.h"

namespace mobirt::gltf {

// Adds the channels and tracks of the animations played, all (only < 0) or animations[only], to
// `rig`, whose nodes (rig.weight_count, animated_node) are prepared. Played together, the first
// channel that drives a property of a node wins; `warn_overrides` names the animations that lose.
void read_animations(const AccessorReader& reader, int only, bool warn_overrides, GltfRig& rig);

}  // namespace mobirt::gltf
