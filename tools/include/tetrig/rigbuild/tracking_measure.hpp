// Does the skin follow the performer? The tracking measure of a played clip (docs/fidelity.md,
// "Tracking").
//
// Each rig marker is glued to a skin point: the point of the fine surface nearest to the marker at
// the rig's rest pose (the clip's alignment frame), kept as barycentric coordinates (a, b, c) of
// one fine triangle, so that every pose carries it: s_m(x) = a x_i + b x_j + c x_k. In every frame
// in which marker m is measured (not predicted, not blending back), with M_m its measured position
// in rig units (the device's millimetres through rig.alignment):
//   e_m = | ||M_m - s_m(x)|| - ||M_m(rest) - s_m(x_rest)|| |,   in mm (the device's millimetres)
// the change of the marker-to-skin distance from its rest value. A skin that follows the markers
// keeps e near 0; a limb that lags or a knee that stays straight while its marker bends shows as
// tens of millimetres. The converged pose of a wrong rig is just as wrong, which the distance to the
// converged pose (tetrig_fidelity's error) cannot see.
//
// Offline (tools, benchmarks): construction allocates (one closest-point query per marker), every
// addFrame appends one sample per measured marker.
#pragma once

#include "tetrig/rig_file.hpp"

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace tetrig {
class LiveRig;
}

namespace tetrig::rigbuild {

// Nearest-rank percentiles of a sample (the smallest value with at least q of the samples at or
// below it); all zero for an empty sample.
struct Percentiles {
  double median = 0, p90 = 0, p99 = 0, max = 0;
  std::size_t count = 0;
};
Percentiles percentilesOf(std::vector<double> samples);

struct SkinPoint {
  std::int32_t triangle = -1;  // index into rig.fine_triangles
  double a = 0, b = 0, c = 0;  // barycentric coordinates of its corners 0, 1, 2
  double rest_distance = 0;    // ||marker - skin point|| at rest, rig units
};

class TrackingMeasure {
 public:
  explicit TrackingMeasure(const Rig& rig);

  // One frame: the fine mesh as published (#fine*3 floats, rig units) and, per rig marker
  // (rig.markers order), its measured position in rig units and whether it was measured.
  void addFrame(std::span<const float> fine_positions, std::span<const Eigen::Vector3d> marker_positions,
                std::span<const std::uint8_t> measured);
  // The same, from the live rig's last processFrame: a marker counts when its state is kMeasured
  // (its target is then the measurement itself).
  void addFrame(std::span<const float> fine_positions, const LiveRig& live);

  const std::vector<SkinPoint>& skinPoints() const { return skin_; }
  double mmPerRigUnit() const { return mm_per_unit_; }
  Percentiles all() const;                       // every measured marker-frame
  Percentiles marker(std::size_t index) const;   // one rig marker's frames
  std::size_t frames() const { return frames_; }

 private:
  const Rig& rig_;
  std::vector<SkinPoint> skin_;
  double mm_per_unit_ = 1.0;
  std::vector<std::vector<double>> samples_;  // per rig marker, mm
  std::size_t frames_ = 0;
};

}  // namespace tetrig::rigbuild
