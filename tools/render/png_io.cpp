// PNG files for the renderer (render/picture_sheet.hpp: writePng, readPng) through libpng's
// simplified API: 8-bit RGBA, encoded in memory with PNG_IMAGE_FLAG_FAST (low zlib effort: a
// 1280 x 720 frame in a few milliseconds) and written through tetrig::AtomicFile, so a failure
// leaves no partial file; read back converted to 8-bit RGBA whatever the file's format.
#include "tetrig/atomic_file.hpp"
#include "tetrig/render/picture_sheet.hpp"

#include <png.h>

#include <cstring>
#include <stdexcept>
#include <string>

namespace tetrig::render {

namespace {

void checkImage(const Image& image) {
  if (image.width < 1 || image.height < 1 || image.width > 65535 || image.height > 65535) {
    throw std::invalid_argument("PNG image size " + std::to_string(image.width) + " x " + std::to_string(image.height) +
                                " is outside 1..65535");
  }
  const std::size_t need = static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.height) * 4;
  if (image.rgba.size() != need) {
    throw std::invalid_argument("PNG image of " + std::to_string(image.width) + " x " + std::to_string(image.height) + " holds " +
                                std::to_string(image.rgba.size()) + " bytes, expected " + std::to_string(need));
  }
}

}  // namespace

void writePng(const std::filesystem::path& path, const Image& image) {
  checkImage(image);
  png_image png;
  std::memset(&png, 0, sizeof png);
  png.version = PNG_IMAGE_VERSION;
  png.width = static_cast<png_uint_32>(image.width);
  png.height = static_cast<png_uint_32>(image.height);
  png.format = PNG_FORMAT_RGBA;
  png.flags = PNG_IMAGE_FLAG_FAST;
  png_alloc_size_t size = 0;
  if (!png_image_write_to_memory(&png, nullptr, &size, 0, image.rgba.data(), 0, nullptr)) {
    const std::string message = png.message;
    png_image_free(&png);
    throw std::runtime_error("cannot encode PNG " + path.string() + ": " + message);
  }
  std::vector<std::uint8_t> bytes(size);
  if (!png_image_write_to_memory(&png, bytes.data(), &size, 0, image.rgba.data(), 0, nullptr)) {
    const std::string message = png.message;
    png_image_free(&png);
    throw std::runtime_error("cannot encode PNG " + path.string() + ": " + message);
  }
  AtomicFile file(path);
  file.write(bytes.data(), size);
  file.commit();
}

Image readPng(const std::filesystem::path& path) {
  png_image png;
  std::memset(&png, 0, sizeof png);
  png.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&png, path.c_str())) {
    const std::string message = png.message;
    png_image_free(&png);
    throw std::runtime_error("cannot read PNG " + path.string() + ": " + message);
  }
  if (png.width < 1 || png.height < 1 || png.width > 65535 || png.height > 65535) {
    png_image_free(&png);
    throw std::runtime_error("cannot read PNG " + path.string() + ": size " + std::to_string(png.width) + " x " +
                             std::to_string(png.height) + " is outside 1..65535");
  }
  png.format = PNG_FORMAT_RGBA;
  Image image;
  image.width = static_cast<int>(png.width);
  image.height = static_cast<int>(png.height);
  image.rgba.resize(PNG_IMAGE_SIZE(png));
  if (!png_image_finish_read(&png, nullptr, image.rgba.data(), 0, nullptr)) {
    const std::string message = png.message;
    png_image_free(&png);
    throw std::runtime_error("cannot read PNG " + path.string() + ": " + message);
  }
  return image;
}

}  // namespace tetrig::render
