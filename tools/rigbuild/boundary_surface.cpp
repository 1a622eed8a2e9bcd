// Boundary faces of a tet mesh (faces used by exactly one tet), oriented outward.
#include "tetrig/rigbuild/boundary_surface.hpp"

#include <algorithm>
#include <array>
#include <vector>

namespace tetrig::rigbuild {

Triangles boundaryFaces(const TetMesh& mesh) {
  struct Face {
    std::array<std::int32_t, 3> key;
    std::array<std::int32_t, 3> oriented;
  };
  std::vector<Face> faces;
  faces.reserve(static_cast<std::size_t>(mesh.tetCount()) * 4);
  for (std::int32_t t = 0; t < mesh.tetCount(); ++t) {
    const std::int32_t a = mesh.tets(t, 0), b = mesh.tets(t, 1), c = mesh.tets(t, 2), d = mesh.tets(t, 3);
    // Outward faces of a tet with det[b-a, c-a, d-a] > 0.
    const std::array<std::array<std::int32_t, 3>, 4> local = {{{a, c, b}, {a, b, d}, {a, d, c}, {b, c, d}}};
    for (const auto& f : local) {
      std::array<std::int32_t, 3> k = f;
      std::sort(k.begin(), k.end());
      faces.push_back({k, f});
    }
  }
  std::sort(faces.begin(), faces.end(), [](const Face& x, const Face& y) { return x.key < y.key; });
  std::vector<std::array<std::int32_t, 3>> out;
  for (std::size_t i = 0; i < faces.size();) {
    std::size_t j = i + 1;
    while (j < faces.size() && faces[j].key == faces[i].key) ++j;
    if (j - i == 1) out.push_back(faces[i].oriented);
    i = j;
  }
  Triangles tris(static_cast<Eigen::Index>(out.size()), 3);
  for (std::size_t f = 0; f < out.size(); ++f) {
    for (int k = 0; k < 3; ++k) tris(static_cast<Eigen::Index>(f), k) = out[f][static_cast<std::size_t>(k)];
  }
  return tris;
}

}  // namespace tetrig::rigbuild
