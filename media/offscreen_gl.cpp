// media layer — OSMesa and EGL implementations of OffscreenGl (see offscreen_gl.hpp).
#include "media/offscreen_gl.hpp"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GL/osmesa.h>
#include <dlfcn.h>

#include <atomic>
#include <cstdlib>
#include <cstring>
#include <cstdio>
#include <stdexcept>
#include <type_traits>
#include <string>
#include <vector>

namespace omnitwin::media {
namespace {

// Set once an OSMesa context was made in this process: MuJoCo may be bound to OSMesa then.
std::atomic<bool> g_osmesa_used{false};

std::string gl_string(GLenum name) {
  const auto* s = reinterpret_cast<const char*>(glGetString(name));
  return s ? s : "?";
}

// Owning handle of an OSMesa context (OSMesaDestroyContext on release).
struct OsmesaDeleter {
  void operator()(osmesa_context* c) const { OSMesaDestroyContext(c); }
};
using OsmesaPtr = std::unique_ptr<osmesa_context, OsmesaDeleter>;

class OsmesaGl final : public OffscreenGl {
 public:
  OsmesaGl(int width, int height)
      : width_(width), height_(height), buffer_(static_cast<size_t>(width) * height * 4) {
    // RGBA colour, 24-bit depth, 8-bit stencil (MuJoCo uses stencil for reflections).
    ctx_.reset(OSMesaCreateContextExt(OSMESA_RGBA, 24, 8, 0, nullptr));
    if (!ctx_) throw std::runtime_error("OSMesa: cannot create a GL context (OSMesaCreateContextExt)");
    g_osmesa_used = true;
    make_current();
  }

  void make_current() override {
    if (OSMesaGetCurrentContext() == ctx_.get()) return;
    if (!OSMesaMakeCurrent(ctx_.get(), buffer_.data(), GL_UNSIGNED_BYTE, width_, height_))
      throw std::runtime_error("OSMesa: cannot make the GL context current (OSMesaMakeCurrent)");
  }

  int width() const override { return width_; }
  int height() const override { return height_; }
  std::string describe() const override {
    return gl_string(GL_VENDOR) + " / " + gl_string(GL_RENDERER) + " / OpenGL " + gl_string(GL_VERSION) + " (OSMesa)";
  }

 private:
  int width_, height_;
  std::vector<unsigned char> buffer_;  // the default framebuffer's colour buffer (RGBA)
  OsmesaPtr ctx_;                      // declared last: destroyed before the buffer
};

// MuJoCo 2.2.2 binds its GL entry points once per process, preferring EGL or GLX when their
// libraries are loaded; with an OSMesa context current that ends in "gladLoadGL error" and
// exit(), or a crash (tried on Debian 12). Refuse cleanly instead.
void check_no_other_gl_loaded() {
  for (const char* sym : {"eglGetProcAddress", "glXGetProcAddressARB"})
    if (::dlsym(RTLD_DEFAULT, sym))
      throw std::runtime_error(std::string("OSMesa rendering: ") + sym +
                               " is loaded in this process (libEGL/libGL linked); MuJoCo would "
                               "bind its GL calls to it instead of OSMesa");
}

// ---- EGL ---------------------------------------------------------------------------------

// The EGL entry points used, resolved from libEGL.so.1 loaded at run time (never linked, so
// that a process rendering with OSMesa never has libEGL). Loaded once per process, never
// unloaded; RTLD_GLOBAL so that MuJoCo's GL loader finds eglGetProcAddress.
struct EglApi {
  PFNEGLGETPROCADDRESSPROC GetProcAddress = nullptr;
  PFNEGLQUERYSTRINGPROC QueryString = nullptr;
  PFNEGLGETERRORPROC GetError = nullptr;
  PFNEGLINITIALIZEPROC Initialize = nullptr;
  PFNEGLCHOOSECONFIGPROC ChooseConfig = nullptr;
  PFNEGLBINDAPIPROC BindAPI = nullptr;
  PFNEGLCREATECONTEXTPROC CreateContext = nullptr;
  PFNEGLDESTROYCONTEXTPROC DestroyContext = nullptr;
  PFNEGLMAKECURRENTPROC MakeCurrent = nullptr;
  PFNEGLGETCURRENTCONTEXTPROC GetCurrentContext = nullptr;
  // Extensions (through GetProcAddress); may be null.
  PFNEGLGETPLATFORMDISPLAYEXTPROC GetPlatformDisplayEXT = nullptr;
  PFNEGLQUERYDEVICESEXTPROC QueryDevicesEXT = nullptr;
  PFNEGLQUERYDEVICESTRINGEXTPROC QueryDeviceStringEXT = nullptr;
  // glGetString of the EGL context (the process's own glGetString may be OSMesa's).
  const GLubyte* (*GetString)(GLenum) = nullptr;
  std::string error;  // why loading failed; empty when loaded
};

bool has_extension(const char* list, const char* name) {
  if (!list) return false;
  const size_t n = std::strlen(name);
  for (const char* p = list; (p = std::strstr(p, name)) != nullptr; p += n)
    if ((p == list || p[-1] == ' ') && (p[n] == ' ' || p[n] == '\0')) return true;
  return false;
}

const EglApi& egl_api() {
  static const EglApi api = [] {
    EglApi a;
    void* lib = ::dlopen("libEGL.so.1", RTLD_NOW | RTLD_GLOBAL);
    if (!lib) {
      const char* e = ::dlerror();
      a.error = std::string("cannot load libEGL.so.1 (") + (e ? e : "?") + "); install libegl1";
      return a;
    }
    auto sym = [&](auto& fn, const char* name) {
      fn = reinterpret_cast<std::remove_reference_t<decltype(fn)>>(::dlsym(lib, name));
      if (!fn && a.error.empty()) a.error = std::string("libEGL.so.1 lacks ") + name;
    };
    sym(a.GetProcAddress, "eglGetProcAddress");
    sym(a.QueryString, "eglQueryString");
    sym(a.GetError, "eglGetError");
    sym(a.Initialize, "eglInitialize");
    sym(a.ChooseConfig, "eglChooseConfig");
    sym(a.BindAPI, "eglBindAPI");
    sym(a.CreateContext, "eglCreateContext");
    sym(a.DestroyContext, "eglDestroyContext");
    sym(a.MakeCurrent, "eglMakeCurrent");
    sym(a.GetCurrentContext, "eglGetCurrentContext");
    if (!a.error.empty()) return a;
    auto ext = [&](auto& fn, const char* name) {
      fn = reinterpret_cast<std::remove_reference_t<decltype(fn)>>(a.GetProcAddress(name));
    };
    ext(a.GetPlatformDisplayEXT, "eglGetPlatformDisplayEXT");
    ext(a.QueryDevicesEXT, "eglQueryDevicesEXT");
    ext(a.QueryDeviceStringEXT, "eglQueryDeviceStringEXT");
    ext(a.GetString, "glGetString");
    return a;
  }();
  return api;
}

std::string egl_error(const EglApi& a, const char* what) {
  char code[16];
  std::snprintf(code, sizeof code, "0x%04X", static_cast<unsigned>(a.GetError()));
  return std::string("EGL: ") + what + " failed (error " + code + ")";
}

// An initialised EGL display with no window system: the first hardware EGL device (a GPU),
// else Mesa's surfaceless platform. Displays live for the process (eglTerminate would
// destroy every context on them); made once. Empty optional-like: nullptr + reason.
struct EglDisplayChoice {
  EGLDisplay display = EGL_NO_DISPLAY;
  std::string kind;   // "device" or "surfaceless"
  std::string error;  // why none could be had
};

EGLDisplay try_initialize(const EglApi& a, EGLenum platform, void* native) {
  EGLDisplay d = a.GetPlatformDisplayEXT(platform, native, nullptr);
  if (d == EGL_NO_DISPLAY) return d;
  EGLint major = 0, minor = 0;
  return a.Initialize(d, &major, &minor) ? d : EGL_NO_DISPLAY;
}

const EglDisplayChoice& egl_display() {
  static const EglDisplayChoice choice = [] {
    EglDisplayChoice c;
    const EglApi& a = egl_api();
    const char* client = a.QueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
    if (!a.GetPlatformDisplayEXT || !has_extension(client, "EGL_EXT_platform_base")) {
      c.error = "EGL: eglGetPlatformDisplayEXT is not available (EGL_EXT_platform_base)";
      return c;
    }
    // A GPU: an EGL device that is not Mesa's software device.
    if (has_extension(client, "EGL_EXT_platform_device") && a.QueryDevicesEXT) {
      EGLDeviceEXT devices[16];
      EGLint n = 0;
      if (a.QueryDevicesEXT(16, devices, &n))
        for (EGLint i = 0; i < n; ++i) {
          const char* dev_ext = a.QueryDeviceStringEXT ? a.QueryDeviceStringEXT(devices[i], EGL_EXTENSIONS) : nullptr;
          if (has_extension(dev_ext, "EGL_MESA_device_software")) continue;
          if (EGLDisplay d = try_initialize(a, EGL_PLATFORM_DEVICE_EXT, devices[i]); d != EGL_NO_DISPLAY) {
            c.display = d;
            c.kind = "device";
            return c;
          }
        }
    }
    if (has_extension(client, "EGL_MESA_platform_surfaceless")) {
      if (EGLDisplay d = try_initialize(a, EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY); d != EGL_NO_DISPLAY) {
        c.display = d;
        c.kind = "surfaceless";
        return c;
      }
    }
    c.error = "EGL: no usable display (no GPU EGL device, and Mesa's surfaceless platform is "
              "missing or failed; install libegl-mesa0)";
    return c;
  }();
  return choice;
}

class EglGl final : public OffscreenGl {
 public:
  EglGl(int width, int height) : width_(width), height_(height) {
    const EglApi& a = egl_api();
    if (!a.error.empty()) throw std::runtime_error("EGL: " + a.error);
    const EglDisplayChoice& dc = egl_display();
    if (dc.display == EGL_NO_DISPLAY) throw std::runtime_error(dc.error);
    display_ = dc.display;
    if (!has_extension(a.QueryString(display_, EGL_EXTENSIONS), "EGL_KHR_surfaceless_context"))
      throw std::runtime_error("EGL: the display lacks EGL_KHR_surfaceless_context");
    if (!a.BindAPI(EGL_OPENGL_API)) throw std::runtime_error(egl_error(a, "eglBindAPI(EGL_OPENGL_API)"));
    // No surface is ever made, so the config only has to be one of desktop GL; MuJoCo makes
    // its own colour, depth and stencil buffers (its offscreen FBO).
    const EGLint attribs[] = {EGL_RED_SIZE, 8, EGL_GREEN_SIZE, 8, EGL_BLUE_SIZE, 8,
                              EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_SURFACE_TYPE, 0, EGL_NONE};
    EGLConfig config = nullptr;
    EGLint n = 0;
    if (!a.ChooseConfig(display_, attribs, &config, 1, &n) || n < 1)
      throw std::runtime_error(egl_error(a, "eglChooseConfig (8-bit RGB, desktop OpenGL)"));
    // Compatibility profile (the default): MuJoCo 2.2 uses fixed-function GL.
    ctx_ = a.CreateContext(display_, config, EGL_NO_CONTEXT, nullptr);
    if (ctx_ == EGL_NO_CONTEXT) throw std::runtime_error(egl_error(a, "eglCreateContext"));
    try {
      make_current();
    } catch (...) {
      a.DestroyContext(display_, ctx_);
      throw;
    }
  }

  ~EglGl() override {
    const EglApi& a = egl_api();
    if (a.GetCurrentContext() == ctx_) a.MakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    a.DestroyContext(display_, ctx_);
  }

  void make_current() override {
    const EglApi& a = egl_api();
    if (a.GetCurrentContext() == ctx_) return;
    if (!a.MakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx_))
      throw std::runtime_error(egl_error(a, "eglMakeCurrent (surfaceless)"));
  }

  int width() const override { return width_; }
  int height() const override { return height_; }

  std::string describe() const override {
    const EglApi& a = egl_api();
    auto str = [&](GLenum name) {
      const auto* s = a.GetString ? reinterpret_cast<const char*>(a.GetString(name)) : nullptr;
      return std::string(s ? s : "?");
    };
    return str(GL_VENDOR) + " / " + str(GL_RENDERER) + " / OpenGL " + str(GL_VERSION) + " (EGL " +
           egl_display().kind + ")";
  }

 private:
  int width_, height_;  // nominal: there is no default framebuffer
  EGLDisplay display_ = EGL_NO_DISPLAY;
  EGLContext ctx_ = EGL_NO_CONTEXT;
};

}  // namespace

GlBackend gl_backend_from_name(const std::string& name) {
  if (name == "osmesa") return GlBackend::osmesa;
  if (name == "egl") return GlBackend::egl;
  throw std::invalid_argument("unknown GL backend \"" + name + "\" (expected \"osmesa\" or \"egl\")");
}

const char* gl_backend_name(GlBackend backend) {
  return backend == GlBackend::egl ? "egl" : "osmesa";
}

GlBackend gl_backend_from_env() {
  const char* v = std::getenv("OMNITWIN_GL");
  if (!v || !*v) return GlBackend::osmesa;
  try {
    return gl_backend_from_name(v);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("OMNITWIN_GL: ") + e.what());
  }
}

std::unique_ptr<OffscreenGl> make_offscreen_gl(int width, int height, GlBackend backend) {
  if (width < 1 || height < 1)
    throw std::runtime_error("off-screen GL: framebuffer size must be positive, got " +
                             std::to_string(width) + "x" + std::to_string(height));
  switch (backend) {
    case GlBackend::osmesa:
      check_no_other_gl_loaded();
      return std::make_unique<OsmesaGl>(width, height);
    case GlBackend::egl:
      if (g_osmesa_used)
        throw std::runtime_error("EGL rendering: an OSMesa context was already made in this process, "
                                 "and MuJoCo binds its GL calls once per process; use one backend "
                                 "per process");
      return std::make_unique<EglGl>(width, height);
  }
  throw std::runtime_error("off-screen GL: unknown backend");
}

}  // namespace omnitwin::media
