// The deformation core: a precompute/solve pair (Stoll et al. 2007, section 2.3).
//
//   Deformer deformer(mesh, setup);            // load: all allocation and the factorization
//   StepStats s = deformer.step(targets, budget);  // per frame: no allocation, lock, throw or I/O
//   deformer.positions();                      // #V*3 doubles, mesh order, valid after step()
//   deformer.paddedPositions();                // the same as #V*4 (x, y, z, 0), for applyPoseTransferPadded,
//                                              // when DeformerOptions::padded_positions is set
//
// Handles (section 2.3.1):
// - vertex handles: a vertex whose position is prescribed; eliminated from L.
// - region handles: a set of tets whose corners are all prescribed by a rigid transform of their
//   rest positions, x = R p_rest + t. An oriented region's rotation R also drives the harmonic
//   interpolation of rotations (section 2.3.2) so twists propagate at once, beyond 180 degrees.
// - point handles: a point inside (or near) tet j, p = sum_k b_k x_ck with fixed barycentric
//   weights b. They enter as a soft constraint lambda ||sum_k b_k x_ck - p||^2 added to the
//   energy, so the matrix L + lambda B^T B is factored once and a frame only changes the
//   right-hand side (lambda = point_handle_weight * mean diagonal of L). Markers bound by
//   invisible tets (paper 3.2) are vertex handles instead, made by the rig builder.
// Per frame only the right-hand side changes; the factor is computed once at load.
//
// Iteration, repeated k times per step() (k bounded by count and deadline, warm-started), in
// displacements u = x - x_rest (exact: G^T D g(I) = L x_rest, so L x = G^T D g(R) is
// L u = G^T D g(R - I); the rest state is exactly u = 0, R = I, delta = 0):
//   1. linear solve L_ff u_f = delta_f - L_fh u_h (+ point-handle terms), split LDL^T, no alloc;
//   2. rotation extraction per tet (warm-started, exact fallback for inverted tets);
//   3. rigid groups: every tet of a group takes the group's average rotation;
//   4. differential coordinates delta = G^T D g(R - I).
// Precision: positions, displacements and the factor are double; the per-tet pass (2, 4) stores
// each tet's frame and rotation in float, computes in float and accumulates delta in float
// (rotation_kernel.hpp).
// Rotation interpolation runs once per change of an oriented handle's rotation, before that
// frame's first solve: the handle's rotation increment since the last interpolation is spread
// over the mesh with precomputed harmonic weights and composed onto every tet's rotation (the
// increments are small even when the total twist exceeds 180 degrees).
//
// Threads: a Deformer is used by one thread at a time (the solver thread). Construction throws
// std::invalid_argument / std::runtime_error with a message naming what was wrong.
#pragma once

#include "tetrig/ldlt_factor.hpp"
#include "tetrig/aligned_vector.hpp"
#include "tetrig/rotation_kernel.hpp"
#include "tetrig/tet_mesh.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/SparseCore>

#include <chrono>
#include <cstdint>
#include <span>
#include <vector>

namespace tetrig {

struct RegionHandle {
  std::vector<std::int32_t> tets;  // every corner of these tets is prescribed
  bool oriented = true;            // its rotation drives rotation interpolation
};

struct PointHandle {
  std::int32_t tet = -1;                                   // tet whose corners carry the point
  Eigen::Vector4d barycentric = Eigen::Vector4d::Zero();   // weights of corners 0..3, sum 1
};

struct RigidGroup {
  std::vector<std::int32_t> tets;  // may be disconnected ("pseudo-skeleton"); groups are disjoint
};

struct DeformerOptions {
  bool update_rotations = true;       // false: linear Laplacian editing (R_j = I), for comparison
  bool interpolate_rotations = true;  // needs oriented region handles; ignored otherwise
  int rotation_steps = 2;             // warm-started refinement steps per tet per iteration
  double point_handle_weight = 1e3;   // lambda / mean diagonal of L for point handles
  double max_abs_coordinate = 1e6;    // a target coordinate beyond this is rejected as absurd
  bool padded_positions = false;      // also write paddedPositions() every step (~30 % more output
                                      // traffic; for applyPoseTransferPadded)
  bool padded_float_positions = false;  // also write paddedFloatPositions() every step (the input of the
                                        // compact pose transfer's float kernel)
  double rotation_extrapolation = 0.0;  // alpha in [0, 1]: a frame starts from every tet's rotation carried
                                        // on by alpha times its last frame's rotation (rotation_prediction.hpp);
                                        // 0: the plain warm start
  double rotation_relaxation = 1.0;  // omega in [1, 2): each iteration's rotation update is carried on by
                                     // omega times itself (rotation_kernel.hpp, over-relaxation); 1: plain
  double rotation_extrapolation_max_deg = 5.0;  // a tet's predicted rotation per frame is capped at this angle
  bool frame_guide = false;  // accept a per-frame rotation increment per tet from outside (setFrameGuide;
                             // the coarse level, tetrig/coarse_level.hpp); 16 bytes per tet more state
  double volume_weight = 0.0;  // w in [0, 1): each tet's energy a [(1 - w) ||F - R||^2 + w ||F - T||^2] with T
                               // its nearest unit-volume shape (rotation_kernel.hpp, volume term); the factor
                               // is the same. Rigid-group tets take none. 0: as rigid as possible, no volume term
  double inversion_guard = 0.0;  // k in [0, 1]: a guarded tet squashed below inversion_guard_threshold of its rest
                                 // volume takes up to k times more stiffness (rotation_kernel.hpp, inversion
                                 // guard); the factor is the same. 0: none
  double inversion_guard_threshold = 0.5;  // tau in (0, 1]: the volume ratio det F where the guard starts
  int inversion_guard_solves = 0;  // > 0: the guard is implicit (inversion_guard.cpp): its stiffness enters each
                                   // global step, solved by this many preconditioned conjugate-gradient steps
                                   // (one more solve each) with the factor as preconditioner; k may then be up to
                                   // kImplicitGuardMaxK, and no push cap. 0: the explicit guard (k <= 1)
  bool linear_constraint = false;  // accept one linear equality constraint on the positions
                                   // (setLinearConstraint); 64 bytes per vertex more state
};

// The largest k of the implicit inversion guard (DeformerOptions::inversion_guard_solves > 0).
inline constexpr double kImplicitGuardMaxK = 1000.0;

struct DeformerSetup {
  std::vector<std::int32_t> vertex_handles;
  std::vector<RegionHandle> region_handles;
  std::vector<PointHandle> point_handles;
  std::vector<RigidGroup> rigid_groups;
  std::vector<double> stiffness;  // empty, or one positive weight per tet (1 = default)
  std::vector<double> volume_weights;  // empty, or one volume-term weight w_j in [0, 1) per tet (a rig's
                                       // per-region volume, docs/deformation.md); options.volume_weight is a floor
  std::int32_t guarded_tet_count = -1;  // the inversion guard covers tets [0, n) (a rig's body tets); -1: all
  DeformerOptions options;
};

struct RigidTransform {
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
};

// Targets for one frame. Sizes must match the setup; spans are read during step() only.
struct HandleTargets {
  std::span<const Eigen::Vector3d> vertex_positions;  // one per vertex handle
  std::span<const RigidTransform> region_transforms;  // one per region handle
  std::span<const Eigen::Vector3d> point_positions;   // one per point handle
};

struct StepBudget {
  int max_iterations = 3;
  std::chrono::steady_clock::time_point deadline = std::chrono::steady_clock::time_point::max();
  // true: this call continues the previous call's frame (the live rig's re-prediction splits a
  // frame's iterations over two calls): the per-frame start (temporal extrapolation) is skipped.
  bool continues_frame = false;
};

enum StepFlags : std::uint32_t {
  kStepDeadlineHit = 1u << 0,         // stopped before max_iterations: the deadline passed
  kStepTargetsRejected = 1u << 1,     // a target was non-finite or absurd: the previous targets were kept
  kStepTargetsWrongSize = 1u << 2,    // a target span had the wrong size: the previous targets were kept
  kStepExactRotations = 1u << 3,      // some tets were inverted/degenerate and took the exact rotation
};

struct StepStats {
  std::int32_t iterations = 0;
  std::uint32_t flags = 0;                // StepFlags
  double energy = 0.0;                    // sum_j a_j ||F_j - R_j||^2 after the last rotation update
                                          // (with the volume term, the combined energy of rotationPass)
  std::int32_t exact_rotations = 0;       // tets that took the exact rotation, summed over iterations
  std::int32_t guarded_solves = 0;        // implicit inversion guard: global steps that held squashed tets
  std::int32_t guarded_tets = 0;          // implicit inversion guard: the tets it holds after the last iteration
  std::int64_t solve_ns = 0;              // linear solves
  std::int64_t rotation_ns = 0;           // rotation extraction + differential update
  std::int64_t interpolation_ns = 0;      // rotation interpolation
  std::int64_t rigid_ns = 0;              // rigid groups
  std::int64_t total_ns = 0;              // the whole step
};

// Each tet's volume-term weight w_j: max(options.volume_weight, volume_weights[j]) (volume_weights
// may be empty), 0 in rigid groups and everywhere when options.update_rotations is false.
// Throws std::invalid_argument when volume_weights has the wrong size or a weight outside [0, 1).
std::vector<double> tetVolumeWeights(const DeformerSetup& setup, std::int32_t tet_count);

class Deformer {
 public:
  Deformer(const TetMesh& mesh, const DeformerSetup& setup);

  // One frame: new targets, up to budget.max_iterations iterations (at least one when
  // max_iterations >= 1; the deadline is checked after each). Never allocates, locks or throws.
  StepStats step(const HandleTargets& targets, const StepBudget& budget);

  // Deformed positions, #V*3 doubles in mesh vertex order (x0 y0 z0 x1 ...).
  std::span<const double> positions() const { return positions_; }
  // The same, #V*4 doubles (x0 y0 z0 0 x1 ...), 64-byte aligned: the input of
  // applyPoseTransferPadded (one vector load per entry of B). Empty unless
  // DeformerOptions::padded_positions.
  std::span<const double> paddedPositions() const { return padded_positions_; }
  // The same in float (x0 y0 z0 0 x1 ..., each rounded to nearest), for the compact pose transfer's
  // float kernel. Empty unless DeformerOptions::padded_float_positions.
  std::span<const float> paddedFloatPositions() const { return padded_float_positions_; }
  Eigen::Vector3d position(std::int32_t v) const;

  // Current rotation of tet t.
  Eigen::Quaterniond rotation(std::int32_t t) const;

  // Replaces every tet rotation (e.g. randomised differential coordinates) and rebuilds delta.
  // Not for the frame path: allocation-free but O(#T).
  void setRotations(std::span<const Eigen::Quaterniond> rotations);

  // Frame guide (DeformerOptions::frame_guide): a rotation increment G per tet (4 floats w x y z per
  // tet, mesh tet order, unit quaternions) composed onto every tet's rotation at the start of the
  // next step() that begins a frame, before its first solve: R' = G R, with the temporal prediction
  // taken beyond the guide (tetrig/rotation_prediction.hpp). Used once, then cleared. Returns false
  // (and keeps nothing) without the option or with the wrong size. No allocation, lock or exception.
  bool setFrameGuide(std::span<const float> wxyz_per_tet) noexcept;

  // A linear equality constraint on the positions, g . x = c (DeformerOptions::linear_constraint;
  // g: #V*3 doubles in mesh vertex order, e.g. a volume's gradient, tetrig/volume_constraint.hpp),
  // enforced by a Lagrange multiplier with the same factor: every solve is followed by
  //   u_f += mu z,   z = L_ff^-1 g_f,   mu = (c - g . x) / (g_f . z),
  // which makes each global step the minimum of its quadratic on the plane g . x = c, and a converged
  // pose the constrained minimum. z is solved here, once (one solve); the constraint holds for every
  // step until replaced or cleared. Handle components of g count in g . x but cannot move. Returns
  // false (and clears the constraint) without the option, with the wrong size, with a non-finite g
  // or c, or when g has no component on a free vertex. No allocation, lock or exception.
  bool setLinearConstraint(std::span<const double> g, double c) noexcept;
  // A new value c for the constraint's g (no solve): false, and no change, without one.
  bool setLinearConstraintValue(double c) noexcept;
  void clearLinearConstraint() noexcept { constraint_active_ = false; }
  bool hasLinearConstraint() const noexcept { return constraint_active_; }

  // Back to the rest state: rotations I, positions at rest, handle targets at rest, no constraint.
  void reset();

  std::int32_t vertexCount() const { return vertex_count_; }
  std::int32_t tetCount() const { return tet_count_; }
  std::int32_t freeVertexCount() const { return free_count_; }
  std::int64_t factorNonZeros() const { return factor_.factorNonZeros(); }
  double factorizeSeconds() const { return factorize_seconds_; }

 private:
  bool acceptTargets(const HandleTargets& targets, std::uint32_t& flags);
  void updateConstantRhs();
  void interpolateRotations();
  void rebuildDelta();
  void rememberRotations();  // previous_rotation_ <- the current rotations (no velocity)
  void writePositions();
  std::int32_t slotOfTet(std::int32_t t) const { return tet_slot_[static_cast<size_t>(t)]; }

  std::int32_t vertex_count_ = 0, tet_count_ = 0, free_count_ = 0, handle_count_ = 0;
  DeformerOptions options_;
  SplitLdlt factor_;
  double factorize_seconds_ = 0.0;

  // Vertex ordering: free vertex v lives at solver index factor position; handle slot h at free_count_ + h.
  std::vector<std::int32_t> solver_index_;    // mesh vertex -> solver index
  std::vector<std::int32_t> mesh_vertex_;     // solver index -> mesh vertex
  AlignedVector<double> rest_solver_;           // rest positions, solver order, kVectorStride per vertex
  AlignedVector<double> u_;                     // displacements x - x_rest, solver order (free then handles)
  AlignedVector<float> delta_;                  // sum_j a_j (R_j - I) G_j, solver order (float: rotation_kernel.hpp)
  AlignedVector<double> rhs_constant_;          // -L_fh u_h + point terms, free part
  std::vector<double> positions_;             // mesh order output
  AlignedVector<double> padded_positions_;      // mesh order output, kVectorStride per vertex
  AlignedVector<float> padded_float_positions_;  // the same in float

  // -L_fh as CSR over the free rows next to a handle (coupling_row_: their solver index),
  // columns = handle slots.
  std::vector<std::int32_t> coupling_row_, coupling_start_, coupling_handle_;
  std::vector<double> coupling_value_;

  // Handles. Handle slot h: mesh vertex handle_vertex_[h], driven by vertex target or region.
  std::int32_t vertex_handle_count_ = 0;
  std::vector<std::int32_t> handle_vertex_;
  std::vector<std::int32_t> handle_region_;       // region index, or -1 for a vertex handle
  std::vector<Eigen::Vector3d> vertex_targets_;   // accepted targets
  std::vector<RigidTransform> region_targets_;
  std::vector<Eigen::Vector3d> point_targets_;

  // Point handles (soft): corners in solver order, barycentric weights, lambda.
  std::vector<std::int32_t> point_corner_;  // 4 per point handle
  std::vector<double> point_weight_;        // 4 per point handle
  std::vector<Eigen::Vector3d> point_rest_; // rest position of each point handle
  double point_lambda_ = 0.0;

  // Tets in blocks.
  std::vector<TetBlock> blocks_;
  std::vector<std::uint16_t> exact_lanes_;  // rotationPass scratch: one lane mask per block
  std::vector<std::int32_t> tet_slot_;  // mesh tet -> block * kTetBlockWidth + lane

  // Rotation interpolation: per oriented region, harmonic weights over tets and the rotation the
  // mesh was last interpolated for.
  std::vector<std::int32_t> oriented_regions_;          // region index of each oriented handle
  std::vector<double> harmonic_weights_;                // oriented-handle-major, #T each, slot order
  std::vector<Eigen::Quaterniond> interpolated_rotation_;
  std::vector<Eigen::Quaterniond> rotation_increment_;  // scratch

  // Temporal extrapolation (options_.rotation_extrapolation): each slot's rotation at the end of
  // the previous frame, laid out like the blocks' rotations ([block][component][lane]).
  AlignedVector<float> previous_rotation_;
  float extrapolation_max_sin_half_ = 1.0f;  // sin(cap / 2)
  // Frame guide (options_.frame_guide): this frame's increment per slot, same layout; identity in
  // padding lanes.
  AlignedVector<float> guide_;
  bool guide_pending_ = false;

  // Volume term (options_.volume_weight > 0): w per slot, the blocks' lane layout; 0 in padding
  // lanes and rigid groups. Empty otherwise.
  AlignedVector<float> volume_weight_;
  const float* volumeWeights() const { return volume_weight_.empty() ? nullptr : volume_weight_.data(); }
  // Inversion guard (options_.inversion_guard > 0): k per slot, 0 for unguarded tets and padding
  AlignedVector<float> guard_;
  // The kernels' (explicit) guard; nullptr when the guard is implicit.
  const float* guard() const { return guard_.empty() || options_.inversion_guard_solves > 0 ? nullptr : guard_.data(); }
  // Implicit guard (options_.inversion_guard_solves > 0; inversion_guard.cpp): the tets squashed
  // below tau at the last rotation pass, with alpha_j a_j, and the conjugate-gradient vectors.
  std::vector<std::int32_t> guarded_slot_;
  std::vector<double> guarded_coef_;
  AlignedVector<float> guard_det_;  // det F per slot at the last rotation pass (written by it)
  std::size_t guarded_count_ = 0;
  AlignedVector<double> cg_r_, cg_z_, cg_p_, cg_lp_;
  void collectGuardedTets();
  void implicitGuardSolve();

  // Rigid groups: CSR over tet slots.
  std::vector<std::int32_t> group_start_, group_slot_;

  // Linear constraint (options_.linear_constraint): g and z = L_ff^-1 g_f in solver order
  // (kVectorStride per vertex), c - g . x_rest, g_f . z.
  AlignedVector<double> constraint_g_, constraint_z_;
  double constraint_rhs_ = 0.0, constraint_gz_ = 0.0, constraint_rest_dot_ = 0.0;
  bool constraint_active_ = false;
  void applyLinearConstraint();
};

}  // namespace tetrig
