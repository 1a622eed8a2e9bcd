// `tetrig build-rig`: from a surface (or a ready tet mesh), a rig description and optionally a
// marker clip, to a tetrig::Rig (runtime/include/tetrig/rig_file.hpp).
//
//   surface --import, validate--> fine mesh --decimate, TetGen--> body tet mesh
//   ready tet mesh (.node/.ele, .mesh) --> body tet mesh, fine mesh = its boundary surface
//   --> pose-transfer weights B (section 2.4)
//   --> markers: rest frame of the clip (given, or --frame auto: rest_frame_search.hpp) or marker
//       positions given directly (BuildRigInputs::marker_positions), aligned
//       to the fine surface (align_markers.hpp), checked for plausibility (alignment_checks.hpp)
//       and against the distance limit, all before decimation and TetGen; bound by invisible tets
//       (bind_markers.hpp), made vertex handles
//   --> selections of the description resolved onto tet vertices and tets
//   --> per-tet stiffness, rigid groups, the Deformer built once as a check
//
// Offline, any thread, allocates, throws RigBuildError (or a reader's error) with a one-line message.
#pragma once

#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/align_markers.hpp"
#include "tetrig/rigbuild/pose_transfer_weights.hpp"
#include "tetrig/rigbuild/progress.hpp"
#include "tetrig/rigbuild/rest_frame_search.hpp"
#include "tetrig/rigbuild/rig_description.hpp"

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace tetrig::rigbuild {

// Marker rest positions given directly instead of a clip frame (e.g. a generated character's
// T-pose markers): labels[i] at device_mm[i] (mm, device axes as markers.device_up says). They
// are aligned, checked and bound exactly like a clip's rest frame.
struct MarkerPositions {
  std::vector<std::string> labels;
  std::vector<Eigen::Vector3d> device_mm;
  std::string what = "the given marker positions";  // names them in messages
};

// The coarse level's tet-vertex budget when a marker-driven rig from a surface mesh is built
// without one being asked for (tetrig build-rig, the demo's rigs; docs/rig-builder.md): it is built
// when the rig has at least 4 times as many tet vertices.
inline constexpr std::int32_t kDefaultCoarseTetVertices = 150;

struct BuildRigInputs {
  std::filesystem::path mesh;                     // surface (OBJ, PLY, OFF, ...) or tet mesh (.node/.ele, .mesh)
  RigDescription description;                     // defaults when no JSON is given
  std::optional<std::filesystem::path> clip;      // overrides description.markers.clip
  std::optional<MarkerPositions> marker_positions;  // markers without a clip (not together with one)
  std::optional<std::int32_t> tet_vertices;       // overrides description.tet_vertices
  std::optional<std::int64_t> frame;              // overrides description.markers.frame (and "auto")
  bool frame_auto = false;                        // search the clip for the rest frame (overrides frame)
  std::optional<double> max_marker_distance;      // overrides description.markers.max_distance(_fraction)
  bool accept_implausible_alignment = false;      // build although the scale or pose checks fail (noted in the report)
  bool accept_pose_mismatch = false;              // ... although the pose checks fail (the scale is still checked)
  std::optional<double> min_fit_scale, max_fit_scale;  // override description.markers.checks
  bool check_deformer = true;                     // build a Deformer from the result (factorizes once)
  bool coarse_level = false;  // this is a coarse level (set by the build of its rig): a volume region that selects no
                              // tet is left out (noted) instead of stopping the build
  std::optional<std::int32_t> coarse_tet_vertices;  // also build the coarse level (Rig::coarse): the same inputs
                                                    // and rest frame with this tet-vertex budget (< tet_vertices)
};

struct BuildRigReport {
  bool tet_input = false;
  std::int32_t fine_vertices = 0, fine_triangles = 0;
  std::int32_t body_vertices = 0, body_tets = 0, interior_vertices = 0;
  std::int32_t markers = 0, invisible_tets = 0, markers_below_skin = 0;
  std::vector<std::string> marker_labels;
  std::optional<AlignmentResult> alignment;
  std::optional<AlignmentCheck> alignment_check;  // measured whenever markers were aligned
  std::optional<RestFrameSearch> frame_search;    // --frame auto
  std::int64_t rest_frame = -1;                   // the clip frame the markers were bound from
  double marker_distance_limit = 0;               // the limit applied (rig units)
  PoseTransferStats pose;
  double import_seconds = 0, tetrahedralize_seconds = 0, pose_seconds = 0, align_seconds = 0, bind_seconds = 0,
         check_seconds = 0, factorize_seconds = 0;
  std::vector<std::string> notes;                 // repairs and choices worth telling the user
  double coarse_seconds = 0;                      // building the coarse level (0: none)
  struct RigidRegion {
    std::string markers;        // their labels, '+'-separated
    double spread_mm = 0;       // the largest spread of their distances over the clip
    std::int32_t tet_vertices = 0;  // the skin they drive (0: none)
  };
  std::vector<RigidRegion> rigid_groups;          // markers found moving rigidly together (rigid_marker_groups.hpp)
};

// Throws RigBuildError before any heavy work when the rig would have no handle (no markers, no
// vertex, region or point handle), and before decimation when the marker alignment fails a check.
Rig buildRig(const BuildRigInputs& inputs, BuildRigReport* report = nullptr, Progress* progress = nullptr);

// True for .node, .ele and .mesh (a ready tet mesh).
bool isTetMeshPath(const std::filesystem::path& path);

}  // namespace tetrig::rigbuild
