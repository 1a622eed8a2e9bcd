// `tetrig build-rig`: from a surface (or a ready tet mesh), a rig description and optionally a
// marker clip, to a tetrig::Rig (runtime/include/tetrig/rig_file.hpp).
//
//   surface --import, validate--> fine mesh --decimate, TetGen--> body tet mesh
//   ready tet mesh (.node/.ele, .mesh) --> body tet mesh, fine mesh = its boundary surface
//   --> pose-transfer weights B (section 2.4)
//   --> markers: rest frame of the clip, aligned to the fine surface (align_markers.hpp), checked
//       against max_distance, bound by invisible tets (bind_markers.hpp), made vertex handles
//   --> selections of the description resolved onto tet vertices and tets
//   --> per-tet stiffness, rigid groups, the Deformer built once as a check
//
// Offline, any thread, allocates, throws RigBuildError (or a reader's error) with a one-line message.
#pragma once

#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/align_markers.hpp"
#include "tetrig/rigbuild/pose_transfer_weights.hpp"
#include "tetrig/rigbuild/progress.hpp"
#include "tetrig/rigbuild/rig_description.hpp"

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace tetrig::rigbuild {

struct BuildRigInputs {
  std::filesystem::path mesh;                     // surface (OBJ, PLY, OFF, ...) or tet mesh (.node/.ele, .mesh)
  RigDescription description;                     // defaults when no JSON is given
  std::optional<std::filesystem::path> clip;      // overrides description.markers.clip
  std::optional<std::int32_t> tet_vertices;       // overrides description.tet_vertices
  std::optional<std::int64_t> frame;              // overrides description.markers.frame
  std::optional<double> max_marker_distance;      // overrides description.markers.max_distance
  bool check_deformer = true;                     // build a Deformer from the result (factorizes once)
};

struct BuildRigReport {
  bool tet_input = false;
  std::int32_t fine_vertices = 0, fine_triangles = 0;
  std::int32_t body_vertices = 0, body_tets = 0, interior_vertices = 0;
  std::int32_t markers = 0, invisible_tets = 0, markers_below_skin = 0;
  std::vector<std::string> marker_labels;
  std::optional<AlignmentResult> alignment;
  PoseTransferStats pose;
  double import_seconds = 0, tetrahedralize_seconds = 0, pose_seconds = 0, align_seconds = 0, bind_seconds = 0,
         check_seconds = 0, factorize_seconds = 0;
  std::vector<std::string> notes;                 // repairs and choices worth telling the user
};

Rig buildRig(const BuildRigInputs& inputs, BuildRigReport* report = nullptr, Progress* progress = nullptr);

// True for .node, .ele and .mesh (a ready tet mesh).
bool isTetMeshPath(const std::filesystem::path& path);

}  // namespace tetrig::rigbuild
