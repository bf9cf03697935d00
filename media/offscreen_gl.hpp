// media layer — an off-screen OpenGL context for MuJoCo's renderer, with no display.
//
// MuJoCo's mjr_* functions draw with whatever GL context is current on the calling thread;
// they never create one. This class is that context. It is an interface with one backend
// today, OSMesa (Mesa's software rasteriser, llvmpipe): it needs no display and no GPU and
// is what CI machines have. An EGL backend (headless GPU) would be a second subclass made by
// make_offscreen_gl; nothing outside this file would change. It is not built because it
// cannot be tested here.
//
// Which GL library MuJoCo 2.2.2 calls is decided once per process, at the first
// mjr_makeContext, by its glad loader (src/render/glad/loader.cc: initialised once), which
// takes the first of eglGetProcAddress / OSMesaGetProcAddress / glXGetProcAddressARB that
// the process already has. omnitwin_media links libOSMesa; if libEGL or libGL is loaded too,
// MuJoCo binds to those and exits or crashes (tried), so the OSMesa backend refuses with a
// clear error then. The context owns its colour buffer (the default framebuffer); MuJoCo
// renders into its own offscreen FBO anyway.
//
// Threading: a context is current on one thread at a time; create, use and destroy it on
// the same thread (or call make_current() after moving to another). Not real-time safe.
#pragma once

#include <memory>
#include <string>

namespace omnitwin::media {

enum class GlBackend {
  osmesa,  // Mesa software rendering; always available where libOSMesa is installed
};

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
  std::string describe() const;

 protected:
  OffscreenGl() = default;
};

// Creates a context of the backend with a width x height [pixels] default framebuffer
// (>= 1 each) and makes it current on the calling thread. Throws std::runtime_error with
// the backend's name if it cannot be created. Not real-time safe (allocates).
std::unique_ptr<OffscreenGl> make_offscreen_gl(int width, int height,
                                               GlBackend backend = GlBackend::osmesa);

}  // namespace omnitwin::media
