#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_buffer_reference_uvec2 : require
// The shading pass (Vulkan) under --data device-addresses: its per-ray inputs and the materials
// read through buffer references, like the traversal pass's data (outside the ES 2.0 model, as
// trace_device_addresses.frag says). The atlas pages stay 2D images.
#define MOBIRT_DATA_DEVICE_ADDRESSES
#include "prelude_vk.glsl"
#include "shade_main.glsl"
