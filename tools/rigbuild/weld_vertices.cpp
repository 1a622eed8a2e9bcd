// Vertex welding with a uniform hash grid: a vertex joins the first earlier representative within
// the tolerance found in its own or the 26 neighbouring cells (cell size = tolerance).
#include "tetrig/rigbuild/weld_vertices.hpp"

#include "tetrig/rigbuild/cell_key.hpp"

#include <array>
#include <cmath>
#include <cstring>
#include <unordered_map>

namespace tetrig::rigbuild {
std::vector<std::int32_t> weldVertices(SurfaceMesh& mesh, double tolerance) {
  const std::int32_t n = mesh.vertexCount();
  std::vector<std::int32_t> representative(static_cast<size_t>(n));
  const double cell = tolerance > 0.0 ? tolerance : 0.0;
  const double tol2 = tolerance * tolerance;
  // Exact mode keys on the coordinates' bit patterns; tolerance mode on grid cells.
  std::unordered_map<CellKey, std::vector<std::int32_t>, CellHash> grid;
  grid.reserve(static_cast<size_t>(n));
  constexpr double kMaxCell = 4.0e18;
  for (std::int32_t v = 0; v < n; ++v) {
    representative[static_cast<size_t>(v)] = v;
    const Eigen::RowVector3d p = mesh.vertices.row(v);
    if (!p.allFinite()) continue;  // never merged
    if (cell == 0.0) {
      CellKey key{};
      std::memcpy(&key.x, &p[0], sizeof(double));
      std::memcpy(&key.y, &p[1], sizeof(double));
      std::memcpy(&key.z, &p[2], sizeof(double));
      if (p[0] == 0.0) key.x = 0;  // -0.0 == 0.0
      if (p[1] == 0.0) key.y = 0;
      if (p[2] == 0.0) key.z = 0;
      auto& bucket = grid[key];
      if (bucket.empty()) {
        bucket.push_back(v);
      } else {
        representative[static_cast<size_t>(v)] = bucket.front();
      }
      continue;
    }
    std::array<double, 3> q{p[0] / cell, p[1] / cell, p[2] / cell};
    if (std::abs(q[0]) > kMaxCell || std::abs(q[1]) > kMaxCell || std::abs(q[2]) > kMaxCell) continue;
    const CellKey home{static_cast<std::int64_t>(std::floor(q[0])), static_cast<std::int64_t>(std::floor(q[1])),
                       static_cast<std::int64_t>(std::floor(q[2]))};
    std::int32_t found = -1;
    for (std::int64_t dx = -1; dx <= 1 && found < 0; ++dx) {
      for (std::int64_t dy = -1; dy <= 1 && found < 0; ++dy) {
        for (std::int64_t dz = -1; dz <= 1 && found < 0; ++dz) {
          const auto it = grid.find(CellKey{home.x + dx, home.y + dy, home.z + dz});
          if (it == grid.end()) continue;
          for (const std::int32_t r : it->second) {
            if ((mesh.vertices.row(r) - p).squaredNorm() <= tol2) {
              found = r;
              break;
            }
          }
        }
      }
    }
    if (found >= 0) {
      representative[static_cast<size_t>(v)] = found;
    } else {
      grid[home].push_back(v);
    }
  }

  // Compact: representatives keep their order.
  std::vector<std::int32_t> new_index(static_cast<size_t>(n), -1);
  std::int32_t kept = 0;
  for (std::int32_t v = 0; v < n; ++v) {
    if (representative[static_cast<size_t>(v)] == v) new_index[static_cast<size_t>(v)] = kept++;
  }
  for (std::int32_t v = 0; v < n; ++v) {
    new_index[static_cast<size_t>(v)] = new_index[static_cast<size_t>(representative[static_cast<size_t>(v)])];
  }
  if (kept == n) return new_index;
  Vertices welded(kept, 3);
  for (std::int32_t v = 0; v < n; ++v) {
    if (representative[static_cast<size_t>(v)] == v) welded.row(new_index[static_cast<size_t>(v)]) = mesh.vertices.row(v);
  }
  mesh.vertices = std::move(welded);
  for (Eigen::Index f = 0; f < mesh.triangles.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const std::int32_t old = mesh.triangles(f, k);
      if (old >= 0 && old < n) mesh.triangles(f, k) = new_index[static_cast<size_t>(old)];
    }
  }
  return new_index;
}

}  // namespace tetrig::rigbuild
