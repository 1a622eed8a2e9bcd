// libFuzzer target for surface import (importSurface: checkSurfaceBytes, then assimp, then the
// file's vertex list, matching and welding) and validateSurface on what it returns. Input: the
// first byte picks the format (mod 4: OBJ, OFF, PLY ascii or binary, STL ascii or binary), the
// rest is the file. assimp runs in this process (ImportOptions::isolate = false) so that a crash
// or an abort inside it is seen as one. Every input must either import or throw RigBuildError
// with a printable one-line message; an imported mesh has in-range indices, a consistent
// vertex map and no more vertices or triangles than the file has bytes (nothing allocated for
// counts the file does not hold).
#include "tetrig/printable_text.hpp"
#include "tetrig/rigbuild/import_surface.hpp"
#include "tetrig/rigbuild/validate_surface.hpp"

#include <stdlib.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>
#include <string_view>

namespace {

// One private directory per process for the file being imported, removed at exit.
struct FuzzDir {
  std::filesystem::path path;
  FuzzDir() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "tetrig-fuzz-import-XXXXXX").string();
    if (::mkdtemp(tmpl.data()) == nullptr) __builtin_trap();
    path = tmpl;
  }
  ~FuzzDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
};

void requirePrintable(std::string_view text) {
  if (!tetrig::isWellFormedUtf8(text)) __builtin_trap();
  for (const char c : text) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 || u == 0x7f) __builtin_trap();  // raw file bytes reached a message
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tetrig::rigbuild;
  if (size == 0) return 0;
  static FuzzDir dir;
  static const char* kExtensions[4] = {".obj", ".off", ".ply", ".stl"};
  const std::filesystem::path file = dir.path / (std::string("in") + kExtensions[data[0] % 4]);
  {
    std::FILE* f = std::fopen(file.c_str(), "wb");
    if (f == nullptr) __builtin_trap();
    if (size > 1 && std::fwrite(data + 1, 1, size - 1, f) != size - 1) __builtin_trap();
    std::fclose(f);
  }
  const std::size_t bytes = size - 1;
  ImportOptions options;
  options.isolate = false;
  try {
    ImportStats stats;
    SurfaceMesh m = importSurface(file, options, &stats);
    const auto nv = m.vertexCount();
    if (nv <= 0 || static_cast<std::size_t>(nv) > bytes || static_cast<std::size_t>(m.triangleCount()) > bytes) __builtin_trap();
    for (Eigen::Index f = 0; f < m.triangles.rows(); ++f) {
      for (int k = 0; k < 3; ++k) {
        if (m.triangles(f, k) < 0 || m.triangles(f, k) >= nv) __builtin_trap();
      }
    }
    if (stats.file_to_vertex.size() != static_cast<std::size_t>(stats.file_vertices)) __builtin_trap();
    for (const std::int32_t v : stats.file_to_vertex) {
      if (v < 0 || v >= nv) __builtin_trap();
    }
    if (stats.welded_vertices != stats.file_vertices - nv) __builtin_trap();
    const SurfaceReport report = validateSurface(m);
    for (const std::int32_t v : report.vertex_map) {
      if (v < -1 || v >= m.vertexCount()) __builtin_trap();
    }
    for (const std::string& r : report.refusals) requirePrintable(r);
  } catch (const RigBuildError& e) {
    requirePrintable(e.what());
  }
  std::remove(file.c_str());  // libFuzzer may end with _Exit: leave at most an empty directory
  return 0;
}
