// Text for captions and the viewer's overlay (render/text_raster.hpp): FreeType renders the
// printable ASCII glyphs of DejaVu Sans once (FT_LOAD_RENDER, 8-bit anti-aliased coverage);
// draw() alpha-blends the cached coverage into an RGBA image, glyph by glyph along the pen's
// advance. The font file comes from fontconfig, else Debian's fixed path.
#include "tetrig/render/text_raster.hpp"

#include <fontconfig/fontconfig.h>
#include <ft2build.h>
#include FT_FREETYPE_H

#include <algorithm>
#include <memory>
#include <stdexcept>
#include <string>

namespace tetrig::render {

namespace {

constexpr const char* kDebianDejaVuSans = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

std::filesystem::path fontconfigDejaVuSans() {
  FcConfig* config = FcInitLoadConfigAndFonts();
  if (config == nullptr) return {};
  std::filesystem::path found;
  FcPattern* pattern = FcNameParse(reinterpret_cast<const FcChar8*>("DejaVu Sans:style=Book"));
  if (pattern != nullptr) {
    FcConfigSubstitute(config, pattern, FcMatchPattern);
    FcDefaultSubstitute(pattern);
    FcResult result = FcResultNoMatch;
    FcPattern* match = FcFontMatch(config, pattern, &result);
    if (match != nullptr) {
      FcChar8* file = nullptr;
      FcChar8* family = nullptr;
      if (FcPatternGetString(match, FC_FILE, 0, &file) == FcResultMatch &&
          FcPatternGetString(match, FC_FAMILY, 0, &family) == FcResultMatch &&
          std::string(reinterpret_cast<const char*>(family)) == "DejaVu Sans") {
        found = reinterpret_cast<const char*>(file);
      }
      FcPatternDestroy(match);
    }
    FcPatternDestroy(pattern);
  }
  FcConfigDestroy(config);
  return found;
}

struct FtLibrary {
  FT_Library lib = nullptr;
  ~FtLibrary() {
    if (lib != nullptr) FT_Done_FreeType(lib);
  }
};
struct FtFace {
  FT_Face face = nullptr;
  ~FtFace() {
    if (face != nullptr) FT_Done_Face(face);
  }
};

}  // namespace

std::filesystem::path findDejaVuSans() {
  std::filesystem::path p = fontconfigDejaVuSans();
  std::error_code ec;
  if (!p.empty() && std::filesystem::is_regular_file(p, ec)) return p;
  if (std::filesystem::is_regular_file(kDebianDejaVuSans, ec)) return kDebianDejaVuSans;
  throw std::runtime_error(std::string("font DejaVu Sans not found (fontconfig has no match and ") + kDebianDejaVuSans +
                           " is missing): install fonts-dejavu-core");
}

TextRasterizer::TextRasterizer(int pixel_height) {
  if (pixel_height < 4 || pixel_height > 256) throw std::invalid_argument("text size " + std::to_string(pixel_height) + " px is outside 4..256");
  const std::filesystem::path font = findDejaVuSans();
  FtLibrary ft;
  if (FT_Init_FreeType(&ft.lib) != 0) throw std::runtime_error("FreeType: FT_Init_FreeType failed");
  FtFace face;
  if (FT_New_Face(ft.lib, font.c_str(), 0, &face.face) != 0) throw std::runtime_error("FreeType cannot open font " + font.string());
  if (FT_Set_Pixel_Sizes(face.face, 0, static_cast<FT_UInt>(pixel_height)) != 0) {
    throw std::runtime_error("FreeType cannot size font " + font.string());
  }
  ascent_ = static_cast<int>(face.face->size->metrics.ascender >> 6);
  line_height_ = static_cast<int>(face.face->size->metrics.height >> 6);
  for (int c = 32; c < 127; ++c) {
    Glyph& g = glyphs_[static_cast<std::size_t>(c - 32)];
    if (FT_Load_Char(face.face, static_cast<FT_ULong>(c), FT_LOAD_RENDER) != 0) {
      throw std::runtime_error("FreeType cannot render '" + std::string(1, static_cast<char>(c)) + "' of " + font.string());
    }
    const FT_GlyphSlot slot = face.face->glyph;
    g.width = static_cast<int>(slot->bitmap.width);
    g.height = static_cast<int>(slot->bitmap.rows);
    g.left = slot->bitmap_left;
    g.top = slot->bitmap_top;
    g.advance = static_cast<int>(slot->advance.x >> 6);
    g.coverage.resize(static_cast<std::size_t>(g.width) * static_cast<std::size_t>(g.height));
    for (int y = 0; y < g.height; ++y) {
      const unsigned char* row = slot->bitmap.buffer + static_cast<std::ptrdiff_t>(y) * slot->bitmap.pitch;
      std::copy(row, row + g.width, g.coverage.begin() + static_cast<std::ptrdiff_t>(y) * g.width);
    }
  }
}

const TextRasterizer::Glyph& TextRasterizer::glyph(char c) const {
  const auto u = static_cast<unsigned char>(c);
  return glyphs_[u >= 32 && u < 127 ? u - 32u : static_cast<unsigned>('?' - 32)];
}

int TextRasterizer::width(std::string_view text) const {
  int w = 0;
  for (char c : text) w += glyph(c).advance;
  return w;
}

void TextRasterizer::draw(Image& image, int x, int y, std::string_view text, const std::array<std::uint8_t, 3>& rgb, bool shadow) const {
  auto blend = [&](int px, int py, int coverage, const std::array<std::uint8_t, 3>& color) {
    if (px < 0 || py < 0 || px >= image.width || py >= image.height || coverage == 0) return;
    std::uint8_t* d = &image.rgba[(static_cast<std::size_t>(py) * static_cast<std::size_t>(image.width) + static_cast<std::size_t>(px)) * 4];
    for (int k = 0; k < 3; ++k) d[k] = static_cast<std::uint8_t>((d[k] * (255 - coverage) + color[static_cast<std::size_t>(k)] * coverage + 127) / 255);
    d[3] = static_cast<std::uint8_t>(std::max<int>(d[3], coverage));
  };
  const int passes = shadow ? 2 : 1;
  for (int pass = 0; pass < passes; ++pass) {
    const bool is_shadow = shadow && pass == 0;
    const std::array<std::uint8_t, 3> color = is_shadow ? std::array<std::uint8_t, 3>{0, 0, 0} : rgb;
    const int off = is_shadow ? 1 : 0;
    int pen = x;
    for (char c : text) {
      const Glyph& g = glyph(c);
      const int gx = pen + g.left + off, gy = y + ascent_ - g.top + off;
      for (int row = 0; row < g.height; ++row) {
        for (int col = 0; col < g.width; ++col) {
          blend(gx + col, gy + row, g.coverage[static_cast<std::size_t>(row * g.width + col)], color);
        }
      }
      pen += g.advance;
    }
  }
}

}  // namespace tetrig::render
