// Headless OpenGL ES 2.0 backend: EGL without a window (Mesa's surfaceless platform, or an EGL
// device), an ES 2.0 context made current without a surface, GLSL ES 1.00 shaders generated from
// the same glsl/ bodies as the Vulkan ones (prelude_es.glsl), float data textures through
// OES_texture_float with NEAREST sampling, one RGBA8 colour attachment per pass, glReadPixels.
// Every pass is synchronous (glFinish), so its time is measured on the CPU clock around it.
#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GLES2/gl2.h>
#include <GLES2/gl2ext.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <map>
#include <memory>
#include <mutex>
#include <regex>
#include <set>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "backend/backend.h"
#include "core/error.h"
#include "layout.h"

// The full-screen triangle's GLSL ES 1.00 source (build/gles_shaders/; a pass's own comes with its
// PassDesc) and the binding and #define tables generated from glsl/layout.h and prelude_vk.glsl.
#include "es_fullscreen_vert.h"
#include "es_raster_frag.h"
#include "es_raster_vert.h"
#include "gles_layout_tables.h"

namespace mobirt {

namespace {

using Clock = std::chrono::steady_clock;

// ---- Small helpers -----------------------------------------------------------------------------

bool env_flag(const char* name) {
  const char* value = std::getenv(name);
  return value && *value && std::string(value) != "0";
}

bool has_word(const char* list, const std::string& word) {
  if (!list) return false;
  const std::string s = std::string(" ") + list + " ";
  return s.find(" " + word + " ") != std::string::npos;
}

std::string egl_error_name(EGLint error) {
  switch (error) {
    case EGL_SUCCESS: return "EGL_SUCCESS";
    case EGL_NOT_INITIALIZED: return "EGL_NOT_INITIALIZED";
    case EGL_BAD_ACCESS: return "EGL_BAD_ACCESS";
    case EGL_BAD_ALLOC: return "EGL_BAD_ALLOC";
    case EGL_BAD_ATTRIBUTE: return "EGL_BAD_ATTRIBUTE";
    case EGL_BAD_CONFIG: return "EGL_BAD_CONFIG";
    case EGL_BAD_CONTEXT: return "EGL_BAD_CONTEXT";
    case EGL_BAD_DISPLAY: return "EGL_BAD_DISPLAY";
    case EGL_BAD_MATCH: return "EGL_BAD_MATCH";
    case EGL_BAD_PARAMETER: return "EGL_BAD_PARAMETER";
    default: return "EGL error " + std::to_string(error);
  }
}

std::string gl_error_name(GLenum error) {
  switch (error) {
    case GL_INVALID_ENUM: return "GL_INVALID_ENUM";
    case GL_INVALID_VALUE: return "GL_INVALID_VALUE";
    case GL_INVALID_OPERATION: return "GL_INVALID_OPERATION";
    case GL_OUT_OF_MEMORY: return "GL_OUT_OF_MEMORY";
    case GL_INVALID_FRAMEBUFFER_OPERATION: return "GL_INVALID_FRAMEBUFFER_OPERATION";
    default: return "GL error " + std::to_string(error);
  }
}

std::string gl_string(GLenum name) {
  const GLubyte* s = glGetString(name);
  return s ? reinterpret_cast<const char*>(s) : "";
}

GLint gl_int(GLenum name) {
  GLint value = 0;
  glGetIntegerv(name, &value);
  return value;
}

// Specialization constant ids (glsl/layout.h) and the #define each becomes on GLES.
const char* define_name(uint32_t id) {
  for (const gles::SpecDefine& d : gles::kSpecDefines) {
    if (d.id == id) return d.define;
  }
  return nullptr;
}

// The binding slot a SAMPLER(slot, name) line names: a number or a MOBIRT_BIND_* name.
int binding_value(const std::string& slot) {
  if (!slot.empty() && std::all_of(slot.begin(), slot.end(), [](char c) { return c >= '0' && c <= '9'; })) {
    return std::atoi(slot.c_str());
  }
  for (const gles::BindingName& b : gles::kBindingNames) {
    if (slot == b.name) return b.slot;
  }
  return -1;
}

std::string strip_comments(const std::string& source) {
  std::string out;
  out.reserve(source.size());
  for (size_t i = 0; i < source.size(); ++i) {
    if (source.compare(i, 2, "//") == 0) {
      while (i < source.size() && source[i] != '\n') ++i;
      out.push_back('\n');
    } else if (source.compare(i, 2, "/*") == 0) {
      const size_t end = source.find("*/", i + 2);
      i = end == std::string::npos ? source.size() : end + 1;
      out.push_back(' ');
    } else {
      out.push_back(source[i]);
    }
  }
  return out;
}

// The OpenGL ES 2.0 constraints read from a GLSL ES source (comments removed): colour outputs
// written and storage writes. Sampled textures are counted after linking, on the program.
struct EsInterface {
  int color_outputs = 0;
  std::vector<std::string> storage;  // what was found: "buffer", "imageStore", ...
};

EsInterface reflect_es_source(const std::string& code) {
  EsInterface result;
  std::set<std::string> outputs;
  static const std::regex frag_data(R"(gl_FragData\s*\[\s*(\d+)\s*\])");
  for (auto it = std::sregex_iterator(code.begin(), code.end(), frag_data); it != std::sregex_iterator(); ++it) {
    outputs.insert("gl_FragData[" + (*it)[1].str() + "]");
  }
  if (std::regex_search(code, std::regex(R"(\bgl_FragColor\b)"))) outputs.insert("gl_FragData[0]");
  static const std::regex out_var(R"((^|[;}\n])\s*(layout\s*\([^)]*\)\s*)?(highp\s+|mediump\s+|lowp\s+)?out\s+\w+\s+(\w+))");
  for (auto it = std::sregex_iterator(code.begin(), code.end(), out_var); it != std::sregex_iterator(); ++it) {
    outputs.insert((*it)[4].str());
  }
  result.color_outputs = int(outputs.size());
  static const std::regex storage(R"(\b(buffer|imageStore|image[123]D\w*|image2DArray|imageCube\w*|atomic\w+|shared)\b)");
  for (auto it = std::sregex_iterator(code.begin(), code.end(), storage); it != std::sregex_iterator(); ++it) {
    result.storage.push_back((*it)[1].str());
  }
  return result;
}

// SAMPLER(slot, name) and DATA_SAMPLER(slot, name) lines of a source (DATA_SAMPLER is SAMPLER on
// GLES: traverse.glsl's scene data, texel buffers on Vulkan): name -> binding slot.
std::map<std::string, int> sampler_slots(const std::string& code) {
  std::map<std::string, int> slots;
  static const std::regex line(R"(\b(?:DATA_)?SAMPLER\s*\(\s*(\w+)\s*,\s*(\w+)\s*\))");
  for (auto it = std::sregex_iterator(code.begin(), code.end(), line); it != std::sregex_iterator(); ++it) {
    if ((*it)[1].str() == "slot") continue;  // a #define of the macro itself
    slots[(*it)[2].str()] = binding_value((*it)[1].str());
  }
  return slots;
}

// ---- Debug messages (KHR_debug) ----------------------------------------------------------------

struct DebugSink {
  std::mutex mutex;
  std::vector<std::string> messages;
};

void GL_APIENTRY debug_callback(GLenum /*source*/, GLenum type, GLuint /*id*/, GLenum severity, GLsizei length,
                                const GLchar* message, const void* user) {
  if (severity == GL_DEBUG_SEVERITY_NOTIFICATION_KHR) return;
  const char* kind = "message";
  switch (type) {
    case GL_DEBUG_TYPE_ERROR_KHR: kind = "error"; break;
    case GL_DEBUG_TYPE_DEPRECATED_BEHAVIOR_KHR: kind = "deprecated behaviour"; break;
    case GL_DEBUG_TYPE_UNDEFINED_BEHAVIOR_KHR: kind = "undefined behaviour"; break;
    case GL_DEBUG_TYPE_PORTABILITY_KHR: kind = "portability"; break;
    case GL_DEBUG_TYPE_PERFORMANCE_KHR: kind = "performance"; break;
    default: break;
  }
  auto* sink = static_cast<DebugSink*>(const_cast<void*>(user));
  std::lock_guard lock(sink->mutex);
  sink->messages.push_back(std::string("GL ") + kind + ": " +
                           (length >= 0 ? std::string(message, size_t(length)) : std::string(message)));
}

// ---- EGL display, shared by every backend of the process -----------------------------------------

struct EglDisplay {
  EGLDisplay display = EGL_NO_DISPLAY;
  std::string platform;
  std::string vendor, version;
  int users = 0;
};

std::mutex& display_mutex() {
  static std::mutex m;
  return m;
}
EglDisplay& shared_display() {
  static EglDisplay d;
  return d;
}

// Opens (or shares) the EGL display: Mesa's surfaceless platform first, else the first EGL device.
EglDisplay& acquire_display() {
  std::lock_guard lock(display_mutex());
  EglDisplay& d = shared_display();
  if (d.users++ > 0) return d;
  try {
    const char* client = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
    if (!client) {
      throw Error(ErrorKind::NoDevice, "EGL has no client extensions (EGL_EXT_client_extensions): install libegl-mesa0");
    }
    auto get_platform_display =
        reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
    if (!has_word(client, "EGL_EXT_platform_base") || !get_platform_display) {
      throw Error(ErrorKind::Unsupported, "EGL lacks EGL_EXT_platform_base: no way to open a display without a window "
                                          "(install libegl-mesa0)");
    }
    if (has_word(client, "EGL_MESA_platform_surfaceless")) {
      d.display = get_platform_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
      d.platform = "EGL_MESA_platform_surfaceless";
    }
    if (d.display == EGL_NO_DISPLAY && has_word(client, "EGL_EXT_platform_device") &&
        has_word(client, "EGL_EXT_device_enumeration")) {
      auto query_devices = reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
      EGLDeviceEXT devices[16];
      EGLint count = 0;
      if (query_devices && query_devices(16, devices, &count) && count > 0) {
        d.display = get_platform_display(EGL_PLATFORM_DEVICE_EXT, devices[0], nullptr);
        d.platform = "EGL_EXT_platform_device";
      }
    }
    if (d.display == EGL_NO_DISPLAY) {
      throw Error(ErrorKind::NoDevice, "no EGL display without a window: neither EGL_MESA_platform_surfaceless nor "
                                       "EGL_EXT_platform_device with a device is available (install libegl-mesa0)");
    }
    EGLint major = 0, minor = 0;
    if (!eglInitialize(d.display, &major, &minor)) {
      throw Error(ErrorKind::NoDevice, "eglInitialize failed on " + d.platform + ": " + egl_error_name(eglGetError()));
    }
    const char* vendor = eglQueryString(d.display, EGL_VENDOR);
    const char* version = eglQueryString(d.display, EGL_VERSION);
    d.vendor = vendor ? vendor : "";
    d.version = version ? version : "";
  } catch (...) {
    d.users = 0;
    d.display = EGL_NO_DISPLAY;
    throw;
  }
  return d;
}

void release_display() {
  std::lock_guard lock(display_mutex());
  EglDisplay& d = shared_display();
  if (--d.users > 0) return;
  if (d.display != EGL_NO_DISPLAY) eglTerminate(d.display);
  d.display = EGL_NO_DISPLAY;
  d.users = 0;
}

// ---- Resources ---------------------------------------------------------------------------------

struct Texture {
  uint32_t width = 0, height = 0;
  TexelFormat format = TexelFormat::RGBA32F;
  GLuint name = 0;
  GLint filter = GL_NEAREST;  // as last set: PassDesc::linear_bindings switch it at binding
};

struct SamplerUniform {
  int slot = -1;
  GLint texture_location = -1;   // name.tex
  GLint inv_size_location = -1;  // name.inv_size
};

struct Pass {
  PassDesc desc;
  GLuint program = 0;
  GLint params_location = -1;
  GLint params_size = 0;  // active vec4 of u_params
  std::vector<SamplerUniform> samplers;  // one per entry of desc.texture_bindings (location -1: unused)
};

// ---- The backend ---------------------------------------------------------------------------------

class GlesBackend final : public Backend {
 public:
  explicit GlesBackend(const BackendOptions& options);
  ~GlesBackend() override;

  DeviceInfo device_info() const override { return info_; }
  TextureHandle create_texture(uint32_t width, uint32_t height, TexelFormat format) override;
  void upload(TextureHandle texture, const void* data, size_t bytes) override;
  void destroy(TextureHandle texture) override;
  PassHandle create_pass(const PassDesc& desc) override;
  void destroy(PassHandle pass) override;
  PassTiming run_pass(PassHandle pass, std::span<const TextureHandle> textures, std::span<const float> uniforms,
                      uint32_t width, uint32_t count, std::span<uint32_t> out) override;
  PassTiming run_raster(std::span<const float> vertices, const RasterView& view, uint32_t width, uint32_t height,
                        std::span<uint32_t> out) override;
  std::vector<std::string> take_debug_messages() override;

 private:
  void current() const;                 // makes this backend's context current
  void check_gl(const char* what) const;  // throws on a pending GL error
  void ensure_target(uint32_t width, uint32_t height);
  GLuint compile(GLenum stage, const std::string& source, const std::string& name);
  // `vertex` and `fragment` linked with `attribute` at location 0; `fragment` is freed with the
  // program (or at once on a failed link, which throws naming `name`).
  GLuint link_program(GLuint vertex, GLuint fragment, const char* attribute, const std::string& name);
  void prepare_raster(uint32_t width, uint32_t height);  // the raster program and target (run_raster)
  Texture& texture_ref(TextureHandle handle);
  Pass& pass_ref(PassHandle handle);

  DebugSink sink_;
  EglDisplay* display_ = nullptr;
  EGLContext context_ = EGL_NO_CONTEXT;
  DeviceInfo info_;
  GLint max_texture_size_ = 0;
  GLint max_texture_units_ = 0;
  GLuint vertex_shader_ = 0;
  GLuint vertex_buffer_ = 0;
  GLuint framebuffer_ = 0;
  GLuint target_ = 0;
  uint32_t target_width_ = 0, target_height_ = 0;
  std::vector<uint8_t> readback_;
  // The raster pass (run_raster), made by its first call: program, vertex buffer, and a target of
  // its own, RGBA8 colour and a depth buffer (24 bits with GL_OES_depth24, else 16).
  struct Raster {
    GLuint program = 0;
    GLint eye = -1, right = -1, up = -1, forward = -1, projection = -1;
    GLuint vertices = 0;
    GLuint framebuffer = 0, colour = 0, depth = 0;
    uint32_t width = 0, height = 0;
  } raster_;
  bool depth24_ = false;
  std::unordered_map<uint32_t, Texture> textures_;
  std::unordered_map<uint32_t, Pass> passes_;
  uint32_t next_texture_ = 1;
  uint32_t next_pass_ = 1;
  double pending_upload_ms_ = 0.0;
};

GlesBackend::GlesBackend(const BackendOptions& options) {
  display_ = &acquire_display();
  try {
    const EGLDisplay dpy = display_->display;
    const char* extensions = eglQueryString(dpy, EGL_EXTENSIONS);
    if (!has_word(extensions, "EGL_KHR_surfaceless_context")) {
      throw Error(ErrorKind::Unsupported, "EGL lacks EGL_KHR_surfaceless_context: mobirt renders without a surface");
    }
    if (!eglBindAPI(EGL_OPENGL_ES_API)) {
      throw Error(ErrorKind::Unsupported, "EGL cannot bind OpenGL ES: " + egl_error_name(eglGetError()));
    }
    const EGLint config_attributes[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_ES2_BIT, EGL_SURFACE_TYPE, EGL_DONT_CARE, EGL_NONE};
    EGLConfig config = nullptr;
    EGLint config_count = 0;
    if (!eglChooseConfig(dpy, config_attributes, &config, 1, &config_count) || config_count == 0) {
      if (!has_word(extensions, "EGL_KHR_no_config_context")) {
        throw Error(ErrorKind::Unsupported, "EGL has no config for OpenGL ES 2.0 (and no EGL_KHR_no_config_context)");
      }
      config = EGL_NO_CONFIG_KHR;
    }
    const bool debug = options.validation || env_flag("MOBIRT_VALIDATION");
    std::vector<EGLint> context_attributes = {EGL_CONTEXT_CLIENT_VERSION, 2};
    const bool egl15 = display_->version.rfind("1.5", 0) == 0;
    if (debug && egl15) context_attributes.insert(context_attributes.end(), {EGL_CONTEXT_OPENGL_DEBUG, EGL_TRUE});
    context_attributes.push_back(EGL_NONE);
    context_ = eglCreateContext(dpy, config, EGL_NO_CONTEXT, context_attributes.data());
    if (context_ == EGL_NO_CONTEXT) {
      throw Error(ErrorKind::Unsupported, "eglCreateContext for OpenGL ES 2.0 failed: " + egl_error_name(eglGetError()));
    }
    if (!eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, context_)) {
      throw Error(ErrorKind::Unsupported, "eglMakeCurrent without a surface failed: " + egl_error_name(eglGetError()));
    }

    const std::string gl_extensions = gl_string(GL_EXTENSIONS);
    if (!has_word(gl_extensions.c_str(), "GL_OES_texture_float")) {
      throw Error(ErrorKind::Unsupported, "the OpenGL ES context (" + gl_string(GL_RENDERER) +
                                              ") lacks GL_OES_texture_float: mobirt keeps its scene data in float textures");
    }
    const bool khr_debug = has_word(gl_extensions.c_str(), "GL_KHR_debug");
    depth24_ = has_word(gl_extensions.c_str(), "GL_OES_depth24");
    if (khr_debug) {
      auto callback = reinterpret_cast<PFNGLDEBUGMESSAGECALLBACKKHRPROC>(eglGetProcAddress("glDebugMessageCallbackKHR"));
      auto control = reinterpret_cast<PFNGLDEBUGMESSAGECONTROLKHRPROC>(eglGetProcAddress("glDebugMessageControlKHR"));
      if (callback) {
        glEnable(GL_DEBUG_OUTPUT_KHR);
        if (debug) glEnable(GL_DEBUG_OUTPUT_SYNCHRONOUS_KHR);
        callback(debug_callback, &sink_);
        if (control) control(GL_DONT_CARE, GL_DONT_CARE, GL_DEBUG_SEVERITY_NOTIFICATION_KHR, 0, nullptr, GL_FALSE);
      }
    }

    // What mobirt needs beyond the ES 2.0 minimums, checked with a clear error.
    GLint range[2] = {0, 0}, precision = 0;
    glGetShaderPrecisionFormat(GL_FRAGMENT_SHADER, GL_HIGH_FLOAT, range, &precision);
    if (precision < 23) {
      throw Error(ErrorKind::Unsupported, "the fragment shader has no 32-bit highp float (precision " +
                                              std::to_string(precision) + " bits): traversal needs it");
    }
    const GLint uniform_vectors = gl_int(GL_MAX_FRAGMENT_UNIFORM_VECTORS);
    const GLint needed_vectors = MOBIRT_MAX_PARAM_VEC4S + MOBIRT_MAX_SAMPLED_TEXTURES;
    if (uniform_vectors < needed_vectors) {
      throw Error(ErrorKind::Unsupported, "GL_MAX_FRAGMENT_UNIFORM_VECTORS is " + std::to_string(uniform_vectors) +
                                              "; mobirt needs " + std::to_string(needed_vectors) + " (" +
                                              std::to_string(MOBIRT_MAX_PARAM_VEC4S) +
                                              " parameters + one texture size per sampler)");
    }
    max_texture_units_ = gl_int(GL_MAX_TEXTURE_IMAGE_UNITS);
    if (max_texture_units_ < MOBIRT_MAX_SAMPLED_TEXTURES) {
      throw Error(ErrorKind::Unsupported, "GL_MAX_TEXTURE_IMAGE_UNITS is " + std::to_string(max_texture_units_) +
                                              ", below OpenGL ES 2.0's minimum of 8");
    }
    max_texture_size_ = gl_int(GL_MAX_TEXTURE_SIZE);
    if (max_texture_size_ < MOBIRT_DATA_WIDTH) {
      throw Error(ErrorKind::Unsupported, "GL_MAX_TEXTURE_SIZE is " + std::to_string(max_texture_size_) +
                                              "; mobirt's data textures are " + std::to_string(MOBIRT_DATA_WIDTH) +
                                              " texels wide");
    }
    GLint viewport[2] = {0, 0};
    glGetIntegerv(GL_MAX_VIEWPORT_DIMS, viewport);

    const std::string renderer = gl_string(GL_RENDERER);
    info_.api = gl_string(GL_VERSION);
    info_.device = renderer;
    info_.driver = gl_string(GL_VENDOR) + " / EGL " + display_->version + " (" + display_->vendor + ", " +
                   display_->platform + ")";
    const std::string mesa = mesa_version(info_.api);  // GL_VERSION "OpenGL ES 3.2 Mesa 25.0.7"
    info_.driver_version = mesa.empty() ? info_.api : mesa;
    info_.ray_query = false;  // no ray tracing in OpenGL ES
    info_.is_software = renderer.find("llvmpipe") != std::string::npos ||
                        renderer.find("softpipe") != std::string::npos || renderer.find("swrast") != std::string::npos;
    auto add = [&](const std::string& name, const std::string& value) { info_.limits.push_back(name + ": " + value); };
    add("GL_VERSION", info_.api);
    add("GL_RENDERER", renderer);
    add("GL_SHADING_LANGUAGE_VERSION", gl_string(GL_SHADING_LANGUAGE_VERSION));
    add("context", "OpenGL ES 2.0 requested (EGL_CONTEXT_CLIENT_VERSION 2), shaders GLSL ES 1.00");
    add("EGL", display_->platform + " + EGL_KHR_surfaceless_context");
    add("extensions used", std::string("GL_OES_texture_float (required)") +
                               (khr_debug ? ", GL_KHR_debug" : ", GL_KHR_debug absent: no debug messages"));
    add("GL_MAX_TEXTURE_IMAGE_UNITS", std::to_string(max_texture_units_));
    add("GL_MAX_FRAGMENT_UNIFORM_VECTORS", std::to_string(uniform_vectors) + " (mobirt needs " +
                                               std::to_string(needed_vectors) + ")");
    add("GL_MAX_TEXTURE_SIZE", std::to_string(max_texture_size_));
    add("GL_MAX_VIEWPORT_DIMS", std::to_string(viewport[0]) + "x" + std::to_string(viewport[1]));
    add("fragment highp float", "precision " + std::to_string(precision) + " bits, range 2^" +
                                    std::to_string(range[1]));
    add("timing", "CPU clock around glFinish (EXT_disjoint_timer_query not used)");

    // Shared objects: the full-screen triangle, its vertex shader, the framebuffer.
    vertex_shader_ = compile(GL_VERTEX_SHADER, es_fullscreen_vert, "fullscreen.vert");
    const GLfloat triangle[] = {-1.0f, -1.0f, 3.0f, -1.0f, -1.0f, 3.0f};
    glGenBuffers(1, &vertex_buffer_);
    glBindBuffer(GL_ARRAY_BUFFER, vertex_buffer_);
    glBufferData(GL_ARRAY_BUFFER, sizeof(triangle), triangle, GL_STATIC_DRAW);
    glGenFramebuffers(1, &framebuffer_);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glPixelStorei(GL_PACK_ALIGNMENT, 4);
    glDisable(GL_DEPTH_TEST);
    glDisable(GL_BLEND);
    glDisable(GL_DITHER);  // RGBA8 values must round exactly, never dither
    check_gl("context set-up");
  } catch (...) {
    if (context_ != EGL_NO_CONTEXT) {
      eglMakeCurrent(display_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
      eglDestroyContext(display_->display, context_);
    }
    release_display();
    throw;
  }
}

GlesBackend::~GlesBackend() {
  if (eglGetCurrentContext() != context_) {
    eglMakeCurrent(display_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, context_);
  }
  for (auto& [id, t] : textures_) glDeleteTextures(1, &t.name);
  for (auto& [id, p] : passes_) glDeleteProgram(p.program);
  if (target_) glDeleteTextures(1, &target_);
  if (framebuffer_) glDeleteFramebuffers(1, &framebuffer_);
  if (raster_.program) glDeleteProgram(raster_.program);
  if (raster_.vertices) glDeleteBuffers(1, &raster_.vertices);
  if (raster_.framebuffer) glDeleteFramebuffers(1, &raster_.framebuffer);
  if (raster_.colour) glDeleteTextures(1, &raster_.colour);
  if (raster_.depth) glDeleteRenderbuffers(1, &raster_.depth);
  if (vertex_buffer_) glDeleteBuffers(1, &vertex_buffer_);
  if (vertex_shader_) glDeleteShader(vertex_shader_);
  glFinish();
  eglMakeCurrent(display_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
  eglDestroyContext(display_->display, context_);
  release_display();
}

void GlesBackend::current() const {
  if (eglGetCurrentContext() == context_) return;
  if (!eglMakeCurrent(display_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, context_)) {
    throw Error(ErrorKind::Internal, "eglMakeCurrent failed: " + egl_error_name(eglGetError()));
  }
}

void GlesBackend::check_gl(const char* what) const {
  const GLenum error = glGetError();
  if (error == GL_NO_ERROR) return;
  while (glGetError() != GL_NO_ERROR) {
  }
  throw Error(error == GL_OUT_OF_MEMORY ? ErrorKind::BadInput : ErrorKind::Internal,
              std::string("OpenGL ES: ") + what + ": " + gl_error_name(error));
}

Texture& GlesBackend::texture_ref(TextureHandle handle) {
  const auto it = textures_.find(handle.id);
  if (it == textures_.end()) throw Error(ErrorKind::Internal, "unknown texture handle " + std::to_string(handle.id));
  return it->second;
}

Pass& GlesBackend::pass_ref(PassHandle handle) {
  const auto it = passes_.find(handle.id);
  if (it == passes_.end()) throw Error(ErrorKind::Internal, "unknown pass handle " + std::to_string(handle.id));
  return it->second;
}

GLuint GlesBackend::compile(GLenum stage, const std::string& source, const std::string& name) {
  const GLuint shader = glCreateShader(stage);
  const char* text = source.c_str();
  glShaderSource(shader, 1, &text, nullptr);
  glCompileShader(shader);
  GLint ok = GL_FALSE;
  glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    GLint length = 0;
    glGetShaderiv(shader, GL_INFO_LOG_LENGTH, &length);
    std::string log(size_t(std::max(length, 1)), '\0');
    glGetShaderInfoLog(shader, GLsizei(log.size()), nullptr, log.data());
    glDeleteShader(shader);
    throw Error(ErrorKind::Internal, "GLSL ES compile of " + name + " failed: " + log.c_str());
  }
  return shader;
}

GLuint GlesBackend::link_program(GLuint vertex, GLuint fragment, const char* attribute, const std::string& name) {
  const GLuint program = glCreateProgram();
  glAttachShader(program, vertex);
  glAttachShader(program, fragment);
  glBindAttribLocation(program, 0, attribute);
  glLinkProgram(program);
  glDeleteShader(fragment);  // freed with the program
  GLint ok = GL_FALSE;
  glGetProgramiv(program, GL_LINK_STATUS, &ok);
  if (!ok) {
    GLint length = 0;
    glGetProgramiv(program, GL_INFO_LOG_LENGTH, &length);
    std::string log(size_t(std::max(length, 1)), '\0');
    glGetProgramInfoLog(program, GLsizei(log.size()), nullptr, log.data());
    glDeleteProgram(program);
    throw Error(ErrorKind::Internal, "GLSL ES link of " + name + " failed: " + log.c_str());
  }
  return program;
}

TextureHandle GlesBackend::create_texture(uint32_t width, uint32_t height, TexelFormat format) {
  current();
  if (width == 0 || height == 0) {
    throw Error(ErrorKind::Internal, "create_texture: empty texture " + std::to_string(width) + "x" + std::to_string(height));
  }
  if (width > uint32_t(max_texture_size_) || height > uint32_t(max_texture_size_)) {
    throw Error(ErrorKind::BadInput, "a " + std::to_string(width) + "x" + std::to_string(height) +
                                         " texture exceeds GL_MAX_TEXTURE_SIZE (" + std::to_string(max_texture_size_) +
                                         "): the scene is too large for this context");
  }
  if (format == TexelFormat::SRGBA8) {
    // DeviceInfo::srgb_textures is false here: atlas_page_format() never asks for it.
    throw Error(ErrorKind::Unsupported, "OpenGL ES 2.0 has no sRGB textures without GL_EXT_sRGB, which this context lacks");
  }
  Texture t;
  t.width = width;
  t.height = height;
  t.format = format;
  glGenTextures(1, &t.name);
  glBindTexture(GL_TEXTURE_2D, t.name);
  // NEAREST, no mipmaps, clamped: complete for float and non-power-of-two textures in ES 2.0.
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  switch (format) {
    case TexelFormat::RGBA32F:
      glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA, GLsizei(width), GLsizei(height), 0, GL_RGBA, GL_FLOAT, nullptr);
      break;
    case TexelFormat::R32F:  // no GL_RED in ES 2.0: LUMINANCE reads back as (L, L, L, 1), .r = L
      glTexImage2D(GL_TEXTURE_2D, 0, GL_LUMINANCE, GLsizei(width), GLsizei(height), 0, GL_LUMINANCE, GL_FLOAT, nullptr);
      break;
    case TexelFormat::RGBA8:
      glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA, GLsizei(width), GLsizei(height), 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
      break;
    case TexelFormat::SRGBA8: break;  // refused above
  }
  try {
    check_gl("glTexImage2D");
  } catch (...) {
    glDeleteTextures(1, &t.name);
    throw;
  }
  const uint32_t id = next_texture_++;
  textures_.emplace(id, t);
  return TextureHandle{id};
}

void GlesBackend::upload(TextureHandle handle, const void* data, size_t bytes) {
  current();
  Texture& t = texture_ref(handle);
  const size_t texel = texel_bytes(t.format);
  const size_t row_bytes = size_t(t.width) * texel;
  const size_t total = row_bytes * t.height;
  if (bytes > total) {
    throw Error(ErrorKind::Internal, "upload of " + std::to_string(bytes) + " bytes into a texture of " +
                                         std::to_string(total) + " bytes");
  }
  if (bytes % texel != 0) throw Error(ErrorKind::Internal, "upload of " + std::to_string(bytes) + " bytes: not whole texels");
  if (bytes == 0) return;
  if (!data) throw Error(ErrorKind::Internal, "upload: no data");
  const auto start = Clock::now();
  const GLenum format = t.format == TexelFormat::R32F ? GL_LUMINANCE : GL_RGBA;
  const GLenum type = t.format == TexelFormat::RGBA8 ? GL_UNSIGNED_BYTE : GL_FLOAT;
  glBindTexture(GL_TEXTURE_2D, t.name);
  const size_t texels = bytes / texel;
  const size_t full_rows = texels / t.width;
  const size_t tail = texels - full_rows * t.width;
  if (full_rows > 0) {
    glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, GLsizei(t.width), GLsizei(full_rows), format, type, data);
  }
  if (tail > 0) {
    glTexSubImage2D(GL_TEXTURE_2D, 0, 0, GLint(full_rows), GLsizei(tail), 1, format, type,
                    static_cast<const char*>(data) + full_rows * row_bytes);
  }
  check_gl("glTexSubImage2D");
  pending_upload_ms_ += elapsed_ms(start);
}

void GlesBackend::destroy(TextureHandle handle) {
  const auto it = textures_.find(handle.id);
  if (it == textures_.end()) return;
  current();
  glDeleteTextures(1, &it->second.name);
  textures_.erase(it);
}

PassHandle GlesBackend::create_pass(const PassDesc& desc) {
  current();
  const std::string name = desc.shader.name();
  const char* embedded = desc.shader.source().es;
  if (!embedded) {
    throw Error(ErrorKind::Unsupported, "shader " + name + " has no GLSL ES 1.00 version (it needs bit operations): "
                                        "Vulkan only");
  }
  // The OpenGL ES 2.0 constraints first, on the source itself: one colour output, no storage.
  const std::string code = strip_comments(embedded);
  const EsInterface es = reflect_es_source(code);
  if (es.color_outputs > 1) {
    throw Error(ErrorKind::Constraint, "shader " + name + " writes " + std::to_string(es.color_outputs) +
                                           " colour outputs; OpenGL ES 2.0 passes write exactly one RGBA8 attachment");
  }
  if (!es.storage.empty()) {
    throw Error(ErrorKind::Constraint, "shader " + name + " uses storage resources (" + es.storage.front() +
                                           "); OpenGL ES 2.0 shaders cannot write storage buffers or images");
  }
  check_pass_desc(desc);

  // Specialisation: #defines right after the #version line.
  std::string defines;
  for (const Specialization& s : desc.specialization) {
    const char* define = define_name(s.id);
    if (!define) {
      throw Error(ErrorKind::Internal, "pass " + name + ": specialization constant " + std::to_string(s.id) +
                                           " has no #define on GLES");
    }
    defines += std::string("#define ") + define + " " + std::to_string(s.value) + "\n";
  }
  std::string source = embedded;
  const size_t version_end = source.find('\n');
  source.insert(version_end == std::string::npos ? source.size() : version_end + 1, defines);

  const GLuint fragment = compile(GL_FRAGMENT_SHADER, source, name);
  Pass pass;
  pass.desc = desc;
  pass.program = link_program(vertex_shader_, fragment, "a_position", name);  // frees `fragment`
  auto fail = [&](ErrorKind kind, const std::string& message) {
    glDeleteProgram(pass.program);
    throw Error(kind, message);
  };

  // Reflection on the linked program: the active samplers, counted against the ES 2.0 limit.
  const std::map<std::string, int> slots = sampler_slots(code);
  GLint active = 0, max_length = 0;
  glGetProgramiv(pass.program, GL_ACTIVE_UNIFORMS, &active);
  glGetProgramiv(pass.program, GL_ACTIVE_UNIFORM_MAX_LENGTH, &max_length);
  std::vector<std::string> sampler_names;
  std::vector<char> buffer(size_t(std::max(max_length, 1)) + 1);
  for (GLint i = 0; i < active; ++i) {
    GLint size = 0;
    GLenum type = 0;
    GLsizei length = 0;
    glGetActiveUniform(pass.program, GLuint(i), GLsizei(buffer.size()), &length, &size, &type, buffer.data());
    const std::string uniform(buffer.data(), size_t(length));
    if (type == GL_SAMPLER_2D || type == GL_SAMPLER_CUBE) {
      for (GLint k = 0; k < size; ++k) sampler_names.push_back(uniform);
    } else if (uniform.rfind("u_params", 0) == 0) {
      pass.params_size = size;
    }
  }
  const int sampler_count = int(sampler_names.size());
  if (sampler_count > MOBIRT_MAX_SAMPLED_TEXTURES || sampler_count > max_texture_units_) {
    fail(ErrorKind::Constraint, "shader " + name + " samples " + std::to_string(sampler_count) +
                                    " textures; at most " + std::to_string(MOBIRT_MAX_SAMPLED_TEXTURES) +
                                    " are allowed (GL_MAX_TEXTURE_IMAGE_UNITS of OpenGL ES 2.0)");
  }
  pass.params_location = glGetUniformLocation(pass.program, "u_params");
  // Texture unit i serves desc.texture_bindings[i]; every active sampler must have its slot bound.
  glUseProgram(pass.program);
  pass.samplers.resize(desc.texture_bindings.size());
  std::set<int> bound_slots;
  for (size_t i = 0; i < desc.texture_bindings.size(); ++i) {
    SamplerUniform& s = pass.samplers[i];
    s.slot = int(desc.texture_bindings[i]);
    bound_slots.insert(s.slot);
    for (const auto& [sampler, slot] : slots) {
      if (slot != s.slot) continue;
      s.texture_location = glGetUniformLocation(pass.program, (sampler + ".tex").c_str());
      s.inv_size_location = glGetUniformLocation(pass.program, (sampler + ".inv_size").c_str());
      if (s.texture_location >= 0) glUniform1i(s.texture_location, GLint(i));
    }
  }
  for (const std::string& sampler : sampler_names) {
    const std::string base = sampler.substr(0, sampler.find('.'));
    const auto it = slots.find(base);
    if (it == slots.end() || !bound_slots.count(it->second)) {
      fail(ErrorKind::Internal, "pass " + name + ": the shader samples " + sampler +
                                    " but the pass binds no texture at its slot");
    }
  }
  glUseProgram(0);
  try {
    check_gl("create_pass");
  } catch (...) {
    glDeleteProgram(pass.program);
    throw;
  }
  const uint32_t id = next_pass_++;
  passes_.emplace(id, std::move(pass));
  return PassHandle{id};
}

void GlesBackend::destroy(PassHandle handle) {
  const auto it = passes_.find(handle.id);
  if (it == passes_.end()) return;
  current();
  glDeleteProgram(it->second.program);
  passes_.erase(it);
}

void GlesBackend::ensure_target(uint32_t width, uint32_t height) {
  if (target_ && target_width_ == width && target_height_ == height) return;
  if (target_) glDeleteTextures(1, &target_);
  glGenTextures(1, &target_);
  glBindTexture(GL_TEXTURE_2D, target_);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA, GLsizei(width), GLsizei(height), 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
  glBindFramebuffer(GL_FRAMEBUFFER, framebuffer_);
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, target_, 0);
  const GLenum status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
  if (status != GL_FRAMEBUFFER_COMPLETE) {
    throw Error(ErrorKind::Internal, "the RGBA8 framebuffer of " + std::to_string(width) + "x" +
                                         std::to_string(height) + " is incomplete (status " + std::to_string(status) + ")");
  }
  check_gl("render target");
  target_width_ = width;
  target_height_ = height;
}

PassTiming GlesBackend::run_pass(PassHandle handle, std::span<const TextureHandle> textures,
                                 std::span<const float> uniforms, uint32_t width, uint32_t count,
                                 std::span<uint32_t> out) {
  const auto wall_start = Clock::now();
  current();
  Pass& pass = pass_ref(handle);
  std::vector<Texture*> bound;
  const uint32_t height = start_run_pass(
      pass.desc, textures, uniforms.size(), width, count, out.size(), uint32_t(max_texture_size_),
      "GL_MAX_TEXTURE_SIZE", [&](TextureHandle t) -> Texture& { return texture_ref(t); }, bound);
  if (height == 0) return empty_pass_timing(pending_upload_ms_, wall_start);
  const std::string name = pass.desc.shader.name();
  PassTiming timing;
  timing.upload_ms = pending_upload_ms_;
  ensure_target(width, height);

  glUseProgram(pass.program);
  if (pass.params_location >= 0 && pass.params_size > 0) {
    // Zero-filled like the Vulkan uniform block; only the active part of the array is loaded.
    std::vector<float> params(size_t(MOBIRT_MAX_PARAM_VEC4S) * 4, 0.0f);
    std::copy(uniforms.begin(), uniforms.end(), params.begin());
    glUniform4fv(pass.params_location, std::min<GLint>(pass.params_size, MOBIRT_MAX_PARAM_VEC4S), params.data());
  }
  for (size_t i = 0; i < bound.size(); ++i) {
    glActiveTexture(GLenum(GL_TEXTURE0 + i));
    glBindTexture(GL_TEXTURE_2D, bound[i]->name);
    const GLint filter = pass.desc.linear(pass.desc.texture_bindings[i]) ? GL_LINEAR : GL_NEAREST;
    if (bound[i]->filter != filter) {  // filtering is the texture object's state in ES 2.0
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, filter);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, filter);
      bound[i]->filter = filter;
    }
    const SamplerUniform& s = pass.samplers[i];
    if (s.inv_size_location >= 0) {
      glUniform2f(s.inv_size_location, 1.0f / float(bound[i]->width), 1.0f / float(bound[i]->height));
    }
  }
  glActiveTexture(GL_TEXTURE0);
  glBindFramebuffer(GL_FRAMEBUFFER, framebuffer_);
  glViewport(0, 0, GLsizei(width), GLsizei(height));
  glBindBuffer(GL_ARRAY_BUFFER, vertex_buffer_);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 2, GL_FLOAT, GL_FALSE, 0, nullptr);
  check_gl(("pass " + name + " set-up").c_str());

  // The pass on the CPU clock: everything before it has finished (glFinish after each pass and
  // upload), so the time between two glFinish is the pass's own.
  glFinish();
  const auto gpu_start = Clock::now();
  glDrawArrays(GL_TRIANGLES, 0, 3);
  glFinish();
  timing.gpu_ms = elapsed_ms(gpu_start);

  const auto read_start = Clock::now();
  readback_.resize(size_t(width) * height * 4);
  glReadPixels(0, 0, GLsizei(width), GLsizei(height), GL_RGBA, GL_UNSIGNED_BYTE, readback_.data());
  check_gl(("pass " + name + " glReadPixels").c_str());
  std::memcpy(out.data(), readback_.data(), size_t(count) * 4);
  timing.readback_ms = elapsed_ms(read_start);
  timing.bytes_read = uint64_t(count) * 4;
  glDisableVertexAttribArray(0);
  glUseProgram(0);
  pending_upload_ms_ = 0.0;
  timing.wall_ms = elapsed_ms(wall_start);
  return timing;
}

void GlesBackend::prepare_raster(uint32_t width, uint32_t height) {
  Raster& r = raster_;
  if (!r.program) {
    const GLuint vertex = compile(GL_VERTEX_SHADER, es_raster_vert, "raster.vert");
    GLuint fragment = 0;
    try {
      fragment = compile(GL_FRAGMENT_SHADER, es_raster_frag, "raster.frag");
    } catch (...) {
      glDeleteShader(vertex);
      throw;
    }
    GLuint program = 0;
    try {
      program = link_program(vertex, fragment, "a_vertex", "raster.vert + raster.frag");
    } catch (...) {
      glDeleteShader(vertex);
      throw;
    }
    glDeleteShader(vertex);  // freed with the program
    r.program = program;
    r.eye = glGetUniformLocation(program, "u_eye");
    r.right = glGetUniformLocation(program, "u_right");
    r.up = glGetUniformLocation(program, "u_up");
    r.forward = glGetUniformLocation(program, "u_forward");
    r.projection = glGetUniformLocation(program, "u_projection");
    glGenBuffers(1, &r.vertices);
    glGenFramebuffers(1, &r.framebuffer);
    check_gl("raster program");
  }
  if (r.colour && r.width == width && r.height == height) return;
  if (width > uint32_t(max_texture_size_) || height > uint32_t(max_texture_size_)) {
    throw Error(ErrorKind::BadInput, "--size " + std::to_string(width) + "x" + std::to_string(height) +
                                         " is larger than GL_MAX_TEXTURE_SIZE (" + std::to_string(max_texture_size_) +
                                         "): use --primary trace");
  }
  r.width = r.height = 0;  // no target until the new one is complete (a failed one is made again)
  if (!r.colour) glGenTextures(1, &r.colour);
  if (!r.depth) glGenRenderbuffers(1, &r.depth);
  glBindTexture(GL_TEXTURE_2D, r.colour);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA, GLsizei(width), GLsizei(height), 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
  glBindRenderbuffer(GL_RENDERBUFFER, r.depth);
  glRenderbufferStorage(GL_RENDERBUFFER, depth24_ ? GL_DEPTH_COMPONENT24_OES : GL_DEPTH_COMPONENT16, GLsizei(width),
                        GLsizei(height));
  glBindFramebuffer(GL_FRAMEBUFFER, r.framebuffer);
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, r.colour, 0);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, r.depth);
  const GLenum status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
  if (status != GL_FRAMEBUFFER_COMPLETE) {
    throw Error(ErrorKind::Internal, "the raster framebuffer of " + std::to_string(width) + "x" +
                                         std::to_string(height) + " is incomplete (status " + std::to_string(status) + ")");
  }
  check_gl("raster target");
  r.width = width;
  r.height = height;
}

PassTiming GlesBackend::run_raster(std::span<const float> vertices, const RasterView& view, uint32_t width,
                                   uint32_t height, std::span<uint32_t> out) {
  const auto wall_start = Clock::now();
  current();
  if (out.size() != size_t(width) * height) {
    throw Error(ErrorKind::Internal, "run_raster: the output holds " + std::to_string(out.size()) + " texels, not " +
                                         std::to_string(width) + "x" + std::to_string(height));
  }
  if (vertices.size() % 12 != 0) {
    throw Error(ErrorKind::Internal, "run_raster: the vertices are not whole triangles of 4 floats a vertex");
  }
  PassTiming timing;
  timing.upload_ms = pending_upload_ms_;
  pending_upload_ms_ = 0.0;
  if (width == 0 || height == 0) {
    timing.wall_ms = elapsed_ms(wall_start);
    return timing;
  }
  prepare_raster(width, height);
  const Raster& r = raster_;
  const auto upload_start = Clock::now();
  glBindBuffer(GL_ARRAY_BUFFER, r.vertices);
  glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(vertices.size_bytes()), vertices.data(), GL_STREAM_DRAW);
  glFinish();
  timing.upload_ms += elapsed_ms(upload_start);
  glUseProgram(r.program);
  glUniform4fv(r.eye, 1, view.eye);
  glUniform4fv(r.right, 1, view.right);
  glUniform4fv(r.up, 1, view.up);
  glUniform4fv(r.forward, 1, view.forward);
  glUniform4fv(r.projection, 1, view.projection);
  glBindFramebuffer(GL_FRAMEBUFFER, r.framebuffer);
  glViewport(0, 0, GLsizei(width), GLsizei(height));
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 4, GL_FLOAT, GL_FALSE, 0, nullptr);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDepthMask(GL_TRUE);
  glClearColor(0.0f, 0.0f, 0.0f, 0.0f);  // index + 1 = 0: no triangle
  glClearDepthf(1.0f);
  check_gl("raster set-up");

  const auto gpu_start = Clock::now();
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glDrawArrays(GL_TRIANGLES, 0, GLsizei(vertices.size() / 4));
  glFinish();
  timing.gpu_ms = elapsed_ms(gpu_start);
  glDisable(GL_DEPTH_TEST);  // the fragment passes draw without one

  const auto read_start = Clock::now();
  glReadPixels(0, 0, GLsizei(width), GLsizei(height), GL_RGBA, GL_UNSIGNED_BYTE, out.data());
  glDisableVertexAttribArray(0);
  glUseProgram(0);
  check_gl("raster glReadPixels");
  timing.readback_ms = elapsed_ms(read_start);
  timing.bytes_read = uint64_t(out.size()) * 4;
  timing.wall_ms = elapsed_ms(wall_start);
  return timing;
}

std::vector<std::string> GlesBackend::take_debug_messages() {
  std::lock_guard lock(sink_.mutex);
  std::vector<std::string> result;
  result.swap(sink_.messages);
  return result;
}

}  // namespace

std::unique_ptr<Backend> create_gles_backend(const BackendOptions& options) {
  return std::make_unique<GlesBackend>(options);
}

}  // namespace mobirt
