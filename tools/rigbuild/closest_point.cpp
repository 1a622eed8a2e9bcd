// Closest point on a triangle mesh: point-triangle distance by Voronoi-region classification
// (Ericson, "Real-Time Collision Detection", 2005, section 5.1.5), bounding-sphere pruning.
#include "tetrig/rigbuild/closest_point.hpp"

#include "tetrig/rigbuild/surface_mesh.hpp"

#include <Eigen/Geometry>

#include <limits>

namespace tetrig::rigbuild {

Eigen::Vector3d closestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                       const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + (d1 / (d1 - d3)) * ab;
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + (d2 / (d2 - d6)) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);
  const double denom = va + vb + vc;
  if (!(std::abs(denom) > 0)) return a;  // zero-area face
  const double v = vb / denom, w = vc / denom;
  return a + ab * v + ac * w;
}

SurfaceQuery::SurfaceQuery(const Vertices& vertices, const Triangles& triangles) : vertices_(vertices), triangles_(triangles) {
  if (triangles_.rows() == 0) throw RigBuildError("closest-point query on a surface without triangles");
  centers_.resize(static_cast<std::size_t>(triangles_.rows()));
  radii_.resize(centers_.size());
  for (Eigen::Index f = 0; f < triangles_.rows(); ++f) {
    const Eigen::Vector3d a = vertices_.row(triangles_(f, 0)), b = vertices_.row(triangles_(f, 1)), c = vertices_.row(triangles_(f, 2));
    const Eigen::Vector3d m = (a + b + c) / 3.0;
    centers_[static_cast<std::size_t>(f)] = m;
    radii_[static_cast<std::size_t>(f)] = std::max({(a - m).norm(), (b - m).norm(), (c - m).norm()});
  }
}

ClosestPoint SurfaceQuery::closest(const Eigen::Vector3d& p) const {
  // Seed with the face of the nearest centre, then prune by bounding spheres.
  std::size_t seed = 0;
  double seed_d = std::numeric_limits<double>::infinity();
  for (std::size_t f = 0; f < centers_.size(); ++f) {
    const double d = (centers_[f] - p).squaredNorm();
    if (d < seed_d) {
      seed_d = d;
      seed = f;
    }
  }
  ClosestPoint best;
  double best_d = std::numeric_limits<double>::infinity();
  auto test = [&](std::size_t f) {
    const Eigen::Index fi = static_cast<Eigen::Index>(f);
    const Eigen::Vector3d a = vertices_.row(triangles_(fi, 0)), b = vertices_.row(triangles_(fi, 1)), c = vertices_.row(triangles_(fi, 2));
    const Eigen::Vector3d q = closestPointOnTriangle(p, a, b, c);
    const double d = (q - p).norm();
    if (d < best_d) {
      best_d = d;
      best.point = q;
      best.face = static_cast<std::int32_t>(f);
    }
  };
  test(seed);
  for (std::size_t f = 0; f < centers_.size(); ++f) {
    if (f == seed) continue;
    const double lower = (centers_[f] - p).norm() - radii_[f];
    if (lower < best_d) test(f);
  }
  best.distance = best_d;
  const Eigen::Index fi = best.face;
  const Eigen::Vector3d a = vertices_.row(triangles_(fi, 0)), b = vertices_.row(triangles_(fi, 1)), c = vertices_.row(triangles_(fi, 2));
  const Eigen::Vector3d n = (b - a).cross(c - a);
  best.normal = n.norm() > 0 ? Eigen::Vector3d(n.normalized()) : Eigen::Vector3d::Zero();
  return best;
}

}  // namespace tetrig::rigbuild
