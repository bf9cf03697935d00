// media layer — an off-screen OpenGL context for MuJoCo's renderer, with no display.
//
// MuJoCo's mjr_* functions draw with whatever GL context is current on the calling thread;
// they never create one. This class is that context. It is an interface with one backend
// today, OSMesa (Mesa's software rasteriser, llvmpipe): it needs no display and no GPU and
// is what CI machines have. An EGL backend (headless GPU) would be a second subclass made by
// make_offscreen_gl. Two backends:
//  - osmesa: Mesa's OSMesa (llvmpipe). Needs no display and no GPU; what CI machines have.
//  - egl: EGL with no window and no pbuffer (EGL_KHR_surfaceless_context). The display is a
//    hardware EGL device if there is one (EGL_EXT_platform_device: a GPU, headless), else
//    Mesa's surfaceless platform (EGL_MESA_platform_surfaceless: llvmpipe again, so it works
//    without a GPU too). libEGL.so.1 is dlopen()ed, never linked: see below.
// The backend is chosen by the caller; gl_backend_from_env() reads OMNITWIN_GL=osmesa|egl
// (unset or empty: osmesa).
//
// Which GL library MuJoCo 2.2.2 calls is decided once per process, at the first
// mjr_makeContext, by its glad loader (src/render/glad/loader.cc: initialised once), which
// takes the first of eglGetProcAddress / OSMesaGetProcAddress / glXGetProcAddressARB that
// the process already has, EGL first. omnitwin_media links libOSMesa; if libEGL or libGL is
// loaded too, MuJoCo binds to those and exits or crashes (tried). Hence:
//  - the EGL backend loads libEGL (dlopen, RTLD_GLOBAL) only when it is asked for, and
//    MuJoCo then binds to eglGetProcAddress, which also works with libOSMesa present;
//  - one process uses one backend: OSMesa refuses once libEGL/libGL is loaded, EGL refuses
//    once an OSMesa context was made in the process (MuJoCo may already be bound to it).
//    Tests of the EGL backend run in their own process (tests/media/egl_render_check).
// The OSMesa context owns its colour buffer (the default framebuffer); the EGL context has
// no default framebuffer at all. MuJoCo renders into its own offscreen FBO
// (mjr_setBuffer(mjFB_OFFSCREEN), sized by the model's offwidth/offheight) either way.
//
// Threading: a context is current on one thread at a time; create, use and destroy it on
// the same thread (or call make_current() after moving to another). Not real-time safe.
#pragma once

#include <memory>
#include <string>

namespace omnitwin::media {

enum class GlBackend {
  osmesa,  // Mesa software rendering; always available where libOSMesa is installed
  egl,     // EGL, surfaceless: a GPU through EGL_EXT_platform_device, else Mesa llvmpipe
};

// "osmesa" or "egl"; throws std::invalid_argument naming the accepted values otherwise.
GlBackend gl_backend_from_name(const std::string& name);
// The name of a backend ("osmesa", "egl").
const char* gl_backend_name(GlBackend backend);
// The backend named by the environment variable OMNITWIN_GL ("osmesa" or "egl"); osmesa if
// it is unset or empty. Throws std::invalid_argument for any other value.
GlBackend gl_backend_from_env();

class OffscreenGl {
 public:
  virtual ~OffscreenGl() = default;
  OffscreenGl(const OffscreenGl&) = delete;
  OffscreenGl& operator=(const OffscreenGl&) = delete;

  // Makes this context current on the calling thread. Throws std::runtime_error if the
  // backend refuses. Cheap when already current.
  virtual void make_current() = 0;

  // Size of the default framebuffer the context owns [pixels].
  virtual int width() const = 0;
  virtual int height() const = 0;

  // GL_VENDOR / GL_RENDERER / GL_VERSION of the current context, e.g. for log lines.
  virtual std::string describe() const = 0;

 protected:
  OffscreenGl() = default;
};

// Creates a context of the backend with a width x height [pixels] default framebuffer
// (>= 1 each) and makes it current on the calling thread. Throws std::runtime_error with
// the backend's name if it cannot be created (library missing, no usable display, or the
// other backend already in use in this process). Not real-time safe (allocates).
std::unique_ptr<OffscreenGl> make_offscreen_gl(int width, int height,
                                               GlBackend backend = GlBackend::osmesa);

}  // namespace omnitwin::media
