// Caption and overlay text: DejaVu Sans rendered with FreeType (anti-aliased 8-bit coverage),
// found through fontconfig ("DejaVu Sans"), else at Debian's fixed path
// /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf (package fonts-dejavu-core). The printable
// ASCII glyphs are rendered once at construction; drawing blends cached glyphs into an RGBA
// image and allocates nothing. Other bytes are drawn as '?'.
//
// Tools only. Throws std::runtime_error naming the font or FreeType step that failed.
#pragma once

#include "tetrig/render/picture_sheet.hpp"

#include <array>
#include <cstdint>
#include <filesystem>
#include <string_view>
#include <vector>

namespace tetrig::render {

// The font file used: fontconfig's match for "DejaVu Sans" when it is a DejaVu Sans file, else
// the Debian path. Throws std::runtime_error when neither exists.
std::filesystem::path findDejaVuSans();

class TextRasterizer {
 public:
  explicit TextRasterizer(int pixel_height = 16);

  // Draws one line with its top-left corner at (x, y) (pixels, y down) in `rgb` (0-255), with a
  // one-pixel dark shadow when `shadow`; clipped to the image.
  void draw(Image& image, int x, int y, std::string_view text, const std::array<std::uint8_t, 3>& rgb, bool shadow = true) const;
  int width(std::string_view text) const;  // advance width of the line, pixels
  int lineHeight() const { return line_height_; }

 private:
  struct Glyph {
    int width = 0, height = 0, left = 0, top = 0, advance = 0;
    std::vector<std::uint8_t> coverage;  // width * height
  };
  const Glyph& glyph(char c) const;
  std::array<Glyph, 95> glyphs_;  // ' ' .. '~'
  int ascent_ = 0, line_height_ = 0;
};

}  // namespace tetrig::render
