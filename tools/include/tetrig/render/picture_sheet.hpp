// Headless pictures of deformed meshes: an OpenGL 3.3 core context without a display (EGL
// surfaceless on Mesa, drawing into a framebuffer object), the same shaded-surface drawing that
// `tetrig view` uses, a grid of frames in one image (the demo report's picture sheet), and PNG
// files (libpng, written through tetrig::AtomicFile).
//
// Tools only: allocates, throws std::runtime_error with one clear line (what failed and what to
// install or set) when no OpenGL context can be made.
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

namespace tetrig::render {

// 8-bit RGBA, rows top to bottom, width * height * 4 bytes.
struct Image {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgba;
};

// One tile of a picture sheet: the fine-mesh positions of one frame (x, y, z per vertex, the
// rig's units), a caption drawn in the tile's corner (e.g. "frame 240  t = 2.00 s"), and
// optional marker positions (x, y, z each, same units) drawn as dots.
struct SheetFrame {
  std::vector<float> positions;
  std::string caption;
  std::vector<float> markers;
};

struct SheetOptions {
  int columns = 4;
  int tile_width = 480, tile_height = 480;
  // The camera looks at the union of all frames' bounds from the front (the rig's -Y side,
  // Z up) turned by this many degrees about the up axis, so every tile shares one camera and
  // motion between tiles is visible.
  float azimuth_deg = 30.0f;
  float elevation_deg = 10.0f;
  int up_axis = 2;  // 0, 1 or 2: which rig axis points up on screen
};

// Renders each frame with the same camera into one tile; tiles fill rows of `columns`.
// `triangles` index the frames' vertices (3 per triangle). Throws std::invalid_argument when a
// frame's size does not match the others or an index is out of range.
// The image is min(columns, frames) tiles wide and ceil(frames / columns) tiles high; unused
// cells of the last row are background. Also std::invalid_argument: no frames, a non-finite
// position, markers not in triples, columns < 1, tiles outside 16..4096 pixels, up_axis not
// 0-2. One headless EGL context per call (tools/render/headless_gl.cpp): about 0.2 s to set up,
// then about 15 ms per 480 x 480 tile of a 6000-triangle mesh on llvmpipe.
Image renderPictureSheet(std::span<const SheetFrame> frames, std::span<const std::int32_t> triangles,
                         const SheetOptions& options = {});

// Writes `image` as an 8-bit RGBA PNG, atomically (no partial file on failure).
void writePng(const std::filesystem::path& path, const Image& image);

// Reads a PNG into 8-bit RGBA (for tests and checks). Throws std::runtime_error on a bad file.
Image readPng(const std::filesystem::path& path);

}  // namespace tetrig::render
