// mobirt bench: the harness runs every column on the same frames and writes every number; a bad
// option or output is refused before the long run.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "layout.h"
#include "test_support.h"

namespace mobirt {
namespace {

namespace fs = std::filesystem;

TEST(Bench, OneSmallCellWithEveryColumn) {
  const fs::path dir = test::temp_dir();
  const fs::path json = dir / "bench.json";
  const test::CommandResult r =
      test::run_mobirt("bench " MOBIRT_SOURCE_DIR "/scenes/fish.gltf --size 64x40 --frames 2 --warmup 1 "
                       "--levels shadow,bounce2 --primary trace --json '" + json.string() + "'");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("Table 1"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("Embree 3."), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("CPU time per frame, ms (median)"), std::string::npos) << r.output;
  // One progress line per cell on stderr, with the cell, the count and each column's fps. Primaries
  // traced, as the peers trace theirs: every column builds its acceleration structure and traces
  // the same rays (Bench.RasterizedPrimariesWithShadows has --primary auto's choice).
  for (const char* line : {"bench: [1/2] fish, + shadow (primary trace): Vulkan ",
                           "bench: [2/2] fish, + 2 bounces (primary trace): Vulkan "}) {
    EXPECT_NE(r.output.find(line), std::string::npos) << line << "\n" << r.output;
  }
  EXPECT_NE(r.output.find(" fps, GLES 2.0 "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(" fps, CPU kd-tree "), std::string::npos) << r.output;
  std::ifstream in(json);
  const nlohmann::json j = nlohmann::json::parse(in);
  ASSERT_EQ(j["cells"].size(), 2u);
  // The ray-query peer runs where the driver has ray queries; elsewhere one line says why.
  const std::string skipped = "bench: ray-query peer skipped: ";
  const size_t skip_line = r.output.find(skipped);
  const bool ray_query = skip_line == std::string::npos;
  if (ray_query) {
    EXPECT_NE(r.output.find(" fps, ray query "), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("fps/rq"), std::string::npos) << r.output;
    EXPECT_TRUE(j["machine"]["ray_query"].is_array()) << j["machine"];
  } else {
    EXPECT_EQ(r.output.find(skipped, skip_line + 1), std::string::npos) << "more than one skip line:\n" << r.output;
    EXPECT_GT(r.output.find('\n', skip_line), skip_line + skipped.size()) << "no reason given";
    EXPECT_FALSE(j["cells"][0].contains("ray_query"));
    EXPECT_FALSE(j["cells"][0]["ratios"]["mobirt"].contains("fps_over_ray_query"));
  }
  // The compute peer needs only a compute queue: it runs wherever mobirt's Vulkan backend does.
  EXPECT_EQ(r.output.find("bench: compute peer skipped: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(" fps, compute "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("compute (Vulkan)"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("fps/cp"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("mobirt's kd-tree as a compute pass, per stage"), std::string::npos) << r.output;
  ASSERT_TRUE(j["machine"]["compute"].is_array()) << j["machine"];
  EXPECT_NE(j["machine"]["compute"].dump().find("is a compute shader"), std::string::npos) << j["machine"]["compute"];
  for (const nlohmann::json& c : j["cells"]) {
    SCOPED_TRACE(c["level"].get<std::string>());
    EXPECT_EQ(c["triangles"].get<int>(), 1392);
    EXPECT_EQ(c["primary"], "trace");
    std::vector<std::string> columns = {"mobirt", "mobirt_gles", "embree", "cpu_kd", "compute"};
    if (ray_query) columns.push_back("ray_query");
    for (const std::string& column : columns) {
      SCOPED_TRACE(column);
      const nlohmann::json& fps = c[column]["fps"];
      EXPECT_GT(fps["median"].get<double>(), 0.0);
      EXPECT_LE(fps["min"].get<double>(), fps["median"].get<double>());
      EXPECT_GE(fps["max"].get<double>(), fps["median"].get<double>());
      const nlohmann::json& s = c[column]["stages_ms"];
      EXPECT_GT(s["build"].get<double>(), 0.0);
      EXPECT_GT(s["trace"].get<double>(), 0.0);
      EXPECT_GT(s["trace_mrays"].get<double>(), 0.0);
      EXPECT_GT(s["shadow_rays"].get<double>(), 0.0);  // both levels cast shadow rays
      // The process's CPU time in the frame: some, and no more than the cores could give in the
      // frame's wall time (a median of values each below that bound is below it too; the slack
      // covers what runs between the clocks, and the other threads' counts, which Linux brings up
      // to date only at a scheduler tick, for frames of a millisecond or two).
      const double cores = std::max(1.0, j["machine"]["cores"].get<double>());
      EXPECT_GT(s["cpu"].get<double>(), 0.0);
      EXPECT_LE(s["cpu"].get<double>(), 1.25 * s["frame"].get<double>() * cores + 5.0);
    }
    for (const char* column : {"mobirt", "mobirt_gles"}) {
      SCOPED_TRACE(column);
      const nlohmann::json& gpu = c[column]["stages_ms"];
      // The paper's bandwidth model: 4 bytes per ray and pass (8-bit colour), every traced ray from
      // the traversal pass, the shaded ones (the hits and one miss) from the shading pass. Checked
      // on the primary generation, whose ray count is fixed, so that the medians over frames of
      // bytes and of shaded rays are in the same relation as each frame's.
      EXPECT_EQ(gpu["pass0_bytes_read"].get<double>(),
                4.0 * (gpu["pass0_rays"].get<double>() + gpu["pass0_shaded_rays"].get<double>()));
      EXPECT_GT(gpu["shaded_rays"].get<double>(), 0.0);
      // The frame's CPU time holds the rendering thread's own (each frame's does, so the medians do).
      EXPECT_GE(gpu["cpu"].get<double>(), gpu["render_cpu"].get<double>());
      EXPECT_LE(gpu["shaded_rays"].get<double>(), gpu["traced_rays"].get<double>());
      EXPECT_EQ(gpu["pass0_rays"].get<double>(), 64.0 * 40.0);
      EXPECT_GT(c["ratios"][column]["traversal_over_embree"].get<double>(), 0.0);
      EXPECT_GT(c["ratios"][column]["build_over_embree"].get<double>(), 0.0);
      EXPECT_DOUBLE_EQ(c["ratios"][column]["cpu_over_embree"].get<double>(),
                       gpu["cpu"].get<double>() / c["embree"]["stages_ms"]["cpu"].get<double>());
      if (ray_query) {
        EXPECT_GT(c["ratios"][column]["fps_over_ray_query"].get<double>(), 0.0);
        EXPECT_GT(c["ratios"][column]["traversal_over_ray_query"].get<double>(), 0.0);
      }
      EXPECT_GT(c["ratios"][column]["fps_over_compute"].get<double>(), 0.0);
      EXPECT_GT(c["ratios"][column]["traversal_over_compute"].get<double>(), 0.0);
      // The serial twin: the same frames again, serially (the same ray tree: shadow rays and the
      // bounces' rays depend on the pose and the tree); its traversal passes' Mrays/s over each
      // peer's, its build over Embree's and the pipelined fps over its fps are the quotients of
      // the medians.
      ASSERT_TRUE(c[column].contains("serial"));
      const nlohmann::json& twin = c[column]["serial"];
      const nlohmann::json& ratios = c["ratios"][column];
      ASSERT_TRUE(ratios.contains("serial_traversal_over_embree")) << ratios;
      ASSERT_TRUE(ratios.contains("serial_traversal_over_compute")) << ratios;
      for (const char* count : {"traced_rays", "shadow_rays", "shaded_rays", "bytes_read"}) {
        EXPECT_EQ(twin["stages_ms"][count], gpu[count]) << count;
      }
      EXPECT_FALSE(twin["pipelined"].get<bool>());
      EXPECT_GT(twin["stages_ms"]["trace_mrays"].get<double>(), 0.0);
      EXPECT_DOUBLE_EQ(ratios["serial_build_over_embree"].get<double>(),
                       twin["stages_ms"]["build"].get<double>() / c["embree"]["stages_ms"]["build"].get<double>());
      EXPECT_DOUBLE_EQ(ratios["serial_traversal_over_embree"].get<double>(),
                       twin["stages_ms"]["trace_mrays"].get<double>() / c["embree"]["stages_ms"]["trace_mrays"].get<double>());
      EXPECT_DOUBLE_EQ(ratios["serial_traversal_over_compute"].get<double>(),
                       twin["stages_ms"]["trace_mrays"].get<double>() / c["compute"]["stages_ms"]["trace_mrays"].get<double>());
      if (ray_query) {
        ASSERT_TRUE(ratios.contains("serial_traversal_over_ray_query")) << ratios;
        EXPECT_DOUBLE_EQ(ratios["serial_traversal_over_ray_query"].get<double>(),
                         twin["stages_ms"]["trace_mrays"].get<double>() /
                             c["ray_query"]["stages_ms"]["trace_mrays"].get<double>());
      }
      EXPECT_DOUBLE_EQ(twin["pipelined_fps_over_serial"].get<double>(),
                       c[column]["fps"]["median"].get<double>() / twin["fps"]["median"].get<double>());
    }
    // The compute peer traces mobirt's rays with mobirt's tree: a wide record per ray from its
    // traversal pass, 4 bytes per ray from the shading pass.
    const nlohmann::json& cp = c["compute"]["stages_ms"];
    EXPECT_EQ(cp["pass0_bytes_read"].get<double>(),
              MOBIRT_HIT_RECORD_BYTES * cp["pass0_rays"].get<double>() + 4.0 * cp["pass0_shaded_rays"].get<double>());
    EXPECT_EQ(cp["pass0_rays"].get<double>(), 64.0 * 40.0);
    EXPECT_NEAR(cp["traced_rays"].get<double>(), c["mobirt"]["stages_ms"]["traced_rays"].get<double>(),
                0.01 * c["mobirt"]["stages_ms"]["traced_rays"].get<double>());
    if (ray_query) {
      // The peer traces the same rays as mobirt's passes and reads back as much.
      const nlohmann::json& rq = c["ray_query"]["stages_ms"];
      EXPECT_EQ(rq["pass0_bytes_read"].get<double>(),
                4.0 * (rq["pass0_rays"].get<double>() + rq["pass0_shaded_rays"].get<double>()));
      EXPECT_EQ(rq["pass0_rays"].get<double>(), 64.0 * 40.0);
      EXPECT_NEAR(rq["traced_rays"].get<double>(), c["mobirt"]["stages_ms"]["traced_rays"].get<double>(),
                  0.01 * c["mobirt"]["stages_ms"]["traced_rays"].get<double>());
    }
    // The same primary rays in every column; the bounces give the fish's glass more rays.
    EXPECT_EQ(c["embree"]["stages_ms"]["traced_rays"].get<double>() >= 64.0 * 40.0, true);
    EXPECT_GT(c["kd_tree"]["sah_cost"].get<double>(), 0.0);
  }
  const nlohmann::json& bounce = j["cells"][1];
  EXPECT_GT(bounce["mobirt"]["stages_ms"]["traced_rays"].get<double>(), 64.0 * 40.0);
  // Vulkan, GLES and Embree trace the same ray tree (up to hits that differ on shared edges).
  EXPECT_EQ(bounce["mobirt_gles"]["stages_ms"]["traced_rays"], bounce["mobirt"]["stages_ms"]["traced_rays"]);
  EXPECT_NEAR(bounce["embree"]["stages_ms"]["traced_rays"].get<double>(),
              bounce["mobirt"]["stages_ms"]["traced_rays"].get<double>(),
              0.01 * bounce["mobirt"]["stages_ms"]["traced_rays"].get<double>());
  EXPECT_TRUE(bounce["paper_fps"].is_null());  // a scene given on the command line: no paper figure

  // The targets (issues 16 and 15): each counted again from the cells' ratios, with its range and
  // its one scene's range, and printed with the same count.
  EXPECT_NE(r.output.find("Targets (issues 15 and 16)"), std::string::npos) << r.output;
  ASSERT_TRUE(j["targets"].is_array());
  std::set<std::string> seen;
  for (const nlohmann::json& t : j["targets"]) {
    const std::string label = t["target"].get<std::string>();
    SCOPED_TRACE(label);
    const std::string column = t["column"].get<std::string>();
    const std::string ratio = t["ratio"].get<std::string>();
    const double at_least = t["at_least"].get<double>();
    size_t cells = 0, met = 0;
    double lo = 1e300, hi = -1e300;
    for (const nlohmann::json& c : j["cells"]) {
      if (!c["ratios"].contains(column) || !c["ratios"][column].contains(ratio)) continue;
      const double v = c["ratios"][column][ratio].get<double>();
      ++cells;
      met += v >= at_least ? 1 : 0;
      lo = std::min(lo, v);
      hi = std::max(hi, v);
    }
    EXPECT_EQ(t["cells"].get<size_t>(), cells);
    EXPECT_EQ(t["met"].get<size_t>(), met);
    EXPECT_DOUBLE_EQ(t["min"].get<double>(), lo);
    EXPECT_DOUBLE_EQ(t["max"].get<double>(), hi);
    ASSERT_EQ(t["scenes"].size(), 1u);
    EXPECT_EQ(t["scenes"][0]["scene"], "fish");
    EXPECT_DOUBLE_EQ(t["scenes"][0]["min"].get<double>(), lo);
    EXPECT_DOUBLE_EQ(t["scenes"][0]["max"].get<double>(), hi);
    const std::string printed = label + ": " + std::to_string(met) + " of " + std::to_string(cells) + " cells (";
    EXPECT_NE(r.output.find(printed), std::string::npos) << printed << "\n" << r.output;
    seen.insert(column + "." + ratio);
  }
  for (const char* key : {"mobirt.fps_over_embree", "mobirt_gles.fps_over_embree", "mobirt.traversal_over_embree",
                          "mobirt.serial_traversal_over_embree"}) {
    EXPECT_EQ(seen.count(key), 1u) << key;
  }
  EXPECT_EQ(seen.count("mobirt.fps_over_ray_query") == 1, ray_query);
}

// A cell whose primaries are rasterized and whose shadow rays test light buffers (what --primary
// auto and --shadow-cells auto make of the default bench's shadow cells): no kd-tree is built, so no
// build ratio is given; the light buffers' build is the build stage. With --shadow-cells 0 the
// shadow rays walk: the tree is built every frame and the ratio given.
TEST(Bench, RasterizedPrimariesWithShadows) {
  const fs::path json = test::temp_dir() / "bench.json";
  const test::CommandResult r =
      test::run_mobirt("bench " MOBIRT_SOURCE_DIR "/scenes/fish.gltf --size 120x72 --frames 2 --warmup 1 "
                       "--levels shadow --backend vulkan --no-cpu --no-serial-twin --json '" + json.string() + "'");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("bench: [1/1] fish, + shadow (primary raster): Vulkan "), std::string::npos) << r.output;
  std::ifstream in(json);
  const nlohmann::json j = nlohmann::json::parse(in);
  ASSERT_EQ(j["cells"].size(), 1u);
  const nlohmann::json& c = j["cells"][0];
  EXPECT_EQ(c["primary"], "raster");
  EXPECT_FALSE(c["kd_tree_built"].get<bool>());
  EXPECT_GT(c["mobirt"]["stages_ms"]["build"].get<double>(), 0.0);
  EXPECT_TRUE(c["ratios"]["mobirt"]["build_over_embree"].is_null());
  EXPECT_GT(c["ratios"]["mobirt"]["fps_over_embree"].get<double>(), 0.0);
  EXPECT_EQ(j["settings"]["primary"], "auto");

  const fs::path walk_json = test::temp_dir() / "bench-walk.json";
  const test::CommandResult walk = test::run_mobirt(
      "bench " MOBIRT_SOURCE_DIR "/scenes/fish.gltf --size 120x72 --frames 2 --warmup 1 --levels shadow "
      "--backend vulkan --no-cpu --no-serial-twin --shadow-cells 0 --json '" +
      walk_json.string() + "'");
  ASSERT_EQ(walk.exit_code, 0) << walk.output;
  std::ifstream walk_in(walk_json);
  const nlohmann::json walked = nlohmann::json::parse(walk_in);
  const nlohmann::json& sc = walked["cells"][0];
  EXPECT_EQ(sc["primary"], "raster") << "0.16 triangles a pixel";
  EXPECT_TRUE(sc["kd_tree_built"].get<bool>());
  EXPECT_GT(sc["ratios"]["mobirt"]["build_over_embree"].get<double>(), 0.0);
}

// --no-baseline leaves out every peer, the ray query and the compute pass included, and says
// nothing about it.
TEST(Bench, NoBaselineSkipsEveryPeer) {
  const fs::path json = test::temp_dir() / "bench.json";
  const test::CommandResult r =
      test::run_mobirt("bench " MOBIRT_SOURCE_DIR "/scenes/fish.gltf --size 32x20 --frames 1 --warmup 0 "
                       "--levels cast --backend vulkan --no-baseline --json '" + json.string() + "'");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find("ray-query peer skipped"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("compute peer skipped"), std::string::npos) << r.output;
  std::ifstream in(json);
  const nlohmann::json j = nlohmann::json::parse(in);
  ASSERT_EQ(j["cells"].size(), 1u);
  const nlohmann::json& c = j["cells"][0];
  EXPECT_GT(c["mobirt"]["fps"]["median"].get<double>(), 0.0);
  for (const char* peer : {"embree", "cpu_kd", "ray_query", "compute", "ratios"}) EXPECT_FALSE(c.contains(peer)) << peer;
  // No peer, no ratio: no target is counted or printed.
  EXPECT_TRUE(j["targets"].empty()) << j["targets"];
  EXPECT_EQ(r.output.find("Targets (issues"), std::string::npos) << r.output;
  EXPECT_EQ(j["machine"]["compute"]["skipped"], "--no-baseline");
  EXPECT_EQ(j["settings"]["compute_data"], "storage-buffers");
  // The tree's settings, so that a run with the build's knobs says which (the defaults here).
  EXPECT_EQ(j["settings"]["build"], "fast");
  EXPECT_EQ(j["settings"]["leaf_size"].get<int>(), 3);
  EXPECT_EQ(j["settings"]["cluster_refs"].get<int>(), 6);
  EXPECT_EQ(j["settings"]["empty_bonus"].get<double>(), 0.5);
  // The per-frame walks trees' bonus (kd_empty_bonus), a float's 0.2.
  EXPECT_NEAR(j["settings"]["walks_empty_bonus"].get<double>(), 0.2, 1e-6);
}

// mobirt's frames are pipelined unless --serial, and the table and the JSON say which; pipelined,
// the next frame was prepared on the worker during each frame but the last, and each frame was
// rendered a second time serially unless --no-serial-twin.
// Ray casting at 32x20 rasterizes the primaries (--primary auto: no tree to rebuild every frame)
// and builds no tree; with --primary trace the worker builds one each frame.
TEST(Bench, SaysWhetherItsFramesArePipelined) {
  for (const std::string mode : {"", " --serial", " --no-serial-twin", " --primary trace", " --serial --primary trace"}) {
    SCOPED_TRACE(mode.empty() ? "pipelined" : mode);
    const bool serial = mode.find(" --serial") != std::string::npos;
    const bool twin_expected = mode.empty() || mode == " --primary trace";
    const bool traced = mode.find("--primary trace") != std::string::npos;
    const fs::path json = test::temp_dir() / "bench.json";
    const test::CommandResult r = test::run_mobirt(
        "bench " MOBIRT_SOURCE_DIR "/scenes/fish.gltf --size 32x20 --frames 3 --warmup 0 --levels cast "
        "--backend vulkan --no-baseline --build-threads 1 --json '" + json.string() + "'" + mode);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_NE(r.output.find(serial ? "mobirt's frames serial (--serial)" : "mobirt's frames pipelined"), std::string::npos)
        << r.output;
    EXPECT_NE(r.output.find(serial ? "mobirt's frame loop, serial" : "mobirt's frame loop, pipelined"), std::string::npos)
        << r.output;
    std::ifstream in(json);
    const nlohmann::json j = nlohmann::json::parse(in);
    EXPECT_EQ(j["settings"]["pipelined"].get<bool>(), !serial);
    EXPECT_EQ(j["settings"]["serial_twin"].get<bool>(), twin_expected);
    EXPECT_EQ(j["settings"]["build_threads"].get<int>(), 1);
    const nlohmann::json& mobirt = j["cells"][0]["mobirt"];
    EXPECT_EQ(mobirt["pipelined"].get<bool>(), !serial);
    EXPECT_EQ(j["cells"][0]["primary"], traced ? "trace" : "raster");
    EXPECT_EQ(j["cells"][0]["kd_tree_built"].get<bool>(), traced);
    const nlohmann::json& s = mobirt["stages_ms"];
    // The serial twin, and the output's table of it; serial, the column is that loop already.
    EXPECT_EQ(r.output.find("mobirt's frames again, serial") != std::string::npos, twin_expected) << r.output;
    ASSERT_EQ(mobirt.contains("serial"), twin_expected);
    if (twin_expected) {
      // The same frames (the hits, and so the shaded rays and the bytes read back, depend on the
      // pose; OneSmallCellWithEveryColumn compares shadow rays and bounces), a serial loop's stages.
      const nlohmann::json& twin = mobirt["serial"]["stages_ms"];
      for (const char* count : {"traced_rays", "shaded_rays", "bytes_read"}) EXPECT_EQ(twin[count], s[count]) << count;
      EXPECT_EQ(twin["pass0_rays"].get<double>(), 32.0 * 20.0);
      EXPECT_EQ(twin["ahead"].get<double>(), 0.0);
      EXPECT_GT(twin["build"].get<double>(), 0.0);
      EXPECT_GE(twin["frame"].get<double>(), twin["build"].get<double>());  // pose, build and passes
    }
    EXPECT_GT(s["build"].get<double>(), 0.0);
    EXPECT_GE(s["render"].get<double>(), s["render_cpu"].get<double>() * 0.999);  // one thread's CPU time
    if (serial) {
      EXPECT_EQ(s["ahead"].get<double>(), 0.0);
      EXPECT_EQ(s["build_wait"].get<double>(), 0.0);
    } else {
      EXPECT_GT(s["ahead"].get<double>(), 0.0);
    }
  }
}

TEST(Bench, BadOptionsAreRefusedBeforeTheRun) {
  const fs::path dir = test::temp_dir();
  for (const std::string& args :
       {std::string("--levels cast,bogus"), std::string("--frames 0"), std::string("--compute-data textures"),
        "--json '" + (dir / "no-such-folder" / "b.json").string() + "'",
        std::string("--scenes '") + (dir / "empty").string() + "'"}) {
    SCOPED_TRACE(args);
    const test::CommandResult r = test::run_mobirt("bench " + args);
    EXPECT_EQ(r.exit_code, 2) << r.output;
    EXPECT_NE(r.output.find("mobirt: error: "), std::string::npos) << r.output;
  }
  EXPECT_FALSE(fs::exists(dir / "no-such-folder"));
}

}  // namespace
}  // namespace mobirt
