// Closest point on a triangle mesh (point-triangle distance by Voronoi-region classification,
// C. Ericson, "Real-Time Collision Detection", 2005, section 5.1.5), over all faces with
// bounding-sphere pruning: exact, O(#F) per query with a small constant.
//
// Offline, any thread; the query object is immutable after construction (concurrent queries are
// fine). Construction allocates; queries do not.
#pragma once

#include "tetrig/tet_mesh.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <vector>

namespace tetrig::rigbuild {

struct ClosestPoint {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();   // on the surface
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // unit normal of the face (outward for an outward surface)
  double distance = 0.0;
  std::int32_t face = -1;
};

class SurfaceQuery {
 public:
  // vertices #V by 3, triangles #F by 3 (both copied).
  SurfaceQuery(const Vertices& vertices, const Triangles& triangles);
  ClosestPoint closest(const Eigen::Vector3d& p) const;
  std::int32_t faceCount() const { return static_cast<std::int32_t>(centers_.size()); }

 private:
  Vertices vertices_;
  Triangles triangles_;
  std::vector<Eigen::Vector3d> centers_;
  std::vector<double> radii_;
};

// Closest point to p on triangle (a, b, c).
Eigen::Vector3d closestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                       const Eigen::Vector3d& c);

}  // namespace tetrig::rigbuild
