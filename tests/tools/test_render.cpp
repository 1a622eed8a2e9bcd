// The headless renderer (tools/include/tetrig/render/picture_sheet.hpp) on the small block rig
// (small_rig.hpp): its rest pose and a pose where the live rig pulled the TOP marker up 150 mm,
// drawn offscreen through EGL surfaceless (Mesa llvmpipe, no display):
//  - the sheet is columns x rows tiles; each tile shows the mesh (many colours, a plausible
//    share of surface pixels), the deformed tile's silhouette reaches higher than the rest
//    tile's, the same pose drawn twice gives the same pixels except where the caption is, the
//    marker dots appear only where markers were given, an empty cell is plain background;
//  - bad input (sizes, indices, NaN, options) is refused with std::invalid_argument;
//  - writePng/readPng round-trip every byte; a failed write leaves no file; a non-PNG is refused.
// TETRIG_KEEP_TEMP=1 keeps the sheet (sheet.png) to look at.
#include "small_rig.hpp"
#include "tetrig/live_rig.hpp"
#include "tetrig/render/gl_program.hpp"
#include "tetrig/render/headless_gl.hpp"
#include "tetrig/render/picture_sheet.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <set>

namespace tetrig {
namespace {

using render::Image;
using render::SheetFrame;
using test::TempDir;

struct Poses {
  std::vector<float> rest, pulled, markers;
  std::vector<std::int32_t> triangles;
};

// Rest pose, and the pose after the TOP marker rose 150 mm (10 frames of 10 iterations).
const Poses& poses() {
  static const Poses p = [] {
    const TempDir dir;
    const Rig rig = test::buildSmallRig(dir);
    LiveRig live(rig);
    const std::vector<std::string> labels = {"TOP", "LEFT", "RIGHT", "FRONT", "BACK"};
    (void)live.bindLabels(labels);
    Poses out;
    out.rest.assign(live.restPositions().begin(), live.restPositions().end());
    out.triangles.assign(live.fineTriangles().begin(), live.fineTriangles().end());
    out.pulled.resize(out.rest.size());
    const auto mm = test::smallMarkerPositionsMm();
    for (int f = 0; f < 10; ++f) {
      MarkerFrame frame;
      frame.frame_counter = static_cast<std::uint64_t>(f + 1);
      frame.receive_timestamp_ns = (f + 1) * 10'000'000LL;
      frame.marker_count = static_cast<std::uint16_t>(mm.size());
      for (std::size_t m = 0; m < mm.size(); ++m) {
        Marker& k = frame.markers[m];
        k.id = static_cast<std::uint16_t>(m);
        k.valid = 1;
        for (int a = 0; a < 3; ++a) k.position_mm[a] = mm[m][static_cast<std::size_t>(a)];
        if (m == 0) k.position_mm[1] += 150.0f;  // TOP up (y up)
      }
      (void)live.processFrame(frame, StepBudget{10}, out.pulled.data(), nullptr);
    }
    for (const Eigen::Vector3d& t : live.markerTargets()) {
      for (int a = 0; a < 3; ++a) out.markers.push_back(static_cast<float>(t[a]));
    }
    return out;
  }();
  return p;
}

Image tileOf(const Image& sheet, int col, int row, int tw, int th) {
  Image t;
  t.width = tw;
  t.height = th;
  for (int y = 0; y < th; ++y) {
    const auto* src = &sheet.rgba[(static_cast<std::size_t>(row * th + y) * static_cast<std::size_t>(sheet.width) + static_cast<std::size_t>(col * tw)) * 4];
    t.rgba.insert(t.rgba.end(), src, src + static_cast<std::ptrdiff_t>(tw) * 4);
  }
  return t;
}

const std::uint8_t* px(const Image& im, int x, int y) { return &im.rgba[(static_cast<std::size_t>(y) * static_cast<std::size_t>(im.width) + static_cast<std::size_t>(x)) * 4]; }

// Surface pixels: the clay colour is warm (red well above blue); background and grid are grey-blue.
bool isSurface(const std::uint8_t* p) { return int{p[0]} - int{p[2]} > 12; }
// Marker dots: saturated orange.
bool isMarker(const std::uint8_t* p) { return p[0] > 120 && int{p[0]} - int{p[1]} > 60 && int{p[1]} - int{p[2]} > 25; }

std::size_t distinctColours(const Image& im) {
  std::set<std::uint32_t> c;
  for (std::size_t i = 0; i < im.rgba.size(); i += 4) c.insert(std::uint32_t{im.rgba[i]} << 16 | std::uint32_t{im.rgba[i + 1]} << 8 | im.rgba[i + 2]);
  return c.size();
}

double surfaceFraction(const Image& im) {
  std::size_t n = 0;
  for (int y = 0; y < im.height; ++y)
    for (int x = 0; x < im.width; ++x) n += isSurface(px(im, x, y)) ? 1 : 0;
  return static_cast<double>(n) / (im.width * im.height);
}

int topSurfaceRow(const Image& im) {
  for (int y = 0; y < im.height; ++y)
    for (int x = 0; x < im.width; ++x)
      if (isSurface(px(im, x, y))) return y;
  return im.height;
}

std::size_t countMarkerPixels(const Image& im) {
  std::size_t n = 0;
  for (int y = 0; y < im.height; ++y)
    for (int x = 0; x < im.width; ++x) n += isMarker(px(im, x, y)) ? 1 : 0;
  return n;
}

TEST(PictureSheet, ShowsTheRigAndItsMotion) {
  const Poses& p = poses();
  // The pull moved the top of the block up by several centimetres (y up, metres).
  float rest_top = -1e9f, pulled_top = -1e9f;
  for (std::size_t i = 1; i < p.rest.size(); i += 3) {
    rest_top = std::max(rest_top, p.rest[i]);
    pulled_top = std::max(pulled_top, p.pulled[i]);
  }
  ASSERT_GT(pulled_top - rest_top, 0.015f);

  const std::vector<SheetFrame> frames = {{p.rest, "rest", {}}, {p.pulled, "TOP up 150 mm", p.markers}, {p.rest, "", {}}};
  render::SheetOptions o;
  o.columns = 2;
  o.tile_width = 240;
  o.tile_height = 200;
  o.up_axis = 1;  // the small rig is y up
  const Image sheet = render::renderPictureSheet(frames, p.triangles, o);
  ASSERT_EQ(sheet.width, 2 * 240);
  ASSERT_EQ(sheet.height, 2 * 200);
  ASSERT_EQ(sheet.rgba.size(), std::size_t{480} * 400 * 4);
  const TempDir dir("tetrig-render");
  render::writePng(dir / "sheet.png", sheet);

  const Image rest = tileOf(sheet, 0, 0, 240, 200), pulled = tileOf(sheet, 1, 0, 240, 200), plain = tileOf(sheet, 0, 1, 240, 200),
              empty = tileOf(sheet, 1, 1, 240, 200);
  for (const Image* t : {&rest, &pulled, &plain}) {
    EXPECT_GT(distinctColours(*t), 100u);                // shaded, not a flat fill
    EXPECT_GT(surfaceFraction(*t), 0.05);                // the mesh is in the picture...
    EXPECT_LT(surfaceFraction(*t), 0.75);                // ...and framed, not filling it
  }
  EXPECT_EQ(distinctColours(empty), 1u);                 // an unused cell is plain background
  // The pulled block reaches higher on screen.
  EXPECT_LT(topSurfaceRow(pulled) + 5, topSurfaceRow(rest)) << topSurfaceRow(pulled) << " vs " << topSurfaceRow(rest);
  std::size_t moved = 0;
  for (std::size_t i = 0; i < rest.rgba.size(); i += 4) moved += std::equal(&rest.rgba[i], &rest.rgba[i] + 3, &pulled.rgba[i]) ? 0 : 1;
  EXPECT_GT(moved, std::size_t{240} * 200 / 50);
  // Same pose twice: identical pixels except in the caption's corner, where the caption is.
  std::size_t caption_diff = 0, other_diff = 0;
  for (int y = 0; y < 200; ++y) {
    for (int x = 0; x < 240; ++x) {
      const bool same = std::equal(px(rest, x, y), px(rest, x, y) + 4, px(plain, x, y));
      if (x < 80 && y < 30) {
        caption_diff += same ? 0 : 1;
      } else {
        other_diff += same ? 0 : 1;
      }
    }
  }
  EXPECT_GT(caption_diff, 20u);
  EXPECT_EQ(other_diff, 0u);
  // Marker dots only where markers were given.
  EXPECT_GE(countMarkerPixels(pulled), 20u);
  EXPECT_EQ(countMarkerPixels(rest), 0u);
}

TEST(PictureSheet, RefusesBadInput) {
  const Poses& p = poses();
  const std::vector<SheetFrame> one = {{p.rest, "", {}}};
  EXPECT_THROW(render::renderPictureSheet({}, p.triangles), std::invalid_argument);
  std::vector<SheetFrame> mismatch = {{p.rest, "", {}}, {std::vector<float>(p.rest.begin(), p.rest.end() - 3), "", {}}};
  EXPECT_THROW(render::renderPictureSheet(mismatch, p.triangles), std::invalid_argument);
  std::vector<std::int32_t> bad_tris = p.triangles;
  bad_tris[4] = static_cast<std::int32_t>(p.rest.size() / 3);
  EXPECT_THROW(render::renderPictureSheet(one, bad_tris), std::invalid_argument);
  bad_tris[4] = -1;
  EXPECT_THROW(render::renderPictureSheet(one, bad_tris), std::invalid_argument);
  std::vector<SheetFrame> nan = one;
  nan[0].positions[7] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(render::renderPictureSheet(nan, p.triangles), std::invalid_argument);
  std::vector<SheetFrame> bad_markers = one;
  bad_markers[0].markers = {1.0f, 2.0f};
  EXPECT_THROW(render::renderPictureSheet(bad_markers, p.triangles), std::invalid_argument);
  render::SheetOptions o;
  o.columns = 0;
  EXPECT_THROW(render::renderPictureSheet(one, p.triangles, o), std::invalid_argument);
  o = {};
  o.tile_width = 8;
  EXPECT_THROW(render::renderPictureSheet(one, p.triangles, o), std::invalid_argument);
  o = {};
  o.up_axis = 3;
  EXPECT_THROW(render::renderPictureSheet(one, p.triangles, o), std::invalid_argument);
}

TEST(GlProgram, LinksValidShadersAndNamesTheFailingOne) {
  const tetrig::render::HeadlessGl gl;
  const char* vs = "#version 330 core\nlayout(location = 0) in vec3 a;\nvoid main() { gl_Position = vec4(a, 1.0); }\n";
  const char* fs = "#version 330 core\nout vec4 o;\nvoid main() { o = vec4(1.0); }\n";
  EXPECT_NE(tetrig::render::linkProgram(vs, fs, "test"), 0u);
  const char* broken = "#version 330 core\nout vec4 o;\nvoid main() { o = undeclared_name; }\n";
  auto message = [&](const char* v, const char* f) {
    try {
      tetrig::render::linkProgram(v, f, "the test program");
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  const std::string bad_fragment = message(vs, broken);
  EXPECT_NE(bad_fragment.find("the test program"), std::string::npos) << bad_fragment;
  EXPECT_NE(bad_fragment.find("fragment shader does not compile"), std::string::npos) << bad_fragment;
  EXPECT_NE(bad_fragment.find("undeclared_name"), std::string::npos) << bad_fragment;  // the driver's log
  const std::string bad_vertex = message(broken, fs);
  EXPECT_NE(bad_vertex.find("vertex shader does not compile"), std::string::npos) << bad_vertex;
  // Both compile, the link fails: the vertex shader has no main().
  const char* no_main = "#version 330 core\nvoid helper() {}\n";
  const std::string bad_link = message(no_main, fs);
  EXPECT_NE(bad_link.find("does not link"), std::string::npos) << bad_link;
}

TEST(Png, RoundTripsEveryByte) {
  Image im;
  im.width = 37;
  im.height = 23;
  for (int i = 0; i < im.width * im.height; ++i) {
    im.rgba.push_back(static_cast<std::uint8_t>(i * 7));
    im.rgba.push_back(static_cast<std::uint8_t>(i * 13 + 5));
    im.rgba.push_back(static_cast<std::uint8_t>(255 - i));
    im.rgba.push_back(static_cast<std::uint8_t>(i % 3 == 0 ? 255 : i * 31));  // opaque, translucent and transparent pixels
  }
  const TempDir dir("tetrig-render");
  render::writePng(dir / "a.png", im);
  const Image back = render::readPng(dir / "a.png");
  EXPECT_EQ(back.width, im.width);
  EXPECT_EQ(back.height, im.height);
  EXPECT_EQ(back.rgba, im.rgba);
}

TEST(Png, FailedWriteLeavesNoFile) {
  Image im;
  im.width = 4;
  im.height = 4;
  im.rgba.assign(64, 200);
  const TempDir dir("tetrig-render");
  EXPECT_THROW(render::writePng(dir / "missing" / "a.png", im), std::exception);
  std::filesystem::create_directory(dir / "taken");  // the target is a directory: the rename fails
  EXPECT_THROW(render::writePng(dir / "taken", im), std::exception);
  std::vector<std::string> left;
  for (const auto& e : std::filesystem::directory_iterator(dir.path())) left.push_back(e.path().filename().string());
  EXPECT_EQ(left, std::vector<std::string>{"taken"});
  EXPECT_TRUE(std::filesystem::is_empty(dir / "taken"));
  Image wrong = im;
  wrong.rgba.pop_back();
  EXPECT_THROW(render::writePng(dir / "b.png", wrong), std::invalid_argument);
  EXPECT_FALSE(std::filesystem::exists(dir / "b.png"));
}

TEST(Png, RefusesFilesThatAreNotPng) {
  const TempDir dir("tetrig-render");
  EXPECT_THROW(render::readPng(dir.write("text.png", "not a png at all")), std::runtime_error);
  EXPECT_THROW(render::readPng(dir / "absent.png"), std::runtime_error);
  Image im;
  im.width = 16;
  im.height = 16;
  im.rgba.assign(16 * 16 * 4, 90);
  render::writePng(dir / "whole.png", im);
  std::ifstream in(dir / "whole.png", std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), {});
  EXPECT_THROW(render::readPng(dir.write("cut.png", bytes.substr(0, bytes.size() / 2))), std::runtime_error);
}

}  // namespace
}  // namespace tetrig
