// mobirt_raster_probe: what the primary rays' closest hits would cost rasterized instead of traced.
//
// The paper traces primary rays through the kd-tree like every other generation, and so does
// mobirt: in a ray-casting frame that walk is the traversal pass, the largest stage. A hybrid
// renderer would instead draw the triangles with a depth test, each fragment writing its
// triangle's index into the same RGBA8 attachment the traversal pass writes (24-bit index), and
// trace only shadow and secondary rays. This probe measures that on the same driver (llvmpipe, here
// through OpenGL ES 2.0 on EGL's surfaceless platform: the rasterizer lavapipe shares), with the
// scene's own camera and size, and checks it against the CPU traversal of the same primary rays
// (src/accel/kdtree_traverse.cpp, the traversal pass's oracle), pixel by pixel. The renderer's
// --primary raster (Backend::run_raster, session 27) grew out of it; the probe stays as its
// standalone measure on GLES (docs/performance-history.md *Session 26*).
//
// Per repeat: the posed triangles written into a vertex buffer (position + index, no sharing),
// the draw (glFinish: the rasterizer's time), the read-back (glReadPixels). Medians are printed,
// then the pixels whose closest triangle differs from the traced one's and why.
//
// Usage: mobirt_raster_probe SCENE [--mtl F] [--camera SPEC] [--size WxH] [--repeat N]
//        (the options of tools/profile/profile_scene.h)
#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GLES2/gl2.h>
#include <GLES2/gl2ext.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "accel/kdtree.h"
#include "core/camera.h"
#include "core/error.h"
#include "profile_scene.h"
#include "raytree/rays.h"
#include "render/renderer.h"

namespace mobirt {
namespace {

constexpr const char* kUsage = "usage: mobirt_raster_probe SCENE [--mtl F] [--camera SPEC] [--size WxH] [--repeat N]";

// Each vertex: its position relative to the eye in the camera's frame (x along right, y along up,
// z along forward: the operands of CameraBasis::ray), and its triangle's index + 1 (0: no triangle).
constexpr const char* kVertexShader = R"(
attribute vec4 a_vertex;
uniform vec4 u_projection;  // x, y: 1 / (tan_half aspect), 1 / tan_half; z, w: depth A, B
varying highp float v_index;
void main() {
  gl_Position = vec4(a_vertex.x * u_projection.x, a_vertex.y * u_projection.y,
                     u_projection.z * a_vertex.z + u_projection.w, a_vertex.z);
  v_index = a_vertex.w;
}
)";

// The index as 3 bytes, low byte in red (ES 2.0 has no integer outputs: exact float arithmetic on
// integers below 2^24). Interpolating three equal values can miss the integer by rounding: + 0.5.
constexpr const char* kFragmentShader = R"(
precision highp float;
varying highp float v_index;
void main() {
  float index = floor(v_index + 0.5);
  float b0 = mod(index, 256.0);
  float rest = floor(index / 256.0);
  float b1 = mod(rest, 256.0);
  float b2 = floor(rest / 256.0);
  gl_FragColor = vec4(b0, b1, b2, 255.0) / 255.0;
}
)";

double ms_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

// Throws with the info log when a shader's compile or a program's link (`status`) failed: the
// shader and program queries have the same shapes.
void check_status(GLuint object, GLenum status, void (*get)(GLuint, GLenum, GLint*),
                  void (*get_log)(GLuint, GLsizei, GLsizei*, GLchar*), const char* what) {
  GLint ok = 0;
  get(object, status, &ok);
  if (!ok) {
    char log[2048] = {};
    get_log(object, sizeof(log), nullptr, log);
    throw Error(ErrorKind::Internal, std::string(what) + " failed: " + log);
  }
}

GLuint compile(GLenum kind, const char* source) {
  const GLuint shader = glCreateShader(kind);
  glShaderSource(shader, 1, &source, nullptr);
  glCompileShader(shader);
  check_status(shader, GL_COMPILE_STATUS, glGetShaderiv, glGetShaderInfoLog, "shader compile");
  return shader;
}

// An OpenGL ES 2.0 context without a surface (Mesa's surfaceless platform), current on return.
void make_context() {
  auto get_platform_display =
      reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
  if (!get_platform_display) throw Error(ErrorKind::NoDevice, "EGL lacks eglGetPlatformDisplayEXT (install libegl-mesa0)");
  const EGLDisplay display = get_platform_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
  EGLint major = 0, minor = 0;
  if (display == EGL_NO_DISPLAY || !eglInitialize(display, &major, &minor)) {
    throw Error(ErrorKind::NoDevice, "no EGL surfaceless display (install libegl-mesa0)");
  }
  eglBindAPI(EGL_OPENGL_ES_API);
  const EGLint config_attributes[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_ES2_BIT, EGL_SURFACE_TYPE, EGL_PBUFFER_BIT,
                                      EGL_NONE};
  EGLConfig config = nullptr;
  EGLint count = 0;
  if (!eglChooseConfig(display, config_attributes, &config, 1, &count) || count == 0) {
    throw Error(ErrorKind::NoDevice, "no EGL config for OpenGL ES 2.0");
  }
  const EGLint context_attributes[] = {EGL_CONTEXT_CLIENT_VERSION, 2, EGL_NONE};
  const EGLContext context = eglCreateContext(display, config, EGL_NO_CONTEXT, context_attributes);
  if (context == EGL_NO_CONTEXT || !eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, context)) {
    throw Error(ErrorKind::NoDevice, "cannot make an OpenGL ES 2.0 context current without a surface");
  }
}

int run(int argc, char** argv) {
  profile::ProfileScene p = profile::load_profile_scene(argc, argv, kUsage);
  const Scene& scene = p.scene;
  const int width = p.width, height = p.height;
  const size_t triangles = scene.mesh.triangle_count();
  if (triangles > (size_t(1) << 24) - 1) throw Error(ErrorKind::BadInput, "more triangles than 24 bits index (index + 1)");
  make_context();
  const GLubyte* renderer_name = glGetString(GL_RENDERER);
  const GLubyte* extension_list = glGetString(GL_EXTENSIONS);
  const std::string renderer = renderer_name ? reinterpret_cast<const char*>(renderer_name) : "?";
  const std::string extensions = extension_list ? reinterpret_cast<const char*>(extension_list) : "";
  const bool depth24 = extensions.find("GL_OES_depth24") != std::string::npos;

  // The target: RGBA8 colour (a texture: ES 2.0 has no RGBA8 renderbuffer without an extension)
  // and a depth buffer.
  GLuint colour = 0, depth = 0, fbo = 0;
  glGenTextures(1, &colour);
  glBindTexture(GL_TEXTURE_2D, colour);
  glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA, width, height, 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
  glGenRenderbuffers(1, &depth);
  glBindRenderbuffer(GL_RENDERBUFFER, depth);
  glRenderbufferStorage(GL_RENDERBUFFER, depth24 ? GL_DEPTH_COMPONENT24_OES : GL_DEPTH_COMPONENT16, width, height);
  glGenFramebuffers(1, &fbo);
  glBindFramebuffer(GL_FRAMEBUFFER, fbo);
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, colour, 0);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth);
  if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
    throw Error(ErrorKind::Internal, "incomplete framebuffer");
  }
  const GLuint program = glCreateProgram();
  glAttachShader(program, compile(GL_VERTEX_SHADER, kVertexShader));
  glAttachShader(program, compile(GL_FRAGMENT_SHADER, kFragmentShader));
  glBindAttribLocation(program, 0, "a_vertex");
  glLinkProgram(program);
  check_status(program, GL_LINK_STATUS, glGetProgramiv, glGetProgramInfoLog, "program link");
  glUseProgram(program);

  // The projection of CameraBasis::ray: pixel x's centre at ndc 2 (x + 0.5) / width - 1, row y
  // (0 at the top) at 1 - 2 (y + 0.5) / height, so that each pixel centre samples the primary ray
  // through it. Depth from the renderer's near and far (raster_view, as --primary raster draws:
  // the nearest point a primary ray can see, to just past the farthest vertex).
  const CameraBasis basis(p.camera, width, height);
  RasterView view{};
  if (!raster_view(p.camera, width, height, scene.mesh.positions, view)) {
    throw Error(ErrorKind::BadInput, "every triangle lies behind the camera");
  }
  const float near_distance = view.projection[2], far_distance = view.projection[3];
  const float a = (far_distance + near_distance) / (far_distance - near_distance);
  const float b = -2.0f * far_distance * near_distance / (far_distance - near_distance);
  glUniform4f(glGetUniformLocation(program, "u_projection"), 1.0f / (basis.tan_half * basis.aspect),
              1.0f / basis.tan_half, a, b);
  glViewport(0, 0, width, height);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glClearColor(0.0f, 0.0f, 0.0f, 0.0f);

  GLuint vbo = 0;
  glGenBuffers(1, &vbo);
  glBindBuffer(GL_ARRAY_BUFFER, vbo);
  glEnableVertexAttribArray(0);
  std::vector<glm::vec4> vertices(3 * triangles);
  std::vector<uint8_t> pixels(size_t(width) * size_t(height) * 4);
  std::vector<double> upload_ms, draw_ms, readback_ms;
  const std::vector<glm::vec3>& positions = scene.mesh.positions;
  for (int r = 0; r < std::max(1, p.repeat) + 1; ++r) {  // the first is a warm-up (shader compile)
    auto start = std::chrono::steady_clock::now();
    for (size_t i = 0; i < 3 * triangles; ++i) {
      const glm::vec3 v = positions[i] - basis.eye;
      vertices[i] = glm::vec4(glm::dot(v, basis.right), glm::dot(v, basis.up), glm::dot(v, basis.forward),
                              float(i / 3 + 1));
    }
    glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(vertices.size() * sizeof(glm::vec4)), vertices.data(), GL_STREAM_DRAW);
    glVertexAttribPointer(0, 4, GL_FLOAT, GL_FALSE, 0, nullptr);
    glFinish();
    const double upload = ms_since(start);
    start = std::chrono::steady_clock::now();
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    glDrawArrays(GL_TRIANGLES, 0, GLsizei(vertices.size()));
    glFinish();
    const double draw = ms_since(start);
    start = std::chrono::steady_clock::now();
    glReadPixels(0, 0, width, height, GL_RGBA, GL_UNSIGNED_BYTE, pixels.data());
    const double readback = ms_since(start);
    if (r > 0) {
      upload_ms.push_back(upload);
      draw_ms.push_back(draw);
      readback_ms.push_back(readback);
    }
  }
  if (glGetError() != GL_NO_ERROR) throw Error(ErrorKind::Internal, "OpenGL ES error");

  // Against the CPU traversal of the primary rays, pixel by pixel (GL's rows run bottom-up).
  const RayBatch rays = primary_rays(p.camera, width, height);
  size_t hits = 0, same = 0, other_triangle = 0, raster_only = 0, traced_only = 0;
  // Of the pixels with another triangle: the ray also hits the rasterized one at the traced t
  // (within 1e-4 of it, relative: two triangles that meet there, an edge or a vertex they
  // share, or coplanar ones), hits it farther, or misses it (the rasterizer's sample fell inside
  // the triangle where the ray test, rounded differently, does not).
  size_t tie = 0, farther = 0, nearer = 0, missed = 0;
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const size_t i = size_t(y) * size_t(width) + size_t(x);
      const uint8_t* px = &pixels[(size_t(height - 1 - y) * size_t(width) + size_t(x)) * 4];
      const int64_t raster = int64_t(px[0]) + 256 * int64_t(px[1]) + 65536 * int64_t(px[2]) - 1;
      const Hit traced = traverse(p.tree, rays.ray(uint32_t(i)));
      hits += traced.valid() ? 1 : 0;
      if (raster >= int64_t(triangles)) throw Error(ErrorKind::Internal, "a pixel holds no triangle's index");
      if (raster == traced.prim) {
        ++same;
      } else if (raster >= 0 && traced.valid()) {
        ++other_triangle;
        Hit h;
        if (!intersect_triangle(p.tree, int32_t(raster), rays.ray(uint32_t(i)), h)) {
          ++missed;
        } else if (std::abs(h.t - traced.t) <= 1e-4f * traced.t) {
          ++tie;
        } else if (h.t > traced.t) {
          ++farther;
        } else {
          ++nearer;  // the traversal missed a closer hit: a traversal bug
        }
      } else if (raster >= 0) {
        ++raster_only;
      } else {
        ++traced_only;
      }
    }
  }
  const double n = double(width) * double(height);
  std::printf("%s: %zu triangles, %dx%d, %s, depth %d bits, medians of %d: vertices written and uploaded %.3f ms, "
              "draw %.3f ms, read-back %.3f ms\n",
              p.path.c_str(), triangles, width, height, renderer.c_str(), depth24 ? 24 : 16, std::max(1, p.repeat),
              median(upload_ms), median(draw_ms), median(readback_ms));
  std::printf("against the CPU traversal: %zu of %.0f pixels hit; the same triangle or both a miss %zu; another triangle "
              "%zu (%.4f %%), rasterized only %zu (%.4f %%), traced only %zu (%.4f %%)\n",
              hits, n, same, other_triangle, 100.0 * double(other_triangle) / n, raster_only,
              100.0 * double(raster_only) / n, traced_only, 100.0 * double(traced_only) / n);
  std::printf("of those with another triangle: the ray meets the rasterized one at the traced t (within 1e-4) %zu, "
              "farther %zu, nearer %zu, misses it %zu; depth range %.4g to %.4g\n",
              tie, farther, nearer, missed, double(near_distance), double(far_distance));
  return 0;
}

}  // namespace
}  // namespace mobirt

int main(int argc, char** argv) { return mobirt::profile::run_tool("mobirt_raster_probe", argc, argv, mobirt::run); }
