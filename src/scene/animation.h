// Animated scenes, evaluated on the CPU once per frame (the kd-tree is then rebuilt from scratch):
// - glTF 2.0: node TRS animation (translation, rotation, scale; LINEAR with slerp for rotations,
//   STEP and CUBICSPLINE), skins (JOINTS_0 / WEIGHTS_0, inverseBindMatrices) and morph targets
//   (POSITION and NORMAL targets, mesh or node weights, "weights" channels);
// - OBJ frame sequences: a folder of .obj files (sorted by name) or a printf pattern such as
//   "wooddoll_%02d.obj", all frames loaded up front, played at LoadOptions::fps.
//
// Semantics:
// - Time t is in seconds. Every glTF sampler is clamped outside its key range (before the first
//   key: the first value; after the last: the last value). duration() is the latest key time of
//   the animations played; evaluate() at any t is valid, also beyond duration().
// - All animations of a glTF file play together, starting at t = 0 (LoadOptions::animation picks
//   one). Where two channels drive the same property (translation, rotation, scale, weights) of
//   the same node, the first in file order (animations[a].channels[c], a then c) wins and the
//   others are dropped (a warning names their animations), so that a file with alternative clips
//   of one skeleton (Fox: Survey, Walk, Run) plays its first clip, as viewers do by default.
//   duration() counts the channels kept only.
// - Skinned meshes: the world transform of the mesh's own node is ignored (glTF 2.0, 3.7.3); joint
//   matrices are world(joint) * inverseBindMatrix; weights are renormalised to sum 1 (a vertex
//   with all weights 0 keeps its bind-space position). Normals take the inverse transpose of the
//   blended skin matrix.
// - Morph targets: position/normal = base + sum of weight_i * target_i; weights from the "weights"
//   channel, else the node's weights, else the mesh's, else 0. TANGENT targets are ignored.
// - OBJ sequences: frame = floor(t * fps) clamped to [0, frames - 1], no interpolation; every
//   frame must have the topology of the first (triangle count and per-triangle materials).
//   Texture coordinates, materials and textures are those of the first frame.
// - rest() is the scene at t = 0; load_scene(path) returns the same scene for a single file.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "scene/loader.h"
#include "scene/scene.h"

namespace mobirt {

namespace detail {
// What moves: writes positions, normals, lights and camera of the scene at time t into `out`, whose
// static parts (texture coordinates, material ids, materials, textures) are already in place and
// whose arrays already have the right sizes.
class Animator {
 public:
  virtual ~Animator() = default;
  virtual void evaluate(double t, Scene& out) const = 0;
};
}  // namespace detail

class AnimatedScene {
 public:
  AnimatedScene() = default;
  // `rest`: the validated scene at t = 0; `animator` null: a static scene.
  AnimatedScene(Scene rest, std::shared_ptr<const detail::Animator> animator, double duration,
                double fps, size_t frames = 0);

  bool animated() const { return animator_ != nullptr; }
  double duration() const { return duration_; }  // seconds; 0 for a static scene
  double fps() const { return fps_; }             // natural frame rate for rendering frames
  size_t frame_count() const { return frames_; }  // OBJ sequences: files loaded; glTF: 0
  const Scene& rest() const { return rest_; }

  // `out` gets the scene at time t: world-space positions and normals, lights and camera. The
  // static parts (source, materials, textures, texture coordinates, material ids, background)
  // are copied from rest() only when `out` does not hold them already (first call), so that a
  // Scene reused from frame to frame keeps its allocations. Anything the caller overrides on
  // `out` (lights, camera) must be re-applied after each call. Throws Error(BadInput) when the
  // scene at t is broken (a camera or spot/directional light whose node scales to zero). A NaN t
  // means t = 0. Thread-safe: evaluate() changes nothing but `out`.
  void evaluate(double t, Scene& out) const;

  // The scene at time t as a new Scene.
  Scene at(double t) const {
    Scene s;
    evaluate(t, s);
    return s;
  }

 private:
  Scene rest_;
  std::shared_ptr<const detail::Animator> animator_;
  double duration_ = 0.0;
  double fps_ = 24.0;
  size_t frames_ = 0;
};

// `path`: a .gltf/.glb, an .obj (static), a folder of .obj files, or a printf pattern with one
// %d conversion (flags '0' and a width allowed, "%%" for a literal '%'; frames counted from 0, or
// from 1 when frame 0 is absent, up to the first missing number). Errors: Error(BadInput) naming
// the file (for a topology mismatch: the frame file that differs from the first).
AnimatedScene load_animated_scene(const std::string& path, const LoadOptions& options = {});

// The files of an OBJ sequence in playing order: the folder's *.obj sorted by name, or the
// pattern's frames. Throws Error(BadInput) when there are none.
std::vector<std::string> sequence_files(const std::string& path);

// True when `path` names an OBJ sequence (a folder or a pattern containing '%') rather than a file.
bool is_sequence_path(const std::string& path);

namespace detail {
// Loaders behind load_animated_scene (gltf_loader.cpp, obj_loader.cpp).
AnimatedScene load_gltf_animated(const std::string& path, const LoadOptions& options);
// One OBJ frame; `warnings` false keeps its warnings quiet (the later frames of a sequence).
Scene load_obj_frame(const std::string& path, const std::string& mtl, bool warnings);
AnimatedScene load_obj_sequence(const std::vector<std::string>& files, const std::string& source,
                                const LoadOptions& options);
}  // namespace detail

}  // namespace mobirt
