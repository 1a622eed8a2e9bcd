// A framebuffer object to draw into and read back: a multisampled colour + depth target (4
// samples when the driver offers them) resolved into a plain RGBA8 one for glReadPixels. Needs a
// current OpenGL 3.3 context (HeadlessGl, or a window's).
//
// Tools only; allocates at construction; readRgba() writes into the caller's buffer.
#pragma once

#include <cstdint>
#include <span>

namespace tetrig::render {

class OffscreenTarget {
 public:
  // Throws std::runtime_error when the framebuffer is incomplete.
  OffscreenTarget(int width, int height, int samples = 4);
  OffscreenTarget(const OffscreenTarget&) = delete;
  OffscreenTarget& operator=(const OffscreenTarget&) = delete;
  ~OffscreenTarget();

  void bind() const;  // binds the (multisampled) draw target and sets the viewport
  // Resolves and copies the picture into `rgba` (width * height * 4 bytes), rows top to bottom.
  void readRgba(std::span<std::uint8_t> rgba) const;
  // Resolves and copies the picture into framebuffer `fbo` (0: a window's) at its origin.
  void blitTo(unsigned fbo) const;

  int width() const { return width_; }
  int height() const { return height_; }
  int samples() const { return samples_; }

 private:
  void release();
  int width_, height_, samples_;
  unsigned draw_fbo_ = 0, color_rb_ = 0, depth_rb_ = 0, resolve_fbo_ = 0, resolve_rb_ = 0;
};

// Reads the bound read framebuffer's `width` x `height` pixels (from the origin) into `rgba`,
// rows top to bottom (glReadPixels gives them bottom to top).
void readPixelsTopDown(int width, int height, std::span<std::uint8_t> rgba);

}  // namespace tetrig::render
