// Invisible tets joining markers to the closest boundary faces (Stoll et al. 2007, section 3.2).
#include "tetrig/rigbuild/bind_markers.hpp"

#include "tetrig/rigbuild/boundary_surface.hpp"
#include "tetrig/rigbuild/closest_point.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cstdio>
#include <limits>
#include <utility>
#include <vector>

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
    const int search = options.face_spread > 0 ? std::max(options.search_faces, 128) : options.search_faces;
    const std::size_t k = std::min<std::size_t>(static_cast<std::size_t>(std::max(search, 1)), order.size());
    std::partial_sort(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(k), order.end());
    MarkerBinding binding;
    binding.tet_vertex = mv;
    // The faces a pass may take, in order of distance: (face, its tet's corners).
    std::vector<std::pair<Eigen::Index, std::array<std::int32_t, 4>>> qualifying;
    for (int pass = 0; pass < 2 && binding.bound_faces == 0; ++pass) {
      qualifying.clear();
      for (std::size_t i = 0; i < k; ++i) {
        const Eigen::Index f = order[i].second;
        const std::int32_t ia = boundary(f, 0), ib = boundary(f, 1), ic = boundary(f, 2);
        const Eigen::Vector3d a = body.vertices.row(ia), b = body.vertices.row(ib), c = body.vertices.row(ic);
        const Eigen::Vector3d n = (b - a).cross(c - a);
        if (!(n.norm() > 0)) continue;
        const double h = n.normalized().dot(p - a);
        const double edge = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
        const double need = options.min_relative_height * edge;
        if (pass == 0 && h >= need) {
          qualifying.push_back({f, {ia, ib, ic, mv}});
        } else if (pass == 1 && h <= -need) {
          qualifying.push_back({f, {ia, ic, ib, mv}});
          binding.below_skin = true;
        }
      }
      if (qualifying.empty()) {
        binding.below_skin = false;
        continue;
      }
      if (options.face_spread <= 0) {
        for (std::size_t i = 0; i < qualifying.size() && binding.bound_faces < options.faces_per_marker; ++i) {
          extra.push_back(qualifying[i].second);
          ++binding.bound_faces;
        }
        continue;
      }
      // Tripod: farthest-point sampling of face centroids within the footprint radius.
      const auto centroid = [&](Eigen::Index f) {
        return ((body.vertices.row(boundary(f, 0)) + body.vertices.row(boundary(f, 1)) + body.vertices.row(boundary(f, 2))) / 3.0)
            .transpose()
            .eval();
      };
      const Eigen::Index f0 = order[0].second;
      const Eigen::Vector3d a0 = body.vertices.row(boundary(f0, 0)), b0 = body.vertices.row(boundary(f0, 1)),
                            c0 = body.vertices.row(boundary(f0, 2));
      const Eigen::Vector3d foot = closestPointOnTriangle(p, a0, b0, c0);
      const double nearest_edge = std::max({(b0 - a0).norm(), (c0 - b0).norm(), (a0 - c0).norm()});
      const double radius = options.face_spread * std::max((p - foot).norm(), nearest_edge);
      std::vector<Eigen::Vector3d> taken{centroid(qualifying[0].first)};
      std::vector<char> used(qualifying.size(), 0);
      used[0] = 1;
      extra.push_back(qualifying[0].second);
      ++binding.bound_faces;
      while (binding.bound_faces < options.faces_per_marker) {
        double best = -1.0;
        std::size_t best_i = 0;
        for (std::size_t i = 1; i < qualifying.size(); ++i) {
          if (used[i]) continue;
          const Eigen::Vector3d g = centroid(qualifying[i].first);
          if ((g - foot).norm() > radius) continue;
          double nearest = std::numeric_limits<double>::infinity();
          for (const Eigen::Vector3d& t : taken) nearest = std::min(nearest, (g - t).norm());
          if (nearest > best) {
            best = nearest;
            best_i = i;
          }
        }
        if (best < 0) {
          // Nothing left within the footprint (a marker near the skin): the nearest unused face.
          for (std::size_t i = 1; i < qualifying.size() && best < 0; ++i) {
            if (!used[i]) {
              best = 0.0;
              best_i = i;
            }
          }
          if (best < 0) break;
        }
        used[best_i] = 1;
        taken.push_back(centroid(qualifying[best_i].first));
        extra.push_back(qualifying[best_i].second);
        ++binding.bound_faces;
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
