// Invisible tets joining markers to the closest boundary faces (Stoll et al. 2007, section 3.2).
#include "tetrig/rigbuild/bind_markers.hpp"

#include "tetrig/tet_mesh.hpp"
#include "tetrig/rigbuild/closest_point.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <utility>
#include <vector>

namespace tetrig::rigbuild {

namespace {

double signedVolume(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c, const Eigen::Vector3d& d) {
  return (b - a).dot((c - a).cross(d - a)) / 6.0;
}

// The fan of a marker at p above the skin (MarkerBindOptions::fan_spread): tets (c, s_i, s_i+1, m)
// with positive orientation, or none when fewer than 2 are well shaped.
std::vector<std::array<std::int32_t, 4>> fanTets(const Vertices& v, const std::vector<std::int32_t>& surface_vertices,
                                                 const std::vector<Eigen::Vector3d>& vertex_normal, const Eigen::Vector3d& p,
                                                 std::int32_t mv, const Eigen::Vector3d& foot, std::int32_t center, double radius,
                                                 const MarkerBindOptions& options) {
  std::vector<std::array<std::int32_t, 4>> tets;
  const double h = (p - foot).norm();
  if (!(h > 0)) return tets;
  const Eigen::Vector3d u = (p - foot) / h;
  const Eigen::Vector3d e1 = u.unitOrthogonal(), e2 = u.cross(e1);
  const int n = std::max(options.fan_spokes, 3);
  std::vector<std::int32_t> spoke(static_cast<std::size_t>(n), -1);
  std::vector<double> reach(static_cast<std::size_t>(n), 0.0);
  const double two_pi = 2.0 * std::acos(-1.0);
  for (const std::int32_t w : surface_vertices) {
    if (w == center) continue;
    const Eigen::Vector3d q = v.row(w).transpose();
    if ((q - foot).norm() > radius) continue;
    if (vertex_normal[static_cast<std::size_t>(w)].dot(u) <= 0.0) continue;  // faces away from the marker
    const Eigen::Vector3d t = q - foot;
    const double x = t.dot(e1), y = t.dot(e2), r = std::hypot(x, y);
    double angle = std::atan2(y, x);
    if (angle < 0) angle += two_pi;
    const auto sector = std::min<std::size_t>(static_cast<std::size_t>(angle / two_pi * n), static_cast<std::size_t>(n - 1));
    if (r > reach[sector]) {
      reach[sector] = r;
      spoke[sector] = w;
    }
  }
  std::vector<std::int32_t> ring;
  for (const std::int32_t w : spoke) {
    if (w >= 0) ring.push_back(w);
  }
  if (ring.size() < 3) return tets;
  const Eigen::Vector3d c = v.row(center).transpose();
  for (std::size_t i = 0; i < ring.size(); ++i) {
    const std::int32_t a = ring[i], b = ring[(i + 1) % ring.size()];
    const Eigen::Vector3d pa = v.row(a).transpose(), pb = v.row(b).transpose();
    const Eigen::Vector3d nb = (pa - c).cross(pb - c);
    if (!(nb.norm() > 0)) continue;
    // The marker's height over the base plane against the base's longest edge (as for faces).
    const double height = std::abs(nb.normalized().dot(p - c));
    const double edge = std::max({(pa - c).norm(), (pb - pa).norm(), (c - pb).norm()});
    if (height < std::max(options.min_relative_height, 0.2) * edge) continue;
    if (signedVolume(c, pa, pb, p) > 0) {
      tets.push_back({center, a, b, mv});
    } else {
      tets.push_back({center, b, a, mv});
    }
  }
  if (tets.size() < 2) tets.clear();
  return tets;
}

}  // namespace

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
  // Fans: the surface vertices and their (area-weighted) outward normals.
  std::vector<std::int32_t> surface_vertices;
  std::vector<Eigen::Vector3d> vertex_normal;
  if (options.fan_spread > 0) {
    vertex_normal.assign(static_cast<std::size_t>(nv), Eigen::Vector3d::Zero());
    std::vector<char> on_surface(static_cast<std::size_t>(nv), 0);
    for (Eigen::Index f = 0; f < nb; ++f) {
      const Eigen::Vector3d a = body.vertices.row(boundary(f, 0)), b = body.vertices.row(boundary(f, 1)), c = body.vertices.row(boundary(f, 2));
      const Eigen::Vector3d n = (b - a).cross(c - a);
      for (int k = 0; k < 3; ++k) {
        vertex_normal[static_cast<std::size_t>(boundary(f, k))] += n;
        on_surface[static_cast<std::size_t>(boundary(f, k))] = 1;
      }
    }
    for (std::int32_t i = 0; i < nv; ++i) {
      if (on_surface[static_cast<std::size_t>(i)]) surface_vertices.push_back(i);
    }
  }
  std::vector<double> scale;  // per invisible tet (MarkerBindResult::invisible_scale)
  const auto add_tet = [&](const std::array<std::int32_t, 4>& corners, double s) {
    extra.push_back(corners);
    scale.push_back(s);
  };
  // Face f's plane: the marker's signed height over it and the height a tet needs (a fraction of
  // the longest edge); nullopt for a degenerate face.
  struct FaceHeight {
    double height = 0.0;
    double need = 0.0;
  };
  const auto face_height = [&](Eigen::Index f, const Eigen::Vector3d& p) -> std::optional<FaceHeight> {
    const Eigen::Vector3d a = body.vertices.row(boundary(f, 0)), b = body.vertices.row(boundary(f, 1)), c = body.vertices.row(boundary(f, 2));
    const Eigen::Vector3d n = (b - a).cross(c - a);
    if (!(n.norm() > 0)) return std::nullopt;
    const double edge = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    return FaceHeight{n.normalized().dot(p - a), options.min_relative_height * edge};
  };
  // The marker's closest point on face f0 (its nearest) and the footprint radius: spread times
  // the marker's height over it, at least the face's longest edge.
  struct Footprint {
    Eigen::Vector3d foot;
    double radius = 0.0;
  };
  const auto footprint = [&](Eigen::Index f0, const Eigen::Vector3d& p, double spread) {
    const Eigen::Vector3d a0 = body.vertices.row(boundary(f0, 0)), b0 = body.vertices.row(boundary(f0, 1)),
                          c0 = body.vertices.row(boundary(f0, 2));
    const Eigen::Vector3d foot = closestPointOnTriangle(p, a0, b0, c0);
    const double nearest_edge = std::max({(b0 - a0).norm(), (c0 - b0).norm(), (a0 - c0).norm()});
    return Footprint{foot, spread * std::max((p - foot).norm(), nearest_edge)};
  };
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
    if (options.fan_spread > 0) {
      const Eigen::Index f0 = order[0].second;
      const Footprint fp = footprint(f0, p, options.fan_spread);
      const std::optional<FaceHeight> h0 = face_height(f0, p);
      std::int32_t center = boundary(f0, 0);
      for (const std::int32_t i : {boundary(f0, 1), boundary(f0, 2)}) {
        if ((body.vertices.row(i).transpose() - fp.foot).norm() < (body.vertices.row(center).transpose() - fp.foot).norm()) center = i;
      }
      std::vector<std::array<std::int32_t, 4>> fan;
      if (h0 && h0->height > 0) fan = fanTets(body.vertices, surface_vertices, vertex_normal, p, mv, fp.foot, center, fp.radius, options);
      if (!fan.empty()) {
        // The weight the needles of the nearest qualifying faces (those the faces binding takes) would have.
        double needles = 0.0, fan_volume = 0.0;
        int counted = 0;
        for (std::size_t i = 0; i < k && counted < options.faces_per_marker; ++i) {
          const Eigen::Index f = order[i].second;
          const std::optional<FaceHeight> fh = face_height(f, p);
          if (!fh || fh->height < fh->need) continue;
          needles += signedVolume(body.vertices.row(boundary(f, 0)).transpose(), body.vertices.row(boundary(f, 1)).transpose(),
                                  body.vertices.row(boundary(f, 2)).transpose(), p);
          ++counted;
        }
        for (const auto& t : fan) {
          fan_volume += signedVolume(body.vertices.row(t[0]).transpose(), body.vertices.row(t[1]).transpose(),
                                     body.vertices.row(t[2]).transpose(), p);
        }
        const double s_fan =
            options.fan_weight > 0 && needles > 0 && fan_volume > 0 ? std::min(1.0, options.fan_weight * needles / fan_volume) : 1.0;
        for (const auto& t : fan) add_tet(t, s_fan);
        binding.bound_faces = static_cast<std::int32_t>(fan.size());
        result.bindings.push_back(binding);
        continue;
      }
    }
    // The faces a pass may take, in order of distance: (face, its tet's corners).
    std::vector<std::pair<Eigen::Index, std::array<std::int32_t, 4>>> qualifying;
    for (int pass = 0; pass < 2 && binding.bound_faces == 0; ++pass) {
      qualifying.clear();
      for (std::size_t i = 0; i < k; ++i) {
        const Eigen::Index f = order[i].second;
        const std::int32_t ia = boundary(f, 0), ib = boundary(f, 1), ic = boundary(f, 2);
        const std::optional<FaceHeight> fh = face_height(f, p);
        if (!fh) continue;
        const double h = fh->height, need = fh->need;
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
          add_tet(qualifying[i].second, 1.0);
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
      const auto [foot, radius] = footprint(order[0].second, p, options.face_spread);
      std::vector<Eigen::Vector3d> taken{centroid(qualifying[0].first)};
      std::vector<char> used(qualifying.size(), 0);
      used[0] = 1;
      add_tet(qualifying[0].second, 1.0);
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
        add_tet(qualifying[best_i].second, 1.0);
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
  result.invisible_scale = std::move(scale);
  return result;
}

}  // namespace tetrig::rigbuild
