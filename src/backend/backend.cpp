#include "backend/backend.h"

#include "core/error.h"
#include "layout.h"

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
    case ShaderId::TestNumerics: return "test/numerics.frag";
  }
  return "unknown shader";
}

void check_run_pass_arguments(const PassDesc& desc, size_t textures, size_t uniform_floats, uint32_t width,
                              uint32_t count, size_t out_texels) {
  const std::string name = shader_name(desc.shader);
  if (textures != desc.texture_bindings.size()) {
    throw Error(ErrorKind::Internal, "pass " + name + " takes " + std::to_string(desc.texture_bindings.size()) +
                                         " textures, got " + std::to_string(textures));
  }
  if (uniform_floats > size_t(MOBIRT_MAX_PARAM_VEC4S) * 4 || uniform_floats > size_t(desc.uniform_vec4s) * 4) {
    throw Error(ErrorKind::Internal, "pass " + name + ": " + std::to_string(uniform_floats) +
                                         " uniform floats, more than the pass's " +
                                         std::to_string(desc.uniform_vec4s) + " vec4");
  }
  if (width == 0) throw Error(ErrorKind::Internal, "pass " + name + ": width 0");
  if (out_texels < count) {
    throw Error(ErrorKind::Internal, "pass " + name + ": output holds " + std::to_string(out_texels) +
                                         " texels, the pass writes " + std::to_string(count));
  }
}

}  // namespace mobirt
