// Self-intersection repair by local umbrella-operator (Laplacian) smoothing around the faces
// TetGen's intersection test reports (see repair_self_intersections.hpp).
#include "tetrig/rigbuild/repair_self_intersections.hpp"

#include <algorithm>

namespace tetrig::rigbuild {

SelfIntersectionRepair repairSelfIntersections(SurfaceMesh& surface, const SelfIntersectionOptions& options) {
  SelfIntersectionRepair repair;
  const auto nv = static_cast<size_t>(surface.vertexCount());
  std::vector<std::vector<std::int32_t>> neighbours(nv);
  for (std::int32_t f = 0; f < surface.triangleCount(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const std::int32_t a = surface.triangles(f, k);
      const std::int32_t b = surface.triangles(f, (k + 1) % 3);
      neighbours[static_cast<size_t>(a)].push_back(b);
      neighbours[static_cast<size_t>(b)].push_back(a);
    }
  }
  for (auto& n : neighbours) {
    std::sort(n.begin(), n.end());
    n.erase(std::unique(n.begin(), n.end()), n.end());
  }
  const Vertices original = surface.vertices;
  std::vector<char> in_region(nv, 0);
  std::vector<char> ever_moved(nv, 0);
  std::vector<std::int32_t> region;
  std::vector<std::int32_t> frontier;
  for (int round = 0; round <= options.max_rounds; ++round) {
    const std::vector<std::int32_t> faces = findSelfIntersections(surface);
    if (round == 0) repair.initial_faces = static_cast<std::int32_t>(faces.size());
    repair.remaining_faces = static_cast<std::int32_t>(faces.size());
    if (faces.empty() || round == options.max_rounds) break;
    ++repair.rounds;
    // Region: the corners of the reported faces, grown by `rings` rings.
    std::fill(in_region.begin(), in_region.end(), 0);
    region.clear();
    for (const std::int32_t f : faces) {
      for (int k = 0; k < 3; ++k) {
        const std::int32_t v = surface.triangles(f, k);
        if (!in_region[static_cast<size_t>(v)]) {
          in_region[static_cast<size_t>(v)] = 1;
          region.push_back(v);
        }
      }
    }
    size_t ring_start = 0;
    for (int ring = 0; ring < options.rings; ++ring) {
      const size_t ring_end = region.size();
      for (size_t i = ring_start; i < ring_end; ++i) {
        for (const std::int32_t w : neighbours[static_cast<size_t>(region[i])]) {
          if (!in_region[static_cast<size_t>(w)]) {
            in_region[static_cast<size_t>(w)] = 1;
            region.push_back(w);
          }
        }
      }
      ring_start = ring_end;
    }
    // Umbrella smoothing of the region (Jacobi steps).
    Vertices next = surface.vertices;
    for (int step = 0; step < options.smoothing_steps; ++step) {
      for (const std::int32_t v : region) {
        const auto& n = neighbours[static_cast<size_t>(v)];
        if (n.empty()) continue;
        Eigen::RowVector3d mean = Eigen::RowVector3d::Zero();
        for (const std::int32_t w : n) mean += surface.vertices.row(w);
        mean /= static_cast<double>(n.size());
        next.row(v) = surface.vertices.row(v) + options.lambda * (mean - surface.vertices.row(v));
      }
      surface.vertices = next;
    }
    for (const std::int32_t v : region) ever_moved[static_cast<size_t>(v)] = 1;
  }
  for (size_t v = 0; v < nv; ++v) {
    if (!ever_moved[v]) continue;
    repair.moved.push_back(static_cast<std::int32_t>(v));
    repair.max_displacement =
        std::max(repair.max_displacement, (surface.vertices.row(static_cast<Eigen::Index>(v)) - original.row(static_cast<Eigen::Index>(v))).norm());
  }
  repair.moved_vertices = static_cast<std::int32_t>(repair.moved.size());
  return repair;
}

}  // namespace tetrig::rigbuild
