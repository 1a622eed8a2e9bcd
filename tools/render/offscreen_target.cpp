// Framebuffer objects for drawing without a window (render/offscreen_target.hpp): multisampled
// renderbuffers (colour RGBA8 + 24-bit depth) blitted into a single-sample RGBA8 renderbuffer,
// then read back with glReadPixels and flipped to rows top to bottom.
#include "tetrig/render/offscreen_target.hpp"

#include <epoxy/gl.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <string>

namespace tetrig::render {

OffscreenTarget::OffscreenTarget(int width, int height, int samples) : width_(width), height_(height), samples_(samples) {
  GLint max_size = 0, max_samples = 0;
  glGetIntegerv(GL_MAX_RENDERBUFFER_SIZE, &max_size);
  glGetIntegerv(GL_MAX_SAMPLES, &max_samples);
  if (width < 1 || height < 1 || width > max_size || height > max_size) {
    throw std::invalid_argument("offscreen picture " + std::to_string(width) + " x " + std::to_string(height) +
                                " is outside 1.." + std::to_string(max_size) + " pixels");
  }
  samples_ = std::clamp(samples, 0, static_cast<int>(max_samples));
  glGenFramebuffers(1, &draw_fbo_);
  glGenRenderbuffers(1, &color_rb_);
  glGenRenderbuffers(1, &depth_rb_);
  glBindRenderbuffer(GL_RENDERBUFFER, color_rb_);
  glRenderbufferStorageMultisample(GL_RENDERBUFFER, samples_, GL_RGBA8, width, height);
  glBindRenderbuffer(GL_RENDERBUFFER, depth_rb_);
  glRenderbufferStorageMultisample(GL_RENDERBUFFER, samples_, GL_DEPTH_COMPONENT24, width, height);
  glBindFramebuffer(GL_FRAMEBUFFER, draw_fbo_);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, color_rb_);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth_rb_);
  const GLenum draw_status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
  glGenFramebuffers(1, &resolve_fbo_);
  glGenRenderbuffers(1, &resolve_rb_);
  glBindRenderbuffer(GL_RENDERBUFFER, resolve_rb_);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, width, height);
  glBindFramebuffer(GL_FRAMEBUFFER, resolve_fbo_);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, resolve_rb_);
  const GLenum resolve_status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
  if (draw_status != GL_FRAMEBUFFER_COMPLETE || resolve_status != GL_FRAMEBUFFER_COMPLETE) {
    release();
    char status[64];
    std::snprintf(status, sizeof status, "0x%04x, 0x%04x", static_cast<unsigned>(draw_status), static_cast<unsigned>(resolve_status));
    throw std::runtime_error(std::string("offscreen framebuffer incomplete (status ") + status + "): the OpenGL driver cannot draw " +
                             std::to_string(width) + " x " + std::to_string(height) + " RGBA8 with " + std::to_string(samples_) + " samples");
  }
}

OffscreenTarget::~OffscreenTarget() { release(); }

void OffscreenTarget::release() {
  if (draw_fbo_ != 0) glDeleteFramebuffers(1, &draw_fbo_);
  if (resolve_fbo_ != 0) glDeleteFramebuffers(1, &resolve_fbo_);
  const GLuint rbs[3] = {color_rb_, depth_rb_, resolve_rb_};
  glDeleteRenderbuffers(3, rbs);
  draw_fbo_ = resolve_fbo_ = color_rb_ = depth_rb_ = resolve_rb_ = 0;
}

void OffscreenTarget::bind() const {
  glBindFramebuffer(GL_FRAMEBUFFER, draw_fbo_);
  glViewport(0, 0, width_, height_);
}

void OffscreenTarget::readRgba(std::span<std::uint8_t> rgba) const {
  glBindFramebuffer(GL_READ_FRAMEBUFFER, draw_fbo_);
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, resolve_fbo_);
  glBlitFramebuffer(0, 0, width_, height_, 0, 0, width_, height_, GL_COLOR_BUFFER_BIT, GL_NEAREST);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, resolve_fbo_);
  readPixelsTopDown(width_, height_, rgba);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
}

void OffscreenTarget::blitTo(unsigned fbo) const {
  glBindFramebuffer(GL_READ_FRAMEBUFFER, draw_fbo_);
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, resolve_fbo_);
  glBlitFramebuffer(0, 0, width_, height_, 0, 0, width_, height_, GL_COLOR_BUFFER_BIT, GL_NEAREST);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, resolve_fbo_);
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, fbo);
  glBlitFramebuffer(0, 0, width_, height_, 0, 0, width_, height_, GL_COLOR_BUFFER_BIT, GL_NEAREST);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
}

void readPixelsTopDown(int width, int height, std::span<std::uint8_t> rgba) {
  const std::size_t row = static_cast<std::size_t>(width) * 4;
  if (rgba.size() < row * static_cast<std::size_t>(height)) throw std::invalid_argument("readPixelsTopDown: buffer too small");
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, width, height, GL_RGBA, GL_UNSIGNED_BYTE, rgba.data());
  // Bottom-to-top rows -> top-to-bottom, in place.
  std::uint8_t* p = rgba.data();
  for (int y = 0; y < height / 2; ++y) {
    std::swap_ranges(p + static_cast<std::size_t>(y) * row, p + static_cast<std::size_t>(y + 1) * row,
                     p + static_cast<std::size_t>(height - 1 - y) * row);
  }
}

}  // namespace tetrig::render
