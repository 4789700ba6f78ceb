// Texel layouts, binding slots and limits shared by C++ and GLSL.
//
// One source of truth: the kd-tree flattener, the ray generator and the hit decoder (C++) and the
// traversal and shading shaders (GLSL 450 now, GLSL ES 1.00 later) all include this file. Only
// #defines, so that the same text is valid C++, GLSL 450 and GLSL ES 1.00.
//
// Every integer that reaches a shader through a texture is stored as an exact float value below
// 2^24, because GLSL ES 1.00 has neither integer textures nor bit operations.
#ifndef MOBIRT_LAYOUT_H
#define MOBIRT_LAYOUT_H

// ---- Data textures ---------------------------------------------------------------------------
// Every data array lives in a 2D RGBA32F texture of width MOBIRT_DATA_WIDTH:
// element i sits at texel (i mod W, i div W). 4096 x 4096 texels hold 16.7M elements, enough for
// the triangles of 5.5M primitives, or as many leaf references; the layout is exact in float arithmetic because 4096^2 = 2^24.
#define MOBIRT_DATA_WIDTH_LOG2 12
#define MOBIRT_DATA_WIDTH 4096

// kd-tree node: one RGBA32F texel.
//   interior: r = split position, g = index of the "above" child (the "below" child is the next
//             node), b = split axis (0, 1, 2), a = empty-child flags: MOBIRT_NODE_BELOW_EMPTY
//             (the below child is a leaf without primitives) + MOBIRT_NODE_ABOVE_EMPTY (the above
//             child is); traversal closes such a child without fetching it. 0 = no flags.
//   leaf:     r = its first entry in the leaf-primitive texture (every leaf with primitives, one
//             alike), g = primitive count, b = MOBIRT_NODE_LEAF, a = 0
#define MOBIRT_NODE_LEAF 3.0
#define MOBIRT_NODE_BELOW_EMPTY 1.0
#define MOBIRT_NODE_ABOVE_EMPTY 2.0
// The node texel's components by name (0 = r ... 3 = a); C++ reads and writes them through
// texels.h.
#define MOBIRT_NODE_SPLIT 0        // interior: split position
#define MOBIRT_NODE_ABOVE_CHILD 1  // interior: index of the above child
#define MOBIRT_NODE_AXIS 2         // interior: split axis; leaf: MOBIRT_NODE_LEAF
#define MOBIRT_NODE_EMPTY_FLAGS 3  // interior: empty-child flags; leaf: 0
#define MOBIRT_LEAF_FIRST 0        // leaf: first leaf-primitive entry
#define MOBIRT_LEAF_COUNT 1        // leaf: primitive count

// Triangle texture: three RGBA32F texels per primitive: v0, v1, v2 (xyz; w unused = 0).
#define MOBIRT_TEXELS_PER_TRIANGLE 3
// Leaf-primitive texture: the leaves' primitives in leaf order, MOBIRT_TEXELS_PER_TRIANGLE RGBA32F
// texels per entry: a copy of the primitive's texels in the triangle texture, with the primitive's
// index in the third texel's w (exact float). A triangle test reads its three texels straight
// from the leaf, without a fetch of its index first (a quarter of the test's texture calls, and the
// triangles of a leaf side by side in memory). The triangle texture stays for what starts from a
// primitive index (the shadow rays' hit normal, the compute pass's barycentrics).
#define MOBIRT_LEAF_PRIM_INDEX_TEXEL 2  // the texel of an entry that holds the index ...
#define MOBIRT_LEAF_PRIM_INDEX 3        // ... in this component (unused in every primitive kind)
// Analytic primitives (src/core/shapes.h) take the same three texels in the same array and the
// same index space; the w of the first texel says the kind (0 for a triangle):
//   sphere: [0] xyz = centre, w = MOBIRT_PRIM_SPHERE; [1] x = radius; [2] unused
//   cone (open truncated cone, a cylinder when the radii are equal):
//           [0] xyz = centre of the base circle, w = MOBIRT_PRIM_CONE; [1] xyz = unit axis
//           towards the apex, w = height; [2] x = base radius, y = slope (radius change per unit
//           of height), zw unused
#define MOBIRT_PRIM_KIND 3  // component of a primitive's first texel
#define MOBIRT_PRIM_TRIANGLE 0.0
#define MOBIRT_PRIM_SPHERE 1.0
#define MOBIRT_PRIM_CONE 2.0

// Ray textures (one pair per ray generation, densely packed, ray i at (i mod W, i div W) with W
// the pass width): origin texture (xyz, tmin), direction texture (xyz, tmax).

// ---- Traversal pass output: one RGBA8 texel per ray ------------------------------------------
// Variant 24/8: r,g,b = hit primitive index + 1 in 24 bits (r = low byte; 0 = miss),
//               a = shadow mask, bit i set when light i is visible from the hit point.
// Variant 16/16: r,g = hit primitive index + 1 in 16 bits, b,a = shadow mask of 16 lights.
// A texel with index 0 (miss) and a non-zero mask means "traversal stopped at its iteration cap":
// the CPU traces that ray itself, so a cap can never produce a wrong pixel.
#define MOBIRT_PACKING_24_8 0
#define MOBIRT_PACKING_16_16 1
#define MOBIRT_MAX_PRIMS_24_8 16777215
#define MOBIRT_MAX_LIGHTS_24_8 8
#define MOBIRT_MAX_PRIMS_16_16 65535
#define MOBIRT_MAX_LIGHTS_16_16 16

// ---- Compute pass output (glsl/trace_compute.comp, a peer outside the ES 2.0 constraints) -----
// One wide hit record per ray in a storage buffer, 32 bytes: vec4 (t, u, v, 0), u and v the
// barycentric weights of v1 and v2, then uvec4 (primitive index + 1, 0 = miss; shadow mask, bit i
// = light i visible; shadow rays cast; flags). The CPU makes the surface record from it without
// intersecting the triangle again.
#define MOBIRT_HIT_RECORD_BYTES 32
#define MOBIRT_HIT_CAPPED 1           // the loop cap stopped the ray: the CPU traces it itself
#define MOBIRT_HIT_NO_BARYCENTRICS 2  // the hit's second test missed (rounding): the CPU intersects it
#define MOBIRT_COMPUTE_GROUP_SIZE 64  // invocations per workgroup, one ray each

// ---- Push constants of every Vulkan fragment pass ----------------------------------------------
// int u_ray_width at byte 0 (the pass's width); from byte MOBIRT_PASS_ADDRESSES, 8 bytes per binding
// slot (slot = binding number, 0 .. MOBIRT_PASS_ADDRESS_SLOTS - 1), the device address of each
// binding read as a buffer reference (--data device-addresses, prelude_vk.glsl), else 0.
#define MOBIRT_PASS_ADDRESSES 16
#define MOBIRT_PASS_ADDRESS_SLOTS 9

// ---- Limits mirrored from OpenGL ES 2.0 ------------------------------------------------------
#define MOBIRT_MAX_SAMPLED_TEXTURES 8  // GL_MAX_TEXTURE_IMAGE_UNITS minimum of ES 2.0
#define MOBIRT_MAX_LIGHTS 16

// ---- Shading-pass inputs (written by the CPU hit decoder) ------------------------------------
// hit_position texture: xyz = hit point, w = material index (-1 = miss: background)
// hit_normal texture:   xyz = shading normal (unit, facing the incoming ray), w = shadow mask
#define MOBIRT_HIT_MATERIAL 3     // component of the hit_position texel
#define MOBIRT_HIT_SHADOW_MASK 3  // component of the hit_normal texel
// Material texture: MOBIRT_TEXELS_PER_MATERIAL RGBA32F texels per material, in one row:
//   texel 0: diffuse rgb, texture index (-1 = none)
//   texel 1: specular rgb, shininess
//   texel 2: reflectance, transmittance, index of refraction, ambient factor
#define MOBIRT_TEXELS_PER_MATERIAL 3
// (C++: the structs of texels.h, one per texel kind and per uniform block, checked against these
// sizes.)

// ---- Binding slots (Vulkan: set 0; GLES: texture units) --------------------------------------
// Traversal pass
#define MOBIRT_BIND_TRACE_PARAMS 0    // uniform block
#define MOBIRT_BIND_NODES 1
#define MOBIRT_BIND_LEAF_PRIMS 2
#define MOBIRT_BIND_TRIANGLES 3
#define MOBIRT_BIND_RAY_ORIGIN 4
#define MOBIRT_BIND_RAY_DIRECTION 5
#define MOBIRT_BIND_HIT_RECORDS 6     // compute pass: the hit records it writes
// Shading pass
#define MOBIRT_BIND_SHADE_PARAMS 0    // uniform block
#define MOBIRT_BIND_HIT_POSITION 1
#define MOBIRT_BIND_HIT_NORMAL 2
#define MOBIRT_BIND_MATERIALS 3
#define MOBIRT_BIND_SHADE_RAY_DIRECTION 4
#define MOBIRT_BIND_HIT_TEXCOORD 5    // xy = texture coordinate of the hit, zw = unused
// The shading pass's data textures above: the 8 units of ES 2.0 less these are the atlas pages.
#define MOBIRT_SHADE_DATA_TEXTURES 5
#define MOBIRT_BIND_ATLAS_PAGE_0 6    // RGBA8 atlas pages (only read in scenes with textures; a
#define MOBIRT_BIND_ATLAS_PAGE_1 7    // pass binds all three, a page the scene lacks is never read)
#define MOBIRT_BIND_ATLAS_PAGE_2 8

// ---- Uniforms: one array of vec4 at binding 0 (Vulkan: a std140 uniform block; GLES: a uniform
// vec4 array), at most MOBIRT_MAX_PARAM_VEC4S entries. Index of each entry:
// The least self-intersection offset at a point p, relative to max |p|: 2 ulps of a float (2^-22).
#define MOBIRT_OFFSET_ULPS 2.384185791015625e-07
#define MOBIRT_MAX_PARAM_VEC4S 176  // 1 + 4 x 16 lights + 2 x 48 textures = 161
// Traversal pass
#define MOBIRT_TP_BOUNDS_LO 0      // xyz = scene box min, w = self-intersection offset (absolute:
                                   // epsilon x the scene box's largest side)
#define MOBIRT_TP_BOUNDS_HI 1      // xyz = scene box max, w = unused
#define MOBIRT_TP_LIGHTS 2         // MOBIRT_TP_VEC4S_PER_LIGHT vec4 per light:
                                   //   [0] xyz = position (point, spot) or the direction towards
                                   //       the light (directional), w = light type
                                   //   [1] xyz = spot direction (where it points), w = cos(outer)
#define MOBIRT_TP_VEC4S_PER_LIGHT 2
// Per light, with LIGHT_BUFFERS (--shadow-cells N): x = the node index of its light buffer's first
// cell (src/accel/light_buffer.h), y = cells per face edge, z = 1 where the light has one (point
// and spot lights; 0: its shadow rays walk the tree), w = unused. The node texture then holds,
// past the tree's nodes, per light buffer: 6 texels, each face's window (s0, t0, columns per unit
// of s, rows per unit of t), then 6 N^2 leaf texels, one per cell (first entry, count,
// MOBIRT_NODE_LEAF, 0), whose entries in the leaf-entry texture are MOBIRT_TEXELS_PER_TRIANGLE
// texels each: (near, part, v0.x, v0.y), (v0.z, v1.x, v1.y, v1.z), (v2.x, v2.y, v2.z, 0), near the
// triangle's nearest distance to the light and part the part of the cell its rectangle covers:
// columns x0..x1 and rows y0..y1 of MOBIRT_LIGHT_BUFFER_SUBCELLS per cell edge, as x0 + S y0 +
// S^2 (x1 + S y1) (S = MOBIRT_LIGHT_BUFFER_SUBCELLS; an exact integer in a float). A ray stops at
// the first entry whose near is past its end, and one whose direction falls outside an entry's
// part cannot meet that triangle: both read from the first texel alone (src/accel/light_buffer.h).
#define MOBIRT_TP_LIGHT_BUFFERS (MOBIRT_TP_LIGHTS + MOBIRT_TP_VEC4S_PER_LIGHT * MOBIRT_MAX_LIGHTS)
#define MOBIRT_LIGHT_BUFFER_WINDOWS 6
#define MOBIRT_LIGHT_BUFFER_SUBCELLS 64
// Shading pass
#define MOBIRT_SP_BACKGROUND 0     // rgb = background colour, a = unused
#define MOBIRT_SP_LIGHTS 1         // MOBIRT_SP_VEC4S_PER_LIGHT vec4 per light:
                                   //   [0] xyz = position or direction to the light, w = type
                                   //   [1] rgb = colour * intensity, w = range (0 = unlimited)
                                   //   [2] xyz = spot direction (where it points), w = cos(inner)
                                   //   [3] x = cos(outer), yzw = unused
#define MOBIRT_SP_VEC4S_PER_LIGHT 4
// Texture atlas: after the lights, MOBIRT_SP_VEC4S_PER_TEXTURE vec4 per texture (see atlas.glsl):
//   [0] xy = tile origin in its page's texels (its first texel, inside the gutter), zw = tile size in texels
//   [1] x = wrap s, y = wrap t (MOBIRT_WRAP_*), z = page (0 .. MOBIRT_ATLAS_MAX_PAGES - 1), w = unused
#define MOBIRT_SP_TEXTURES(light_count) (MOBIRT_SP_LIGHTS + MOBIRT_SP_VEC4S_PER_LIGHT * (light_count))
#define MOBIRT_SP_VEC4S_PER_TEXTURE 2
#define MOBIRT_WRAP_REPEAT 0.0
#define MOBIRT_WRAP_MIRRORED_REPEAT 1.0
#define MOBIRT_WRAP_CLAMP 2.0
// Atlas pages of MOBIRT_ATLAS_SIZE^2 texels, the paper's atlas repeated: as many as the units that
// the shading pass's data textures leave, up to MOBIRT_ATLAS_TILES_PER_PAGE tiles each (the
// paper's 16), a tile and its gutter at most a page. Each tile is framed by MOBIRT_ATLAS_GUTTER
// texels a side copied by its wrap mode, for one hardware bilinear fetch (src/scene/atlas.h). Any 16
// tiles up to MOBIRT_ATLAS_SURE_TILE on a side fit one page (4 x (510 + 2) = 2048), so every scene
// within MOBIRT_ATLAS_MAX_TEXTURES packs.
#define MOBIRT_ATLAS_SIZE 2048
#define MOBIRT_ATLAS_MAX_PAGES 3  // MOBIRT_MAX_SAMPLED_TEXTURES - MOBIRT_SHADE_DATA_TEXTURES
#define MOBIRT_ATLAS_TILES_PER_PAGE 16
#define MOBIRT_ATLAS_MAX_TEXTURES 48  // MOBIRT_ATLAS_MAX_PAGES x MOBIRT_ATLAS_TILES_PER_PAGE
#define MOBIRT_ATLAS_GUTTER 1
#define MOBIRT_ATLAS_SURE_TILE 510

// ---- Specialization constants (Vulkan constant_id; #defines on GLES) -------------------------
#define MOBIRT_SPEC_LIGHT_COUNT 0  // lights in the scene, 0..MOBIRT_MAX_LIGHTS
#define MOBIRT_SPEC_STACK_DEPTH 1  // short-stack entries, 0 = pure kd-restart
#define MOBIRT_SPEC_MAX_STEPS 2    // loop cap of the traversal (nodes visited + triangles tested)
#define MOBIRT_SPEC_PACKING 3      // MOBIRT_PACKING_24_8 or MOBIRT_PACKING_16_16
#define MOBIRT_SPEC_TEXTURE_COUNT 4  // shade: textures in the atlas, 0 = no atlas code at all
#define MOBIRT_MAX_STACK_DEPTH 32  // the short stack of traverse.glsl (an #error there ties the two); deeper is refused
#define MOBIRT_SPEC_INTERSECT 5    // trace: MOBIRT_INTERSECT_* (--intersect)
#define MOBIRT_SPEC_PRECISION 6    // trace: MOBIRT_PRECISION_* (--precision)
#define MOBIRT_SPEC_OFFSET 7       // trace: MOBIRT_OFFSET_* (--offset), the shadow-ray origins
#define MOBIRT_SPEC_COLOUR 8       // shade: MOBIRT_COLOUR_* (--colour), what the RGBA8 texel holds
#define MOBIRT_SPEC_ATLAS_PAGES 9  // shade: atlas pages, 0..MOBIRT_ATLAS_MAX_PAGES; code for pages beyond folds away
#define MOBIRT_SPEC_ANALYTIC 10    // trace: 1 = the scene has analytic primitives (spheres, cones),
                                   // 0 = triangles only: no code for the others at all
#define MOBIRT_SPEC_WIDE_INDICES 11  // trace, shade (Vulkan buffers): 1 = the pass binds a buffer of more
                                     // than MOBIRT_NARROW_INDEX_TEXELS texels: data_index() converts up to 2^24
#define MOBIRT_SPEC_PRIMARY_HITS 12  // trace: each ray's closest primitive is known (--primary raster): its
                                     // index + 1 in the ray direction's w (0: none), tested alone; where
                                     // that test misses (an edge), MOBIRT_PRIMARY_HITS_WALK walks the
                                     // tree, MOBIRT_PRIMARY_HITS_PLANE (a frame without a kd-tree) keeps
                                     // the triangle, t from its plane
#define MOBIRT_PRIMARY_HITS_WALK 1
#define MOBIRT_PRIMARY_HITS_PLANE 2
// The direction's w of a ray in a MOBIRT_PRIMARY_HITS_WALK pass whose closest primitive is not
// known: it walks the tree from its tmin, tmax infinite (the mirror rays drawn and the other rays
// of their generation in one pass, --mirrors).
#define MOBIRT_HIT_UNKNOWN (-1.0)
#define MOBIRT_SPEC_LIGHT_BUFFERS 13  // trace: 1 = point and spot lights' shadow rays test their light
                                      // buffer's cell (MOBIRT_TP_LIGHT_BUFFERS) instead of walking the tree
// Element indices reach the shaders as exact floats: below 2^24 (a float's consecutive integers end
// there), so no buffer holds more texels than that. Below 2^23 one add makes them ints
// (prelude_vk.glsl's data_index()); a pass that binds a larger buffer is specialised to WIDE_INDICES.
#define MOBIRT_NARROW_INDEX_TEXELS 8388608   // 2^23
#define MOBIRT_MAX_INDEX_TEXELS 16777216     // 2^24

// Ray/triangle test: Moller-Trumbore (1997), or the watertight test of Woop, Benthin and Wald
// (JCGT 2013), which never lets a ray slip between two triangles that share an edge.
#define MOBIRT_INTERSECT_MT 0
#define MOBIRT_INTERSECT_WATERTIGHT 1
// Float precision of the intersection arithmetic: highp (fp32), or mediump emulated by rounding
// the ray, the triangle's vertices and every intermediate result of the test to fp16 (drivers
// that compute mediump in fp32, as lavapipe does, would otherwise show no difference). The
// traversal's own arithmetic (node indices, split distances) stays highp: its indices need 24 bits.
#define MOBIRT_PRECISION_HIGH 0
#define MOBIRT_PRECISION_MEDIUM 1
// Self-intersection offset of a ray leaving a surface, along the geometric normal:
//   FIXED: epsilon in scene units; SCALED: epsilon x the scene box's largest side, never below 2
//   ulps of the hit point (fp32 ulps, or fp16 ulps under mediump); NORMAL_ULP: Wachter and Binder
//   2019 (Ray Tracing Gems, ch. 6): the point moved by an integer number of ulps per component,
//   MOBIRT_WB_INT_SCALE x the normal, with a float offset of MOBIRT_WB_FLOAT_SCALE x the normal for
//   components within MOBIRT_WB_ORIGIN of 0.
#define MOBIRT_OFFSET_FIXED 0
#define MOBIRT_OFFSET_SCALED 1
#define MOBIRT_OFFSET_NORMAL_ULP 2
#define MOBIRT_WB_ORIGIN 0.03125           // 1 / 32
#define MOBIRT_WB_FLOAT_SCALE 1.52587890625e-05  // 1 / 65536
#define MOBIRT_WB_INT_SCALE 256.0
// The least SCALED offset under mediump: 2 fp16 ulps of max |p| (2^-9).
#define MOBIRT_OFFSET_HALF_ULPS 0.001953125
// Shading output: 8 bits per channel in one pass, or 16 bits per channel in two passes (the same
// shading twice; one writes the high bytes, the other the low bytes of round(c x 65535)), so
// that every pass still writes one RGBA8 texel per ray.
#define MOBIRT_COLOUR_8 0
#define MOBIRT_COLOUR_16_HIGH 1
#define MOBIRT_COLOUR_16_LOW 2

// Light types as stored in the light uniforms
#define MOBIRT_LIGHT_POINT 0.0
#define MOBIRT_LIGHT_SPOT 1.0
#define MOBIRT_LIGHT_DIRECTIONAL 2.0
#define MOBIRT_LIGHT_NONE -1.0  // an unused slot of a general (unspecialised) pass: never lights

#endif  // MOBIRT_LAYOUT_H
