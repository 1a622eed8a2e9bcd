// Posing a rig offline (`tetrig pose`, the deformation-survey test): rigid transforms for its
// region handles, the Deformer run to convergence, the fine mesh by pose transfer.
//
//   RigidTransform m = readDefFile("cylinder.def");          // the survey's 4x4 handle transform
//   PoseResult r = poseRig(rig, {{"handle", m}});            // other regions, markers, points stay at rest
//   writeObjAtomically("posed.obj", rig, r.fine_positions);  // fine mesh in the rig's vertex order
//
// Convergence: after every batch of `batch` iterations the run stops when no tet vertex moved
// more than step_tolerance of the fine mesh's bounding-box diagonal over the batch, or after
// max_iterations (then converged is false). The Deformer's energy (sum_j a_j ||F_j - R_j||^2,
// StepStats::energy) and its relative change over the last batch are reported, but they do not
// decide: the local-global iteration's energy flattens quadratically while a soft mode still
// drifts, and its float per-tet pass puts a noise floor of about 1e-8 on the relative change per
// 10 iterations; stopped there, the cactus edit was still 1e-3 of its diagonal away from its
// converged pose (measured, docs/rig-builder.md). A fixed count (iterations > 0) runs exactly
// that many.
//
// Offline, any thread, allocates, throws RigBuildError (one line: what, where, what to do).
#pragma once

#include "tetrig/deformer.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/surface_mesh.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace tetrig::rigbuild {

// A .def file of the Botsch-Sorkine deformation survey: '#' comment lines and a 4x4 affine
// matrix, row-major, 16 numbers (x' = M x in homogeneous coordinates). The region handles of a
// rig are rigid, so the matrix must be rigid: bottom row 0 0 0 1 and a linear part within
// `rotation_tolerance` (Frobenius norm) of a rotation, which is then projected onto its nearest
// rotation (the survey prints 6 digits: its matrices are rotations to about 1e-6). Anything else
// (fewer or more numbers, a word, non-finite values, a scale, shear or mirror) is refused with the
// path, what was found and what to do.
struct DefTransform {
  Eigen::Matrix4d matrix = Eigen::Matrix4d::Identity();  // as read
  RigidTransform rigid;                                   // nearest rotation + translation
  double rotation_error = 0.0;                            // ||linear - rotation||_F
};
DefTransform parseDefText(std::string_view text, const std::string& where, double rotation_tolerance = 1e-3);
DefTransform readDefFile(const std::filesystem::path& path, double rotation_tolerance = 1e-3);

struct PoseOptions {
  int iterations = 0;                    // > 0: exactly this many; 0: to convergence
  int max_iterations = 20000;            // bound when running to convergence
  int batch = 10;                        // iterations between two convergence checks
  double step_tolerance = 2e-7;          // converged when no tet vertex moves more than this x diagonal over a batch
  bool update_rotations = true;          // false: linear Laplacian editing (R = I), for comparison
  double volume_weight = 0.0;            // DeformerOptions::volume_weight: the volume term's share, [0, 1)
};

struct PoseResult {
  std::vector<double> tet_positions;   // #tet V * 3, tet-mesh order (markers included)
  std::vector<double> fine_positions;  // #fine V * 3, fine (rendered) vertex order
  int iterations = 0;
  double energy = 0.0;                 // after the last iteration
  double relative_energy_change = 0.0; // over the last batch (0 when the energy is 0)
  double last_batch_step = 0.0;        // largest tet-vertex move over the last batch, / fine diagonal
  bool converged = false;              // stopped by the step criterion (or a fixed count ran)
  std::int32_t inverted_tets = 0;      // body tets with non-positive volume after the pose
  std::uint32_t step_flags = 0;        // StepFlags seen in any step (targets rejected, exact rotations)
};

// Poses `rig`: every region handle named in `regions` takes its transform (x = R p_rest + t);
// regions not named, vertex handles (markers) and point handles stay at rest. Unknown or repeated
// region names are refused (naming the rig's regions).
PoseResult poseRig(const Rig& rig, const std::vector<std::pair<std::string, RigidTransform>>& regions,
                   const PoseOptions& options = {});

// The fine mesh at `fine_positions` (#fine V * 3) as Wavefront OBJ text (v lines in the rig's
// fine-vertex order, 1-based f lines), and written atomically (writeFileAtomically).
std::string fineMeshObjText(const Rig& rig, const std::vector<double>& fine_positions, const std::string& comment);
void writeObjAtomically(const std::filesystem::path& path, const Rig& rig, const std::vector<double>& fine_positions,
                        const std::string& comment);

}  // namespace tetrig::rigbuild
