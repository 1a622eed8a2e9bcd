// The plausibility bound on a published pose (docs/live.md, "Never NaN, never absurd").
//
//   PoseBound bound(rest_diagonal, max_abs_coordinate, capacity);   // load (allocates the median's scratch)
//   bound.beginTargets();                                            // per frame: the frame's targets
//   for (p : targets) bound.addTarget(p);
//   bound.endTargets();                                              // the centre: their per-axis median
//   bool ok = bound.accepts(xyz, n);                                 // the pose, n floats (x, y, z per vertex)
//
// A pose is accepted when every coordinate is finite, |c| <= max_abs_coordinate, and every vertex
// lies within kPoseBoundReach rest diagonals (the rest diagonal: of the fine mesh's bounding box at
// rest) of the centre along each axis. The centre is the per-axis median of the frame's targets
// (the live rig adds its markers' targets): a body stays within about one rest diagonal of where
// most of its markers are however they carry, turn or stretch it, while a median is not dragged
// by a minority of far targets, so a pose pulled away from the body by a few absurd targets, or a
// solve that diverges, leaves the box. With no target added the box test is skipped (only the
// finite and absolute tests apply). Targets beyond the capacity given at load are ignored.
// accepts(), the target calls and endTargets() allocate nothing and do not throw.
#pragma once

#include <Eigen/Core>

#include <cstddef>
#include <vector>

namespace tetrig {

inline constexpr double kPoseBoundReach = 2.0;  // rest diagonals from the targets' median, along each axis

class PoseBound {
 public:
  PoseBound() = default;
  // capacity: the most targets a frame adds (the median's scratch is sized here).
  PoseBound(double rest_diagonal, double max_abs_coordinate, std::size_t capacity);

  void beginTargets() noexcept;
  void addTarget(const Eigen::Vector3d& p) noexcept;  // non-finite targets are ignored
  void endTargets() noexcept;                          // sets the centre (and the box) from the targets added

  // As of the last endTargets() (beginTargets() alone clears the box to +-max_abs_coordinate).
  bool accepts(const float* xyz, std::size_t floats) const noexcept;
  // The box accepts() tests against: centre -+ reach per axis, within the absolute bound. No target:
  // +-max_abs_coordinate.
  Eigen::Vector3d low() const noexcept { return low_; }
  Eigen::Vector3d high() const noexcept { return high_; }
  Eigen::Vector3d centre() const noexcept { return centre_; }  // the targets' per-axis median (0 without targets)

 private:
  double reach_ = 0.0;
  double max_abs_ = 0.0;
  std::size_t count_ = 0;
  std::vector<double> axis_[3];  // this frame's targets, one coordinate per array (capacity at load)
  Eigen::Vector3d centre_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d low_ = Eigen::Vector3d::Zero(), high_ = Eigen::Vector3d::Zero();
};

}  // namespace tetrig
