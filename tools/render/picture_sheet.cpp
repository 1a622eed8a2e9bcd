// The picture sheet (render/picture_sheet.hpp): every frame drawn by the shared MeshDrawer with
// one camera framing the union of all frames' bounds, each into the same multisampled
// offscreen target (tile size), read back into its cell of the sheet; captions blended in with
// FreeType afterwards. One headless EGL context per call.
#include "tetrig/render/picture_sheet.hpp"

#include "tetrig/render/camera.hpp"
#include "tetrig/render/headless_gl.hpp"
#include "tetrig/render/mesh_drawer.hpp"
#include "tetrig/render/offscreen_target.hpp"
#include "tetrig/render/text_raster.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace tetrig::render {

namespace {

void checkInputs(std::span<const SheetFrame> frames, std::span<const std::int32_t> triangles, const SheetOptions& o) {
  if (frames.empty()) throw std::invalid_argument("picture sheet: no frames");
  if (o.columns < 1) throw std::invalid_argument("picture sheet: columns must be at least 1");
  if (o.tile_width < 16 || o.tile_height < 16 || o.tile_width > 4096 || o.tile_height > 4096) {
    throw std::invalid_argument("picture sheet: tile size " + std::to_string(o.tile_width) + " x " + std::to_string(o.tile_height) +
                                " is outside 16..4096");
  }
  if (o.up_axis < 0 || o.up_axis > 2) throw std::invalid_argument("picture sheet: up_axis must be 0, 1 or 2");
  if (!std::isfinite(o.azimuth_deg) || !std::isfinite(o.elevation_deg)) throw std::invalid_argument("picture sheet: camera angles must be finite");
  const std::size_t n = frames.front().positions.size();
  if (n == 0 || n % 3 != 0) {
    throw std::invalid_argument("picture sheet: frame 0 has " + std::to_string(n) + " coordinates (need 3 per vertex, at least one vertex)");
  }
  for (std::size_t f = 0; f < frames.size(); ++f) {
    if (frames[f].positions.size() != n) {
      throw std::invalid_argument("picture sheet: frame " + std::to_string(f) + " has " + std::to_string(frames[f].positions.size()) +
                                  " coordinates, frame 0 has " + std::to_string(n));
    }
    if (frames[f].markers.size() % 3 != 0) {
      throw std::invalid_argument("picture sheet: frame " + std::to_string(f) + "'s markers are not x, y, z triples");
    }
    for (float v : frames[f].positions) {
      if (!std::isfinite(v)) throw std::invalid_argument("picture sheet: frame " + std::to_string(f) + " has a non-finite position");
    }
  }
  if (triangles.size() % 3 != 0) throw std::invalid_argument("picture sheet: triangle indices are not a multiple of 3");
  const auto vertices = static_cast<std::int64_t>(n / 3);
  for (std::size_t i = 0; i < triangles.size(); ++i) {
    if (triangles[i] < 0 || triangles[i] >= vertices) {
      throw std::invalid_argument("picture sheet: triangle " + std::to_string(i / 3) + " has vertex index " + std::to_string(triangles[i]) +
                                  " outside [0, " + std::to_string(vertices) + ")");
    }
  }
}

}  // namespace

Image renderPictureSheet(std::span<const SheetFrame> frames, std::span<const std::int32_t> triangles, const SheetOptions& options) {
  checkInputs(frames, triangles, options);
  const int columns = std::min(options.columns, static_cast<int>(frames.size()));
  const int rows = static_cast<int>((frames.size() + static_cast<std::size_t>(columns) - 1) / static_cast<std::size_t>(columns));
  const int tw = options.tile_width, th = options.tile_height;
  if (static_cast<std::int64_t>(columns) * tw > 65535 || static_cast<std::int64_t>(rows) * th > 65535) {
    throw std::invalid_argument("picture sheet: " + std::to_string(columns) + " x " + std::to_string(rows) +
                                " tiles exceed 65535 pixels; use fewer frames or smaller tiles");
  }
  Bounds bounds;
  for (const SheetFrame& f : frames) {
    bounds.add(f.positions);
    bounds.add(f.markers);
  }
  const OrbitCamera camera = OrbitCamera::framing(bounds, options.up_axis, options.azimuth_deg, options.elevation_deg);
  const TextRasterizer text(std::clamp(th / 24, 11, 28));

  Image sheet;
  sheet.width = columns * tw;
  sheet.height = rows * th;
  sheet.rgba.assign(static_cast<std::size_t>(sheet.width) * static_cast<std::size_t>(sheet.height) * 4, 0);
  for (std::size_t i = 0; i < sheet.rgba.size(); i += 4) {  // empty cells of the last row: the background's dark end
    for (int k = 0; k < 3; ++k) sheet.rgba[i + static_cast<std::size_t>(k)] = static_cast<std::uint8_t>(std::lround(kBackgroundBottom[k] * 255.0f));
    sheet.rgba[i + 3] = 255;
  }

  const HeadlessGl gl;
  {
    const OffscreenTarget target(tw, th);
    MeshDrawer drawer(triangles, static_cast<std::int32_t>(frames.front().positions.size() / 3));
    drawer.setFloor(bounds, options.up_axis);
    Image tile;
    tile.width = tw;
    tile.height = th;
    tile.rgba.resize(static_cast<std::size_t>(tw) * static_cast<std::size_t>(th) * 4);
    for (std::size_t f = 0; f < frames.size(); ++f) {
      drawer.setPositions(frames[f].positions);
      drawer.setMarkers(frames[f].markers);
      target.bind();
      drawer.draw(camera, tw, th);
      target.readRgba(tile.rgba);
      for (std::size_t i = 3; i < tile.rgba.size(); i += 4) tile.rgba[i] = 255;  // opaque, whatever the blending left
      if (!frames[f].caption.empty()) {
        const int margin = std::max(4, th / 60);
        text.draw(tile, margin, margin, frames[f].caption, {240, 240, 240});
      }
      const int cx = static_cast<int>(f % static_cast<std::size_t>(columns)), cy = static_cast<int>(f / static_cast<std::size_t>(columns));
      const std::size_t row_bytes = static_cast<std::size_t>(tw) * 4;
      for (int y = 0; y < th; ++y) {
        const std::size_t dst = (static_cast<std::size_t>(cy * th + y) * static_cast<std::size_t>(sheet.width) + static_cast<std::size_t>(cx * tw)) * 4;
        std::copy_n(tile.rgba.begin() + static_cast<std::ptrdiff_t>(static_cast<std::size_t>(y) * row_bytes), row_bytes,
                    sheet.rgba.begin() + static_cast<std::ptrdiff_t>(dst));
      }
    }
  }  // GL objects go before the context
  return sheet;
}

}  // namespace tetrig::render
