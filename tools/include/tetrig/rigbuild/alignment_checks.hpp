// Is an automatic marker alignment believable? alignMarkers (align_markers.hpp) always returns the
// best similarity it finds, also for a marker set that does not belong on the mesh: a human marker
// set on a four-legged animal (fit scale 0.06), or an arms-down frame on a T-pose mesh (the cloud
// shrunk to 0.8, ankle markers at the knees, wrist markers at the hips). Both fit "well" by
// distance, since the ICP slides markers onto whatever skin is nearest. These checks look at what
// a good fit must also have:
//   - scale: the fit scale (rig units per device unit, relative to the unit conversion) within
//     [min_fit_scale, max_fit_scale] (default 0.85..1.18: people differ in size, a marker set for
//     another body or a mesh in another unit does not);
//   - pose, extent: along the mesh's up axis and its widest horizontal axis (the arm span of a
//     T-pose), the outermost markers reach within max_extent_gap (default 0.15) of the mesh's
//     extent from each end: ankle markers near the feet, head markers near the top, wrist markers
//     near the ends of the arms;
//   - pose, distance: at most max_far_fraction (default 25 %) of the markers further from the
//     surface than far_distance_fraction (default 3 %) of the mesh's bounding-box diagonal.
// Measured on the real data (docs/rig-builder.md, "Plausibility checks") the good pairings are far
// inside every limit and each refused pairing breaks at least one by a wide margin.
//
// Offline, any thread, allocates; never throws for a bad fit (the caller decides).
#pragma once

#include "tetrig/rigbuild/surface_mesh.hpp"

#include <Eigen/Core>

#include <string>
#include <vector>

namespace tetrig::rigbuild {

struct AlignmentCheckLimits {
  bool check_scale = true;
  bool check_pose = true;
  double min_fit_scale = 0.85;
  double max_fit_scale = 1.18;
  double max_extent_gap = 0.15;          // fraction of the mesh's extent along the axis
  double far_distance_fraction = 0.03;   // of the mesh's bounding-box diagonal
  double max_far_fraction = 0.25;        // of the markers
};

// Where the markers end along one axis of the mesh, against where the mesh ends.
struct ExtentCoverage {
  Eigen::Vector3d axis = Eigen::Vector3d::Zero();  // unit, rig space
  double mesh_lo = 0, mesh_hi = 0;                 // mesh vertices' extreme coordinates along axis
  double marker_lo = 0, marker_hi = 0;
  std::string label_lo, label_hi;                  // the outermost markers
  double gap_lo = 0, gap_hi = 0;                   // (marker_lo - mesh_lo) and (mesh_hi - marker_hi) / mesh extent; < 0: beyond the mesh
};

struct AlignmentCheck {
  double fit_scale = 1.0;
  ExtentCoverage up;                  // along the mesh's up axis
  ExtentCoverage across;              // along its widest horizontal axis (principal axis of the area)
  double diagonal = 0.0;              // mesh bounding-box diagonal
  double far_distance = 0.0;          // far_distance_fraction * diagonal
  int far_markers = 0, markers = 0;   // markers further than far_distance, of all
  double median_distance = 0.0, max_distance = 0.0;
  std::vector<std::string> scale_failures;  // one clause each ("fit scale 0.061 is outside 0.85..1.18")
  std::vector<std::string> pose_failures;
  bool ok() const { return scale_failures.empty() && pose_failures.empty(); }
  // The measured numbers in one line (scale, extents, distances).
  std::string summary() const;
  // Every failure, scale then pose, joined by "; " ("" when ok()).
  std::string failures() const;
};

// positions / distances / labels: one per marker, rig space, after alignment. up_axis: the mesh's
// up axis name ("y", "-z", ...). Only the checks switched on in `limits` add failures; every number
// is measured either way.
AlignmentCheck checkAlignment(const SurfaceMesh& surface, const std::string& up_axis, const std::vector<Eigen::Vector3d>& positions,
                              const std::vector<double>& distances, const std::vector<std::string>& labels, double fit_scale,
                              const AlignmentCheckLimits& limits);

}  // namespace tetrig::rigbuild
