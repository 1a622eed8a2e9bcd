// The plausibility bound on a published pose (docs/live.md, "Never NaN, never absurd").
//
//   PoseBound bound(rest_diagonal, max_abs_coordinate);   // load
//   bound.beginTargets();                                   // per frame: the frame's handle targets
//   for (p : targets) bound.addTarget(p);
//   bool ok = bound.accepts(xyz, n);                        // the pose, n floats (x, y, z per vertex)
//
// A pose is accepted when every coordinate is finite, |c| <= max_abs_coordinate, and every vertex
// lies inside the box of the frame's handle targets grown by kPoseBoundMargin rest diagonals on
// each side (the rest diagonal: of the fine mesh's bounding box at rest). Every part of a rig is
// tied to some handle through the body, so a pose the targets can produce stays within about one
// body length of them, however they stretch or swing it; a solve that diverges (positions growing
// frame after frame) leaves the box within a few frames, long before it overflows. With no target
// added the box test is skipped (only the finite and absolute tests apply).
// accepts() and the target calls allocate nothing and do not throw.
#pragma once

#include <Eigen/Core>

#include <cstddef>

namespace tetrig {

inline constexpr double kPoseBoundMargin = 3.0;  // rest diagonals of slack around the targets' box

class PoseBound {
 public:
  PoseBound() = default;
  PoseBound(double rest_diagonal, double max_abs_coordinate) noexcept;

  void beginTargets() noexcept;
  void addTarget(const Eigen::Vector3d& p) noexcept;  // non-finite targets are ignored
  bool accepts(const float* xyz, std::size_t floats) const noexcept;

  // The box accepts() tests against this frame: lo/hi per axis (after the margin and the
  // absolute bound). Empty targets: +-max_abs_coordinate.
  Eigen::Vector3d low() const noexcept;
  Eigen::Vector3d high() const noexcept;

 private:
  double margin_ = 0.0;
  double max_abs_ = 0.0;
  bool any_ = false;
  Eigen::Vector3d lo_ = Eigen::Vector3d::Zero(), hi_ = Eigen::Vector3d::Zero();
};

}  // namespace tetrig
