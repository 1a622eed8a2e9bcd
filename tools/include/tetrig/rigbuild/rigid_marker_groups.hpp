// Markers that move as one rigid body over a clip (the three markers on a shoe, the four on a
// head band), found from the clip's geometry alone, and the skin each group drives.
//
// A pair of markers is rigidly linked when the spread of their distance over the clip is small:
//   d_ij(f) = |x_i(f) - x_j(f)| over the frames where both are valid (a sample of at most
//   max_frames frames, evenly spaced), spread_ij = P95(d_ij) - P5(d_ij);
//   linked when spread_ij <= max(max_spread_mm, max_spread_fraction * median(d_ij)).
// Groups are built by complete linkage (every pair of a group linked), pairs taken in order of
// increasing spread; a group needs at least min_markers markers that are not collinear at rest
// (their rest triangle of largest area has an area of at least min_area_fraction of the
// squared largest distance), else it cannot give an orientation and is dropped.
//
// A clip shows which markers move together only where the performer moved the joints between
// them: in a static calibration trial every pair keeps its distance, and all markers would form
// one group. So a group whose extent (its largest median marker distance) exceeds
// max_extent_fraction of the whole marker set's (the largest median distance of any pair) is not
// a body part the clip has told apart: it is left out (returned in `too_large`, for the report).
//
// The skin a group drives (groupSkinMask): the tet vertices p, at rest, with
//   d_in(p) <= radius_fraction * extent   and   d_in(p) <= next_marker_fraction * d_out(p),
// d_in the distance to the group's nearest marker, d_out to the nearest marker of the rest of the
// rig, extent the group's largest marker distance. The first bound keeps the region near its
// markers; the second stops it well short of where the next body part's markers are (with 0.25, at
// most a fifth of the way from a group marker towards another marker), so the skin of the joint
// between two parts (the hip crease between the pelvis and the thigh markers) stays with the solve,
// and two groups' skin never meet.
//
// Offline, any thread, allocates.
#pragma once

#include "tetrig/tet_mesh.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace tetrig::rigbuild {

struct RigidMarkerGroupOptions {
  double max_spread_mm = 5.0;          // absolute floor of the allowed distance spread
  double max_spread_fraction = 0.01;   // ... or this fraction of the pair's median distance
  int min_markers = 3;
  double min_area_fraction = 0.05;     // non-collinearity at rest (see above)
  int max_frames = 2000;               // frames sampled from the clip
  double min_valid_fraction = 0.5;     // a pair needs both markers valid in this fraction of the sample
  double max_extent_fraction = 0.35;   // a group spans at most this fraction of the marker set (see above)
};

struct RigidMarkerGroup {
  std::vector<std::int32_t> markers;  // indices into the clip's marker list, ascending
  double spread_mm = 0.0;             // the largest spread_ij of its pairs
  double extent_mm = 0.0;             // the largest median d_ij of its pairs
};

// frame(f, positions, valid): the markers of clip frame f in mm (any fixed axes); valid[i] false
// for a gap. rest: the markers at the rest frame (any unit; used for collinearity only).
using MarkerFrameReader = std::function<void(std::int64_t, std::vector<Eigen::Vector3d>&, std::vector<std::uint8_t>&)>;

std::vector<RigidMarkerGroup> findRigidMarkerGroups(std::int64_t frame_count, std::size_t marker_count, const MarkerFrameReader& frame,
                                                    const std::vector<Eigen::Vector3d>& rest, const RigidMarkerGroupOptions& options = {},
                                                    std::vector<RigidMarkerGroup>* too_large = nullptr);

// The spread_ij of every pair (row-major marker_count x marker_count; +inf where a pair had too few
// frames together), as findRigidMarkerGroups measures it. For reports and tests.
std::vector<double> markerDistanceSpreads(std::int64_t frame_count, std::size_t marker_count, const MarkerFrameReader& frame,
                                          const RigidMarkerGroupOptions& options = {}, std::vector<double>* median_distance = nullptr);

// The tet vertices (rows of `vertices`, rig units) a group drives: see above. markers: every rig
// marker's rest position (rig units), group: indices into it, extent: the group's largest marker
// distance (rig units).
struct GroupSkinOptions {
  double radius_fraction = 0.2;        // of the group's extent
  double next_marker_fraction = 0.25;  // of the distance to the nearest marker outside the group
};
std::vector<std::uint8_t> groupSkinMask(const Vertices& vertices, const std::vector<Eigen::Vector3d>& markers,
                                        const std::vector<std::int32_t>& group, double extent, const GroupSkinOptions& options = {});

}  // namespace tetrig::rigbuild
