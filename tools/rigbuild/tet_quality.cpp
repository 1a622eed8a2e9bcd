// Tet shape measures (tet_quality.hpp): the radius ratio 3 r / R (r = 3 V / total face area,
// R = |a^2 (b x c) + b^2 (c x a) + c^2 (a x b)| / (12 V) for edge vectors a, b, c from one corner)
// and the six dihedral angles (pi minus the angle between the outward normals of the two faces
// meeting at each edge).
#include "tetrig/rigbuild/tet_quality.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <vector>

namespace tetrig::rigbuild {
namespace {

std::array<Eigen::Vector3d, 4> corners(const TetMesh& mesh, std::int32_t t) {
  return {mesh.vertices.row(mesh.tets(t, 0)).transpose(), mesh.vertices.row(mesh.tets(t, 1)).transpose(),
          mesh.vertices.row(mesh.tets(t, 2)).transpose(), mesh.vertices.row(mesh.tets(t, 3)).transpose()};
}

double radiusRatio(const std::array<Eigen::Vector3d, 4>& p) {
  const Eigen::Vector3d a = p[1] - p[0], b = p[2] - p[0], c = p[3] - p[0];
  const double six_volume = std::abs(a.dot(b.cross(c)));
  const double face_area2 = (p[1] - p[0]).cross(p[2] - p[0]).norm() + (p[1] - p[0]).cross(p[3] - p[0]).norm() +
                            (p[2] - p[0]).cross(p[3] - p[0]).norm() + (p[2] - p[1]).cross(p[3] - p[1]).norm();  // 2 x total area
  const double r_numerator = (a.squaredNorm() * b.cross(c) + b.squaredNorm() * c.cross(a) + c.squaredNorm() * a.cross(b)).norm();
  if (!(six_volume > 0.0) || !(face_area2 > 0.0) || !(r_numerator > 0.0)) return 0.0;
  // r = 3 V / A = six_volume / face_area2; R = r_numerator / (2 six_volume).
  const double r = six_volume / face_area2;
  const double big_r = r_numerator / (2.0 * six_volume);
  return std::clamp(3.0 * r / big_r, 0.0, 1.0);
}

}  // namespace

double tetRadiusRatio(const TetMesh& mesh, std::int32_t t) { return radiusRatio(corners(mesh, t)); }

TetQuality tetQuality(const TetMesh& mesh, std::int32_t first, std::int32_t count) {
  TetQuality q;
  const std::int32_t begin = std::clamp<std::int32_t>(first, 0, mesh.tetCount());
  const std::int32_t end = count < 0 ? mesh.tetCount() : std::min(mesh.tetCount(), begin + count);
  if (end <= begin) return q;
  std::vector<double> ratios;
  ratios.reserve(static_cast<std::size_t>(end - begin));
  q.min_dihedral_degrees = 180.0;
  static constexpr int kFaces[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};  // face k opposite corner k, outward for V > 0
  for (std::int32_t t = begin; t < end; ++t) {
    const std::array<Eigen::Vector3d, 4> p = corners(mesh, t);
    const double rho = radiusRatio(p);
    ratios.push_back(rho);
    q.below_0_1 += rho < 0.1 ? 1 : 0;
    std::array<Eigen::Vector3d, 4> n;
    const double orientation = (p[1] - p[0]).dot((p[2] - p[0]).cross(p[3] - p[0])) >= 0.0 ? 1.0 : -1.0;
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector3d& x = p[static_cast<std::size_t>(kFaces[k][0])];
      const Eigen::Vector3d& y = p[static_cast<std::size_t>(kFaces[k][1])];
      const Eigen::Vector3d& z = p[static_cast<std::size_t>(kFaces[k][2])];
      n[static_cast<std::size_t>(k)] = orientation * (y - x).cross(z - x);
      const double len = n[static_cast<std::size_t>(k)].norm();
      if (len > 0.0) n[static_cast<std::size_t>(k)] /= len;
    }
    // The edge shared by faces i and j (opposite corners i and j): dihedral = pi - angle(n_i, n_j).
    for (int i = 0; i < 4; ++i) {
      for (int j = i + 1; j < 4; ++j) {
        const double c = std::clamp(n[static_cast<std::size_t>(i)].dot(n[static_cast<std::size_t>(j)]), -1.0, 1.0);
        const double dihedral = 180.0 - std::acos(c) * 180.0 / M_PI;
        q.min_dihedral_degrees = std::min(q.min_dihedral_degrees, dihedral);
        q.max_dihedral_degrees = std::max(q.max_dihedral_degrees, dihedral);
      }
    }
  }
  q.tets = end - begin;
  const auto mid = ratios.begin() + static_cast<std::ptrdiff_t>(ratios.size() / 2);
  std::nth_element(ratios.begin(), mid, ratios.end());
  q.median_radius_ratio = *mid;
  q.min_radius_ratio = *std::min_element(ratios.begin(), ratios.end());
  return q;
}

std::string TetQuality::summary() const {
  char buf[160];
  std::snprintf(buf, sizeof buf, "radius ratio min %.3g median %.3g (%d of %d below 0.1), dihedral angles %.3g-%.4g degrees",
                min_radius_ratio, median_radius_ratio, below_0_1, tets, min_dihedral_degrees, max_dihedral_degrees);
  return buf;
}

}  // namespace tetrig::rigbuild
