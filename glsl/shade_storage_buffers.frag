#version 450
#extension GL_GOOGLE_include_directive : require
// The shading pass (Vulkan) under --data storage-buffers: its per-ray inputs and the materials are
// read-only storage buffers, like the traversal pass's data (the measurement variant that breaks
// the ES 2.0 model by name: the constraint checker waives that rule for a pass binding them).
// The atlas pages stay 2D images.
#define MOBIRT_DATA_STORAGE_BUFFERS
#include "prelude_vk.glsl"
#include "shade_main.glsl"
