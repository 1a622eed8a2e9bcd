// Invisible tets joining markers to the closest boundary faces (Stoll et al. 2007, section 3.2).
#include "tetrig/rigbuild/bind_markers.hpp"

#include "tetrig/rigbuild/boundary_surface.hpp"
#include "tetrig/rigbuild/closest_point.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cstdio>

namespace tetrig::rigbuild {

MarkerBindResult bindMarkers(const TetMesh& body, const std::vector<Eigen::Vector3d>& positions,
                             const std::vector<std::string>& labels, const MarkerBindOptions& options) {
  if (positions.size() != labels.size()) throw RigBuildError("bindMarkers: positions and labels differ in count");
  const Triangles boundary = boundaryFaces(body);
  if (boundary.rows() == 0) throw RigBuildError("bindMarkers: the tet mesh has no boundary faces");
  const std::int32_t nv = body.vertexCount();
  const std::int32_t nm = static_cast<std::int32_t>(positions.size());
  MarkerBindResult result;
  result.mesh.vertices.resize(nv + nm, 3);
  result.mesh.vertices.topRows(nv) = body.vertices;
  std::vector<std::array<std::int32_t, 4>> extra;
  const Eigen::Index nb = boundary.rows();
  std::vector<std::pair<double, Eigen::Index>> order(static_cast<std::size_t>(nb));
  for (std::int32_t m = 0; m < nm; ++m) {
    const Eigen::Vector3d p = positions[static_cast<std::size_t>(m)];
    const std::int32_t mv = nv + m;
    result.mesh.vertices.row(mv) = p.transpose();
    for (Eigen::Index f = 0; f < nb; ++f) {
      const Eigen::Vector3d a = body.vertices.row(boundary(f, 0)), b = body.vertices.row(boundary(f, 1)), c = body.vertices.row(boundary(f, 2));
      order[static_cast<std::size_t>(f)] = {(closestPointOnTriangle(p, a, b, c) - p).squaredNorm(), f};
    }
    const std::size_t k = std::min<std::size_t>(static_cast<std::size_t>(std::max(options.search_faces, 1)), order.size());
    std::partial_sort(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(k), order.end());
    MarkerBinding binding;
    binding.tet_vertex = mv;
    for (int pass = 0; pass < 2 && binding.bound_faces == 0; ++pass) {
      for (std::size_t i = 0; i < k && binding.bound_faces < options.faces_per_marker; ++i) {
        const Eigen::Index f = order[i].second;
        const std::int32_t ia = boundary(f, 0), ib = boundary(f, 1), ic = boundary(f, 2);
        const Eigen::Vector3d a = body.vertices.row(ia), b = body.vertices.row(ib), c = body.vertices.row(ic);
        const Eigen::Vector3d n = (b - a).cross(c - a);
        if (!(n.norm() > 0)) continue;
        const double h = n.normalized().dot(p - a);
        const double edge = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
        const double need = options.min_relative_height * edge;
        if (pass == 0 && h >= need) {
          extra.push_back({ia, ib, ic, mv});
          ++binding.bound_faces;
        } else if (pass == 1 && h <= -need) {
          extra.push_back({ia, ic, ib, mv});
          ++binding.bound_faces;
          binding.below_skin = true;
        }
      }
    }
    if (binding.bound_faces == 0) {
      throw RigBuildError("marker " + labels[static_cast<std::size_t>(m)] +
                          " cannot be bound: it lies in the plane of its " + std::to_string(k) +
                          " nearest boundary faces (every invisible tet would be degenerate); move it off the surface or exclude it");
    }
    if (binding.below_skin) ++result.below_skin;
    result.bindings.push_back(binding);
  }
  result.mesh.tets.resize(body.tetCount() + static_cast<Eigen::Index>(extra.size()), 4);
  result.mesh.tets.topRows(body.tetCount()) = body.tets;
  for (std::size_t i = 0; i < extra.size(); ++i) {
    for (int c = 0; c < 4; ++c) result.mesh.tets(body.tetCount() + static_cast<Eigen::Index>(i), c) = extra[i][static_cast<std::size_t>(c)];
  }
  result.invisible_tets = static_cast<std::int32_t>(extra.size());
  return result;
}

}  // namespace tetrig::rigbuild
