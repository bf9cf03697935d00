// media layer — OSMesa implementation of OffscreenGl (see offscreen_gl.hpp).
#include "media/offscreen_gl.hpp"

#include <GL/osmesa.h>
#include <dlfcn.h>

#include <stdexcept>
#include <string>
#include <vector>

namespace omnitwin::media {
namespace {

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
    make_current();
  }

  void make_current() override {
    if (OSMesaGetCurrentContext() == ctx_.get()) return;
    if (!OSMesaMakeCurrent(ctx_.get(), buffer_.data(), GL_UNSIGNED_BYTE, width_, height_))
      throw std::runtime_error("OSMesa: cannot make the GL context current (OSMesaMakeCurrent)");
  }

  int width() const override { return width_; }
  int height() const override { return height_; }

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

std::string gl_string(GLenum name) {
  const auto* s = reinterpret_cast<const char*>(glGetString(name));
  return s ? s : "?";
}

}  // namespace

std::string OffscreenGl::describe() const {
  return gl_string(GL_VENDOR) + " / " + gl_string(GL_RENDERER) + " / OpenGL " +
         gl_string(GL_VERSION);
}

std::unique_ptr<OffscreenGl> make_offscreen_gl(int width, int height, GlBackend backend) {
  if (width < 1 || height < 1)
    throw std::runtime_error("off-screen GL: framebuffer size must be positive, got " +
                             std::to_string(width) + "x" + std::to_string(height));
  switch (backend) {
    case GlBackend::osmesa:
      check_no_other_gl_loaded();
      return std::make_unique<OsmesaGl>(width, height);
  }
  throw std::runtime_error("off-screen GL: unknown backend");
}

}  // namespace omnitwin::media
