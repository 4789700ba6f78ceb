// The rig of a glTF file: what it animates and poses, in a form that evaluation walks without the
// tinygltf model: nodes with their rest transforms, the instances the scene traversal made of them,
// meshes, skins, lights, camera and the keyframe tracks of the animations played.
#pragma once

#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "scene/animation.h"
#include "scene/keyframes.h"
#include "scene/scene.h"

namespace mobirt::gltf {

enum class ChannelPath { Translation, Rotation, Scale, Weights };

struct AnimChannel {
  size_t node = 0;
  ChannelPath path = ChannelPath::Translation;
  size_t sampler = 0;
};

// One triangle primitive in its mesh's space, ready to be posed.
struct PrimData {
  std::vector<glm::vec3> positions;                 // per vertex
  std::vector<glm::vec3> normals;                   // per vertex; empty: flat normals
  std::vector<std::vector<glm::vec3>> target_positions;  // per morph target (empty: none)
  std::vector<std::vector<glm::vec3>> target_normals;    // per morph target (empty: none)
  std::vector<glm::uvec4> joints;                   // JOINTS_0; empty: not skinnable
  std::vector<glm::vec4> weights;                   // WEIGHTS_0, renormalised to sum 1
  uint32_t max_joint = 0;
  std::vector<uint32_t> triangles;                  // vertex indices, the file's winding
  std::vector<glm::vec2> uvs;                       // per vertex; empty: none
  uint32_t material = 0;
};

struct MeshData {
  bool prepared = false;
  std::vector<PrimData> prims;
};

struct SkinData {
  std::vector<size_t> joints;         // node indices
  std::vector<glm::dmat4> inverse_bind;
};

// A node as visited by the traversal of the scene (a node reached twice is two instances).
struct Instance {
  size_t node = 0;
  int parent = -1;  // instance index
};

struct Draw {
  size_t instance = 0;
  size_t mesh = 0;
  int skin = -1;
  size_t first_corner = 0;  // where its triangles start in the scene's vertex arrays
  bool flip = false;        // the rest pose mirrors (negative determinant): winding reversed
};

struct LightInstance {
  size_t instance = 0;
  Light light;  // everything but position and direction
};

struct CameraInstance {
  size_t instance = 0;
  size_t camera = 0;
  double yfov = 0.0;
  float znear = 0.0f;
};

class GltfRig : public detail::Animator {
 public:
  void evaluate(double t, Scene& out) const override;

  std::string file;
  // Nodes.
  std::vector<glm::dmat4> rest_local;         // the file's local transforms
  std::vector<glm::dvec3> rest_translation;   // TRS (a matrix node that is animated: decomposed)
  std::vector<glm::dquat> rest_rotation;
  std::vector<glm::dvec3> rest_scale;
  std::vector<uint8_t> animated_node;         // 1: its local transform comes from TRS at t
  std::vector<size_t> weight_offset;          // into rest_weights; npos: no morph weights
  std::vector<size_t> weight_count;
  std::vector<double> rest_weights;
  std::vector<int> node_parent;               // first parent, -1: root
  std::vector<size_t> node_order;             // parents before children (for joint worlds)
  // Scene traversal.
  std::vector<Instance> instances;
  std::vector<MeshData> meshes;
  std::vector<SkinData> skins;
  std::vector<Draw> draws;
  std::vector<LightInstance> lights;
  std::optional<CameraInstance> camera;
  size_t corners = 0;
  // Animation.
  std::vector<KeyframeTrack> samplers;
  std::vector<AnimChannel> channels;
  double duration = 0.0;

 private:
  [[noreturn]] void fail_at(double t, const std::string& message) const;
};

// The rig at time t: every node's TRS and morph weights, the world transform of every instance
// and (with skins) of every node, and the joint matrices of every skin.
struct Pose {
  std::vector<glm::dvec3> translation;
  std::vector<glm::dquat> rotation;
  std::vector<glm::dvec3> scale;
  std::vector<double> weights;
  std::vector<glm::dmat4> instance_world;
  std::vector<glm::dmat4> node_world;
  std::vector<std::vector<glm::dmat4>> joint_matrices;  // per skin
};

void pose(const GltfRig& rig, double t, Pose& p);

}  // namespace mobirt::gltf
