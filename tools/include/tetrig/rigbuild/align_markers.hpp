// Alignment of a marker set (device millimetres, device axes) to a mesh (rig units, rig axes):
// Stoll et al. 2007 section 3.2 align the model to the first frame's markers by hand; this does it
// automatically for a T-pose clip and a T-pose mesh.
//   1. axes and unit: the device up axis is turned onto the rig up axis, millimetres are scaled to
//      the rig unit;
//   2. coarse: heading from the principal horizontal axis of the marker cloud and of the surface
//      (the arm span of a T-pose), four candidate headings (0, 90, 180, 270 degrees around it),
//      scale from the heights, translation from the bounding-box centres;
//   3. iterative closest points against the surface: each step pairs every marker with its closest
//      surface point (optionally pushed out along the normal by the expected marker offset) and
//      solves the transform in closed form (Umeyama 1991, least squares, optionally weighted by
//      |r|^(p-2) for an L_p fit). Phase A: rigid ICP at the height-based scale from each heading
//      candidate; the candidate with the smallest mean distance wins (a free scale would shrink
//      the marker cloud onto the surface: distances -> 0 as scale -> 0). Phase B: similarity ICP
//      from there, the scale kept within max_scale_change of the height estimate.
// Whether the result is plausible (scale, pose, distances) is judged by alignment_checks.hpp.
//
// Offline, any thread, allocates, throws RigBuildError.
#pragma once

#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/closest_point.hpp"
#include "tetrig/rigbuild/surface_mesh.hpp"

#include <Eigen/Core>

#include <functional>
#include <string>
#include <vector>

namespace tetrig::rigbuild {

struct AlignmentOptions {
  std::string device_up = "z";        // "x", "y", "z", "-x", "-y", "-z"
  std::string rig_up = "y";
  double rig_units_per_mm = 1e-3;     // metres
  std::string mode = "auto";          // "auto", "units", "matrix"
  std::vector<double> matrix;         // "matrix": 3x4 row-major, device mm -> rig units
  int icp_iterations = 60;
  bool icp_scale = true;
  double max_scale_change = 0.25;
  double marker_offset = 0.0;
  double fit_power = 2.0;             // ICP fits minimise sum |r|^p (IRLS for p != 2); p > 2 weights the worst markers up
  std::function<void(double)> progress;  // fraction done, may be empty
};

struct AlignmentResult {
  RigAlignment alignment;
  std::vector<Eigen::Vector3d> rig_positions;  // markers after alignment, rig units
  std::vector<double> distances;               // to the surface, rig units
  double median_distance = 0.0, max_distance = 0.0, mean_distance = 0.0;
  int candidate = -1;                          // heading candidate chosen (auto)
  int iterations = 0;                          // ICP iterations of the chosen candidate
};

// Unit vector of an axis name; throws RigBuildError for anything else.
Eigen::Vector3d axisVector(const std::string& axis);

// The rotation that turns the device's up axis onto the rig's ("z", "-y", ...): the shortest
// rotation between them, or a half turn about x (or y) when they are opposite. Throws on an
// unknown axis name.
Eigen::Matrix3d upAxisRotation(const std::string& device_up, const std::string& rig_up);

AlignmentResult alignMarkers(const std::vector<Eigen::Vector3d>& device_mm, const SurfaceMesh& surface,
                             const AlignmentOptions& options);

// Closest point on the surface to a rig-space point.
using ClosestPointFunction = std::function<ClosestPoint(const Eigen::Vector3d&)>;

// The same with the caller's closest-point function instead of the exact SurfaceQuery (e.g. an
// approximate one when many clip frames are screened, rest_frame_search.hpp); `surface` still
// gives the coarse estimate (bounding box, principal horizontal axis). Distances in the result
// are `closest`'s.
AlignmentResult alignMarkers(const std::vector<Eigen::Vector3d>& device_mm, const SurfaceMesh& surface,
                             const AlignmentOptions& options, const ClosestPointFunction& closest);

}  // namespace tetrig::rigbuild
