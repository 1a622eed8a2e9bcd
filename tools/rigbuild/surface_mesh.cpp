#include "tetrig/rigbuild/surface_mesh.hpp"

#include <Eigen/Geometry>

#include <cctype>

namespace tetrig::rigbuild {

double signedVolume(const SurfaceMesh& mesh) {
  double six_volume = 0.0;
  for (std::int32_t f = 0; f < mesh.triangleCount(); ++f) {
    const Eigen::Vector3d a = mesh.vertices.row(mesh.triangles(f, 0)).transpose();
    const Eigen::Vector3d b = mesh.vertices.row(mesh.triangles(f, 1)).transpose();
    const Eigen::Vector3d c = mesh.vertices.row(mesh.triangles(f, 2)).transpose();
    six_volume += a.dot(b.cross(c));
  }
  return six_volume / 6.0;
}

std::string lowercaseExtension(const std::filesystem::path& path) {
  std::string e = path.extension().string();
  for (char& c : e) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return e;
}

}  // namespace tetrig::rigbuild
