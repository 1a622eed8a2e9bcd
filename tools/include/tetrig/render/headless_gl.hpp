// A headless OpenGL 3.3 core context with no display and no window system: EGL on Mesa's
// surfaceless platform (EGL_MESA_platform_surfaceless through eglGetPlatformDisplayEXT), made
// current without a surface (EGL_KHR_surfaceless_context). There is no default framebuffer:
// draw into a framebuffer object (render/offscreen_target.hpp). GL entry points through libepoxy.
//
// Tools only; one object per thread, current on the thread that made it. Throws
// std::runtime_error with one line naming the EGL step that failed and what to install.
#pragma once

namespace tetrig::render {

class HeadlessGl {
 public:
  HeadlessGl();
  HeadlessGl(const HeadlessGl&) = delete;
  HeadlessGl& operator=(const HeadlessGl&) = delete;
  ~HeadlessGl();

  const char* renderer() const;  // GL_RENDERER, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)"

 private:
  void* display_ = nullptr;
  void* context_ = nullptr;
};

}  // namespace tetrig::render
