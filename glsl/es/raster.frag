#version 100
// glsl/raster.frag for OpenGL ES 2.0: the index + 1 rounded to its integer from its two 12-bit
// halves and written as glsl/packing.glsl's 24/8 layout without shadow bits (bytes low, middle,
// high, mask 0), each byte from the halves alone, so that no value the shader computes passes
// 4095. Exact for every index a scene may have (below kKdMaxTriangles, 2^24 / 3; tested in
// LargestIndicesComeBackExact); within 4096 of 2^24, which no scene reaches, llvmpipe returned
// odd indices one too large, joined into one float or not.
precision highp float;

varying highp float v_index_high;
varying highp float v_index_low;

void main() {
  float high = floor(v_index_high + 0.5);  // 0 .. 4095
  float low = floor(v_index_low + 0.5);    // 0 .. 4095
  gl_FragColor = vec4(mod(low, 256.0), floor(low / 256.0) + 16.0 * mod(high, 16.0), floor(high / 16.0), 0.0) / 255.0;
}
