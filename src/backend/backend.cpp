#include "backend/backend.h"

#include "core/error.h"

namespace mobirt {

size_t texel_bytes(TexelFormat format) {
  switch (format) {
    case TexelFormat::RGBA32F: return 16;
    case TexelFormat::R32F: return 4;
    case TexelFormat::RGBA8: return 4;
  }
  throw Error(ErrorKind::Internal, "texel_bytes: unknown texel format " + std::to_string(int(format)));
}

const char* shader_name(ShaderId id) {
  switch (id) {
    case ShaderId::Traverse: return "trace.frag";
    case ShaderId::Shade: return "shade.frag";
    case ShaderId::TestTwoOutputs: return "test/two_outputs.frag";
    case ShaderId::TestStorageWrite: return "test/storage_write.frag";
    case ShaderId::TestNineTextures: return "test/nine_textures.frag";
    case ShaderId::TestCopyInput: return "test/copy_input.frag";
    case ShaderId::TestSpin: return "test/spin.frag";
    case ShaderId::TestAtlasLookup: return "test/atlas_lookup.frag";
  }
  return "unknown shader";
}

}  // namespace mobirt
