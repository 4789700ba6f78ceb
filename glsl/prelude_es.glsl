// GLSL ES 1.00 (OpenGL ES 2.0) dialect of mobirt's shaders: the same names as prelude_vk.glsl.
// Every .frag for GLES is
//   #version 100
//   #include "prelude_es.glsl"
// followed by the shared bodies; the build expands the includes (GLSL ES 1.00 has no #include)
// and the GLES backend inserts the scene's #defines right after the #version line.
#include "layout.h"

precision highp float;
precision highp int;
precision highp sampler2D;

// Scene specialisation: #defines set by the backend (Vulkan: specialization constants). The
// defaults are the Vulkan ones.
#ifndef LIGHT_COUNT
#define LIGHT_COUNT 0
#endif
#ifndef STACK_DEPTH
#define STACK_DEPTH 6
#endif
#ifndef MAX_STEPS
#define MAX_STEPS 4096
#endif
// A loop that only its body ends: GLSL ES 1.00 (Appendix A) allows for loops with a constant
// bound only, so it keeps an index, bounded by `limit` (the cap, or one more).
#define UNBOUNDED_LOOP(i, limit) for (int i = 0; i < limit; ++i)
// traverse()'s short stack with a count of its entries (see there).
#define STACK_COUNTED 1
// traverse() keeps a flag of its own for a leaf to close (see there).
#define LEAF_CLOSE_IN_NODE 0
// GLSL ES 1.00 has no control-flow attributes (see prelude_vk.glsl). What keeps an `if` a branch
// here is its size: KEEP_BRANCH_PAD(x) returns x through enough ALU instructions
// (es_keep_branch_pad below).
#define KEEP_BRANCH
#define KEEP_BRANCH_PAD(x) es_keep_branch_pad(x)
#ifndef PACKING
#define PACKING MOBIRT_PACKING_24_8
#endif
#ifndef TEXTURE_COUNT
#define TEXTURE_COUNT 0
#endif
#ifndef INTERSECT
#define INTERSECT MOBIRT_INTERSECT_MT
#endif
#ifndef PRECISION
#define PRECISION MOBIRT_PRECISION_HIGH
#endif
#ifndef OFFSET_MODE
#define OFFSET_MODE MOBIRT_OFFSET_SCALED
#endif
#ifndef COLOUR
#define COLOUR MOBIRT_COLOUR_8
#endif
#ifndef ATLAS_PAGES
#define ATLAS_PAGES 0
#endif
#ifndef ANALYTIC
#define ANALYTIC 0
#endif
// Vulkan's buffers only (prelude_vk.glsl's data_index); the data textures here index by 2D
// coordinates, exact up to 2^24 either way.
#ifndef WIDE_INDICES
#define WIDE_INDICES 0
#endif
// --primary raster (layout.h, MOBIRT_SPEC_PRIMARY_HITS).
#ifndef PRIMARY_HITS
#define PRIMARY_HITS 0
#endif
// --shadow-cells (layout.h, MOBIRT_SPEC_LIGHT_BUFFERS).
#ifndef LIGHT_BUFFERS
#define LIGHT_BUFFERS 0
#endif

#define PRECISE
#include "precision.glsl"

// The numeric primitive of prelude_vk.glsl that GLSL ES 1.00 lacks (no floatBitsToInt, no bit
// operations), emulated with float arithmetic that is exact as long as exp2 of an integer is
// exact (it is on llvmpipe; tests/numerics_test.cpp checks it against the CPU on both backends,
// bit for bit).
// The float whose bits, read as a signed integer, are x's plus k (an integer value): x moved by k
// units in the last place, away from zero for k > 0, across a power of two where the ulp doubles
// (or halves). Exact for normal x and |k| < 2^23; Wachter and Binder's offset (offset.glsl) calls it
// only for |x| >= 1/32, traverse()'s kd-restart with k = 1 for a restart point tmax > 0. Below
// x = 2^-103 its ulp, exp2(e - 23), is subnormal: where subnormals flush, the result is <= x (NaN
// below 2^-126), so splits up to that tmax are walked on both sides: no hit is lost, but the walk
// may leave the CPU's steps or run to the cap (the CPU then traces the ray). No ray reaches such
// a restart point in practice.
float add_float_bits(float x, float k) {
  float m = abs(x);
  float e = float_binade(m);
  float low = exp2(e);
  float ulp = exp2(e - 23.0);
  float steps = (m - low) * exp2(23.0 - e) + k;  // ulps above 2^e after the move
  float r = low + steps * ulp;
  if (steps >= 8388608.0) {
    r = 2.0 * low + (steps - 8388608.0) * 2.0 * ulp;
  } else if (steps < 0.0) {
    r = low + steps * 0.5 * ulp;
  }
  return x < 0.0 ? -r : r;
}

// x itself, for x >= -3e38 and not NaN, through 9 max() with distinct constants below it: what
// KEEP_BRANCH_PAD is on ES. Mesa's GL front end turns an `if` into selects when its body has at
// most 8 counted ALU instructions (nir_opt_peephole_select(nir, 8, ...) in gl_nir_opts; moves and
// vec2/3/4 do not count), and these 9 count. One assignment each: as one nested expression the
// GLSL compiler's min/max pass prunes all but one, and equal constants NIR folds. Measured on
// Mesa 25.0.7 with traverse()'s push, whose other instructions count 1: 7 max() left it selects
// (toaster, GLES, 200x120, depth 2: 144.57M JIT instructions a frame against 137.19M without
// them), 8 made it a branch (132.12M), 9 keep one in reserve (132.30M). Another Mesa may flatten
// it again: the same image, only slower.
float es_keep_branch_pad(float x) {
  float y = x;
  y = max(y, -3.0e38);
  y = max(y, -3.1e38);
  y = max(y, -3.2e38);
  y = max(y, -3.3e38);
  y = max(y, -3.35e38);
  y = max(y, -3.36e38);
  y = max(y, -3.37e38);
  y = max(y, -3.38e38);
  y = max(y, -3.39e38);
  return y;
}

// The pass's uniforms: one vec4 array (indices in layout.h).
uniform vec4 u_params[MOBIRT_MAX_PARAM_VEC4S];
#define PARAM(i) u_params[i]

// Every sampler comes with the inverse of its texture's size (set by the backend from the bound
// texture), because texture2D takes normalised coordinates: texel (x, y) is read at its centre
// ((x + 0.5) / W, (y + 0.5) / H), with NEAREST filtering. The binding slot becomes a texture unit
// by glUniform1i after linking (the backend parses the slot from the SAMPLER line).
struct MobirtSampler {
  sampler2D tex;
  vec2 inv_size;
};
#define SAMPLER(slot, name) uniform MobirtSampler name

// Data textures: element i at texel (i mod W, i div W). Indices arrive as exact floats below
// 2^24 and W is a power of two, so i / W is exact, its floor is the row and its fraction the
// column / W, and adding 0.5 / W gives the column's centre exactly: one multiply and one floor a
// fetch (mod, a second floor and a division before: same coordinates, more JIT code).
#define DATA_TEXEL(s, index) DATA_TEXEL_ROWS(s, DATA_ROWS(s), index)
vec4 mobirt_data_texel(sampler2D tex, float row_and_fraction, float inv_rows) {
  float row = floor(row_and_fraction);
  return texture2D(tex, vec2((row_and_fraction - row) + 0.5 / float(MOBIRT_DATA_WIDTH), (row + 0.5) * inv_rows));
}
// The fetch in a loop: the texture's inverse row count read once before it (DATA_ROWS), then
// DATA_TEXEL_ROWS(s, rows, index) in the loop. llvmpipe reads a uniform at every use (a scalar load
// behind a bounds check, then a broadcast) and nothing moves it out of a loop; read once, it is a
// value of the loop's own: traverse()'s loops 1.45 % fewer JIT instructions on the fish's GLES
// frame at 2 bounces, 1.1 % on the toaster's (docs/performance-history.md, *Session 50*).
#define DATA_ROWS(s) ((s).inv_size.y)
#define DATA_TEXEL_ROWS(s, rows, index) mobirt_data_texel((s).tex, (index) * (1.0 / float(MOBIRT_DATA_WIDTH)), rows)
// Per-ray textures share the pass's layout: this fragment's own ray. gl_FragCoord.xy is already
// the texel centre (x + 0.5, y + 0.5); window row 0 is texture row 0 and glReadPixels' first row.
#define RAY_TEXEL(s) texture2D((s).tex, gl_FragCoord.xy * (s).inv_size)
// Texture atlas page (RGBA8, NEAREST): the texel at integer coordinates xy (exact floats). No
// ATLAS_FILTERED: without GL_EXT_sRGB (Mesa offers none to ES 2.0) a LINEAR fetch would blend the
// sRGB-encoded values, so atlas.glsl blends 4 decoded texels itself.
#define ATLAS_TEXEL(s, xy) texture2D((s).tex, ((xy) + 0.5) * (s).inv_size)

#define OUTPUT(value) gl_FragColor = (value)
