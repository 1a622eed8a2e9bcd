// The whole offline geometry chain in one call, for the CLI: import -> validate/repair ->
// decimate -> self-intersection repair -> TetGen -> pose-transfer weights B, with per-step
// timings and reports. Each step is its own header (import_surface.hpp, validate_surface.hpp,
// decimate_surface.hpp, repair_self_intersections.hpp, tetrahedralize_surface.hpp,
// pose_transfer_weights.hpp); this only chains them.
//
// Offline, any thread, allocates, throws RigBuildError (one line: what, where, what to do).
#pragma once

#include "tetrig/rigbuild/import_surface.hpp"
#include "tetrig/rigbuild/pose_transfer_weights.hpp"
#include "tetrig/rigbuild/tetrahedralize_surface.hpp"
#include "tetrig/rigbuild/validate_surface.hpp"

#include <Eigen/SparseCore>

#include <filesystem>
#include <functional>
#include <string>

namespace tetrig::rigbuild {

struct RigGeometryOptions {
  ImportOptions import;
  ValidateOptions validate;
  DecimateOptions decimate;                // decimate.target_vertices = the tet-vertex budget
  TetrahedralizeOptions tetrahedralize;
  SelfIntersectionOptions intersections;
  PoseTransferOptions pose_transfer;
  int retries = 6;                         // extra decimation targets tried (see buildCoarseTetMesh)
};

struct RigGeometryTimings {  // seconds, wall clock
  double import = 0, validate = 0, coarse = 0, weights = 0;
};

struct RigGeometry {
  SurfaceMesh fine;                        // validated, repaired fine surface (the rendered mesh)
  ImportStats import_stats;
  SurfaceReport surface_report;
  CoarseRig coarse;                        // coarse.tets.mesh is the tet mesh the runtime deforms
  Eigen::SparseMatrix<double, Eigen::RowMajor> b;  // #fine by #tetV, rows sum to 1
  PoseTransferStats b_stats;
  double rest_error = 0.0;                 // restReconstructionError(b, fine, tets), relative
  RigGeometryTimings seconds;
};

// `progress` (may be empty) receives one short line per finished step.
RigGeometry buildRigGeometry(const std::filesystem::path& surface, const RigGeometryOptions& options = {},
                             const std::function<void(const std::string&)>& progress = {});

}  // namespace tetrig::rigbuild
