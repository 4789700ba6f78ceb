// Atlas packing (scene/atlas.h):
// PackTiles/<n>: the shelf packer alone on n tiles of mixed sizes (fixed list, non-square ones).
// AssembleAtlas/<n>: pack and copy n decoded tiles into 2048x2048 atlas pages (no file decoding).
// BuildAtlas/<scene>: the whole per-scene step from the texture files: decode, downscale, pack.
#include <benchmark/benchmark.h>

#include <string>
#include <vector>

#include "bench_meshes.h"
#include "benchmarks.h"
#include "scene/atlas.h"

namespace mobirt::bench {

namespace {

// Up to 16 tile sizes, at most 512 on a side, the non-square ones of real texture sets among them.
std::vector<glm::ivec2> tile_sizes(int count) {
  static const glm::ivec2 kSizes[] = {{512, 512}, {256, 256}, {512, 256}, {128, 512}, {64, 64},
                                      {300, 200}, {512, 512}, {32, 480},  {256, 128}, {200, 300},
                                      {512, 64},  {96, 96},   {384, 384}, {128, 128}, {16, 16},
                                      {256, 512}};
  return std::vector<glm::ivec2>(std::begin(kSizes), std::begin(kSizes) + count);
}

void tile_packing(benchmark::State& state) {
  const std::vector<glm::ivec2> sizes = tile_sizes(int(state.range(0)));
  for (auto _ : state) {
    std::vector<AtlasTile> tiles = pack_tiles(sizes);
    benchmark::DoNotOptimize(tiles.data());
  }
}

void atlas_assembly(benchmark::State& state) {
  std::vector<AtlasTexture> textures;
  uint32_t value = 1;
  for (const glm::ivec2& size : tile_sizes(int(state.range(0)))) {
    AtlasTexture t;
    t.image.width = size.x;
    t.image.height = size.y;
    t.image.pixels.resize(size_t(size.x) * size_t(size.y));
    for (uint32_t& p : t.image.pixels) p = (value = value * 1664525u + 1013904223u);
    textures.push_back(std::move(t));
  }
  for (auto _ : state) {
    Atlas atlas = assemble_atlas(textures);
    benchmark::DoNotOptimize(atlas.pages.data());
  }
}

void atlas_from_files(benchmark::State& state, std::string name) {
  const Scene& scene = project_scene_loaded(name);
  for (auto _ : state) {
    Atlas atlas = build_atlas(scene);
    benchmark::DoNotOptimize(atlas.pages.data());
  }
  state.counters["textures"] = double(scene.textures.size());
}

}  // namespace

void register_atlas_benchmarks() {
  benchmark::RegisterBenchmark("PackTiles", tile_packing)->Arg(4)->Arg(16)->ArgName("tiles");
  benchmark::RegisterBenchmark("AssembleAtlas", atlas_assembly)
      ->Arg(4)
      ->Arg(16)
      ->ArgName("tiles")
      ->Unit(benchmark::kMillisecond);
  for (const char* name : {"fish", "marbles", "toaster"}) {
    benchmark::RegisterBenchmark(("BuildAtlas/" + std::string(name)).c_str(), atlas_from_files, std::string(name))
        ->Unit(benchmark::kMillisecond);
  }
}

}  // namespace mobirt::bench
