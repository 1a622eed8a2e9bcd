// Scenes shared by tests and benchmarks.
//
// Bars: nx * ny * nz unit cubes along z, each cube split into 5 tets with the split mirrored on
// alternate cubes so neighbouring faces agree (a conforming mesh). 4x4x33 gives 850 vertices and
// 2640 tets; 8x8x85 gives 6966 vertices and 27200 tets (the benchmark bars).
#pragma once

#include "tetrig/tet_mesh.hpp"

#include <Eigen/Geometry>

#include <cstdint>
#include <vector>

namespace tetrig::scenes {

TetMesh makeBar(int nx, int ny, int nz);

struct BarScene {
  TetMesh mesh;
  int nx = 0, ny = 0, nz = 0;
  std::vector<std::int32_t> near_vertices;  // z <= 5 % of the length
  std::vector<std::int32_t> far_vertices;   // z >= 95 % of the length
  std::vector<std::int32_t> near_tets;      // tets whose 4 corners are all near vertices
  std::vector<std::int32_t> far_tets;       // tets whose 4 corners are all far vertices
  Eigen::Vector3d axis_point;               // a point on the bar's long axis (centre of the near end)
  double length = 0.0;
};

BarScene makeBarScene(int nx, int ny, int nz);

// Rigid transform about the bar's long axis: rotate by `angle` (radians) about the axis through
// the cross-section centre, then translate by `shift`.
Eigen::Isometry3d barAxisTransform(const BarScene& bar, double angle, const Eigen::Vector3d& shift);

// Bends the bar into a circular arc in the y-z plane so that its far handle region is rotated by
// `angle` (radians, about the x axis) and sits where an arc of the bar's length puts it. Returns
// the rigid transform of the far region (the near region stays at rest).
Eigen::Isometry3d barBendTransform(const BarScene& bar, double angle);

// Rest positions of `vertices`, transformed.
std::vector<Eigen::Vector3d> transformedPositions(const TetMesh& mesh, const std::vector<std::int32_t>& vertices,
                                                  const Eigen::Isometry3d& transform);

}  // namespace tetrig::scenes
