// libFuzzer target for scene loading: bytes -> a scene file on disk -> load_animated_scene ->
// evaluate at two times -> build_kdtree, plus decoding of the embedded textures. Expected errors
// (mobirt::Error) are fine; anything else (a crash, an ASan/UBSan report, a leak, a timeout, any
// other exception) is a finding. Built by tools/fuzz.sh (CMake option MOBIRT_FUZZ, clang).
//
// Input layout: byte 0 picks the format, the rest up to the first NUL byte is the scene file, and
// what follows that NUL (if any) is a companion file beside it:
//   byte0 % 6 == 0: scene.gltf   + companion b.bin (a buffer the glTF may name by "uri": "b.bin")
//   byte0 % 6 == 1: scene.glb    (the whole rest, NULs included, is the .glb; no companion)
//   byte0 % 6 == 2: scene.obj    + companion m.mtl (found when the OBJ says "mtllib m.mtl")
//   byte0 % 6 == 3: scene.obj    + companion m.mtl passed as LoadOptions::mtl (always parsed)
//   byte0 % 6 == 4: scene.nff    (the whole rest; no companion)
//   byte0 % 6 == 5: scene.ply    (the whole rest, NULs included: binary PLY; no companion)
// The ASCII digits '0' to '5' pick formats 0 to 5.
// tests/fuzz/regressions/ replays files of this layout (tests/reliability_test.cpp), so the same
// function is compiled there without libFuzzer: see scene_fuzz_one.h.
#include <cstddef>
#include <cstdint>

#include "scene_fuzz_one.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  mobirt::fuzz::run_one(data, size);
  return 0;
}
