#include "tetrig/rigbuild/surface_mesh.hpp"

#include "tetrig/volume_constraint.hpp"

#include <cctype>

namespace tetrig::rigbuild {

double signedVolume(const SurfaceMesh& mesh) {
  return enclosedVolume(std::span<const std::int32_t>(mesh.triangles.data(), static_cast<std::size_t>(mesh.triangles.size())),
                        mesh.vertices.data());
}

std::string lowercaseExtension(const std::filesystem::path& path) {
  std::string e = path.extension().string();
  for (char& c : e) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return e;
}

}  // namespace tetrig::rigbuild
