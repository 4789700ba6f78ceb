// The scene, view and tree a profiling tool works on, from the same options as `mobirt render`
// (the subset that matters to traversal), shared by tools/profile/*.cpp.
//
//   TOOL SCENE [--mtl F] [--camera SPEC] [--light SPEC]... [--size WxH] [--stack N] [--bins N]
//        [--leaf-size N] [--isect-cost C] [--max-depth N] [--empty-bonus-min-width W] [--depth N]
//        [--csv FILE] [--repeat N]
#pragma once

#include <cstdio>
#include <exception>
#include <optional>
#include <string>
#include <vector>

#include "accel/kdtree.h"
#include "core/camera.h"
#include "core/error.h"
#include "raytree/ray_order.h"
#include "scene/animation.h"
#include "scene/loader.h"
#include "scene/overrides.h"

namespace mobirt::profile {

struct ProfileScene {
  std::string path;
  Scene scene;
  Camera camera;
  FlatKdTree tree;
  int width = 400, height = 240, stack = 4, depth = 0, repeat = 5;
  std::string csv;  // empty: no CSV
  // --ray-order coherent (the renderer's: sorted when the octants are mixed), sorted (always) or
  // tiles (the tiling alone): order_for_traversal's sort_above.
  float sort_above = kSortAboveOctantChanges;
};

inline ProfileScene load_profile_scene(int argc, char** argv, const char* usage) {
  if (argc < 2) {
    std::fprintf(stderr, "%s\n", usage);
    throw Error(ErrorKind::BadInput, "no scene given");
  }
  ProfileScene p;
  p.path = argv[1];
  LoadOptions load;
  // The tools compare triangle engines (Embree, the driver's ray queries) with mobirt's walk on the
  // same triangles: NFF shapes come tessellated.
  load.analytic = false;
  std::vector<Light> lights;
  std::optional<Camera> camera;
  KdBuildOptions kd;
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) throw Error(ErrorKind::BadInput, a + " needs a value");
    const std::string v = argv[++i];
    if (a == "--mtl") load.mtl = v;
    else if (a == "--camera") camera = parse_camera(v);
    else if (a == "--light") lights.push_back(parse_light(v));
    else if (a == "--size") std::sscanf(v.c_str(), "%dx%d", &p.width, &p.height);
    else if (a == "--stack") p.stack = std::stoi(v);
    else if (a == "--bins") kd.bins = std::stoi(v);
    else if (a == "--leaf-size") kd.max_leaf_prims = std::stoi(v);
    else if (a == "--isect-cost") kd.intersection_cost = std::stof(v);
    else if (a == "--max-depth") kd.max_depth = std::stoi(v);
    else if (a == "--empty-bonus-min-width") kd.empty_bonus_min_width = std::stof(v);
    else if (a == "--depth") p.depth = std::stoi(v);
    else if (a == "--repeat") p.repeat = std::stoi(v);
    else if (a == "--csv") p.csv = v;
    else if (a == "--ray-order" && v == "coherent") p.sort_above = kSortAboveOctantChanges;
    else if (a == "--ray-order" && v == "sorted") p.sort_above = 0.0f;
    else if (a == "--ray-order" && v == "tiles") p.sort_above = 2.0f;
    else throw Error(ErrorKind::BadInput, "unknown option " + a + "\n" + usage);
  }
  const AnimatedScene animation = load_animated_scene(p.path, load);
  p.scene = animation.rest();
  apply_overrides(p.scene, lights, camera);
  p.camera = p.scene.camera ? *p.scene.camera
                            : frame_box(p.scene.bounds(), 0.7854f, float(p.width) / float(p.height));
  p.tree = build_kdtree(p.scene.mesh.positions, kd);
  return p;
}

// main() of a profiling tool: runs `run`, and turns an exception into a message and exit code 2.
inline int run_tool(const char* name, int argc, char** argv, int (*run)(int, char**)) {
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: error: %s\n", name, e.what());
    return 2;
  }
}

}  // namespace mobirt::profile
