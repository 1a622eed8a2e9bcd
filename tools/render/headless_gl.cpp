// Headless OpenGL through EGL on Mesa's surfaceless platform (render/headless_gl.hpp). Steps:
// eglGetPlatformDisplayEXT(EGL_PLATFORM_SURFACELESS_MESA) -> eglInitialize -> eglBindAPI(OpenGL)
// -> a config (EGL_NO_CONFIG_KHR when offered, else any OpenGL-renderable one) -> an OpenGL 3.3
// core context -> eglMakeCurrent with no surface. Entry points through libepoxy, which also
// dispatches GL calls through eglGetProcAddress while an EGL context is current.
#include "tetrig/render/headless_gl.hpp"

#include <epoxy/egl.h>
#include <epoxy/gl.h>

#include <cstdio>
#include <stdexcept>
#include <string>

namespace tetrig::render {

namespace {

constexpr const char* kInstall =
    "needs Mesa's EGL (Debian: libegl1 libegl-mesa0 libgl1-mesa-dri; no display or GPU required)";

[[noreturn]] void fail(const std::string& step) {
  throw std::runtime_error("headless OpenGL: " + step + " (EGL error 0x" + [] {
    char hex[16];
    std::snprintf(hex, sizeof hex, "%04x", static_cast<unsigned>(eglGetError()));
    return std::string(hex);
  }() + "); " + kInstall);
}

}  // namespace

HeadlessGl::HeadlessGl() {
  if (!epoxy_has_egl()) throw std::runtime_error(std::string("headless OpenGL: libEGL could not be loaded; ") + kInstall);
  if (!epoxy_has_egl_extension(EGL_NO_DISPLAY, "EGL_MESA_platform_surfaceless") ||
      !epoxy_has_egl_extension(EGL_NO_DISPLAY, "EGL_EXT_platform_base")) {
    throw std::runtime_error(std::string("headless OpenGL: EGL lacks EGL_MESA_platform_surfaceless; ") + kInstall);
  }
  EGLDisplay display = eglGetPlatformDisplayEXT(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
  if (display == EGL_NO_DISPLAY) fail("eglGetPlatformDisplayEXT(surfaceless) failed");
  EGLint major = 0, minor = 0;
  if (!eglInitialize(display, &major, &minor)) fail("eglInitialize failed");
  display_ = display;
  try {
    if (!epoxy_has_egl_extension(display, "EGL_KHR_surfaceless_context")) fail("EGL lacks EGL_KHR_surfaceless_context");
    if (!eglBindAPI(EGL_OPENGL_API)) fail("eglBindAPI(EGL_OPENGL_API) failed");
    EGLConfig config = EGL_NO_CONFIG_KHR;
    if (!epoxy_has_egl_extension(display, "EGL_KHR_no_config_context")) {
      const EGLint attributes[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_NONE};
      EGLint count = 0;
      if (!eglChooseConfig(display, attributes, &config, 1, &count) || count < 1) fail("no OpenGL-renderable EGL config");
    }
    const EGLint context_attributes[] = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 3,
                                         EGL_CONTEXT_OPENGL_PROFILE_MASK, EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE};
    EGLContext context = eglCreateContext(display, config, EGL_NO_CONTEXT, context_attributes);
    if (context == EGL_NO_CONTEXT) fail("eglCreateContext(OpenGL 3.3 core) failed");
    context_ = context;
    if (!eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, context)) fail("eglMakeCurrent(no surface) failed");
    if (epoxy_gl_version() < 33) throw std::runtime_error("headless OpenGL: the context is older than OpenGL 3.3");
  } catch (...) {
    if (context_ != nullptr) eglDestroyContext(display, static_cast<EGLContext>(context_));
    eglTerminate(display);
    throw;
  }
}

// The display stays initialized for the rest of the process (EGL has one per platform and
// native display; eglInitialize on it again is a no-op): eglTerminate would unload Mesa's driver,
// whose few unreleased blocks LeakSanitizer then reports from an unknown module, and the next
// picture would load it again.
HeadlessGl::~HeadlessGl() {
  EGLDisplay display = static_cast<EGLDisplay>(display_);
  eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
  eglDestroyContext(display, static_cast<EGLContext>(context_));
  eglReleaseThread();
}

const char* HeadlessGl::renderer() const { return reinterpret_cast<const char*>(glGetString(GL_RENDERER)); }

}  // namespace tetrig::render
