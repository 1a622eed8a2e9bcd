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
// (docs/deformation.md, "Rotation extraction").
// Rotation interpolation runs once per change of an oriented handle's rotation, before that
// frame's first solve: the handle's rotation increment since the last interpolation is spread
// over the mesh with precomputed harmonic weights and composed onto every tet's rotation (the
// increments are small even when the total twist exceeds 180 degrees).
//
// Threads: a Deformer is used by one thread at a time (the solver thread). Construction throws
// std::invalid_argument / std::runtime_error with a message naming what was wrong.
#pragma once

#include "tetrig/tet_mesh.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace tetrig {

// Deformer::setLinearConstraint: solve z = L_ff^-1 g_f for the new g, or keep the last one's.
enum class ConstraintDirection { kSolve, kKeep };

class DeformerImpl;

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
                                        // on by alpha times its last frame's rotation (docs/fidelity.md, "Temporal prediction");
                                        // 0: the plain warm start
  double rotation_relaxation = 1.0;  // omega in [1, 2): each iteration's rotation update is carried on by
                                     // omega times itself (docs/fidelity.md, "Over-relaxation"); 1: plain
  double rotation_extrapolation_max_deg = 5.0;  // a tet's predicted rotation per frame is capped at this angle
  bool frame_guide = false;  // accept a per-frame rotation increment per tet from outside (setFrameGuide;
                             // the coarse level, docs/fidelity.md "Coarse level"); 16 bytes per tet more state
  double volume_weight = 0.0;  // w in [0, 1): each tet's energy a [(1 - w) ||F - R||^2 + w ||F - T||^2] with T
                               // its nearest unit-volume shape (docs/deformation.md, "Volume term"); the factor
                               // is the same. Rigid-group tets take none. 0: as rigid as possible, no volume term
  double inversion_guard = 0.0;  // k in [0, 1]: a guarded tet squashed below inversion_guard_threshold of its rest
                                 // volume takes up to k times more stiffness (docs/deformation.md, "Inversion
                                 // guard); the factor is the same. 0: none
  double inversion_guard_threshold = 0.5;  // tau in (0, 1]: the volume ratio det F where the guard starts
  int inversion_guard_solves = 0;  // > 0: the guard is implicit (inversion_guard.cpp): its stiffness enters each
                                   // global step, solved by this many preconditioned conjugate-gradient steps
                                   // (one more solve each) with the factor as preconditioner; k may then be up to
                                   // kImplicitGuardMaxK, and no push cap. 0: the explicit guard (k <= 1)
  bool linear_constraint = false;  // accept one linear equality constraint on the positions
                                   // (setLinearConstraint); 64 bytes per vertex more state
  bool untangle = false;  // with the implicit guard: after each step's last iteration, relax the free corners of
                          // the guarded tets whose volume ratio is below 0.1 on the same guarded energy, the
                          // rotations held (untangle.cpp; docs/deformation.md, "Untangling the published
                          // pose"). Only the positions the step writes change
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
  // true: another call continues this frame right after this one (continues_frame there). The
  // frame's last rotation pass otherwise leaves the right-hand side for the next frame to build
  // (with the temporal prediction or oriented regions it turns the rotations first); a call that
  // continues builds it then (a whole pass) unless this call kept it.
  bool continued_after = false;
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
  // Load time: validates the mesh and setup, builds the Laplacian and factors it, allocates every
  // per-frame buffer. Throws std::invalid_argument / std::runtime_error naming what was wrong.
  Deformer(const TetMesh& mesh, const DeformerSetup& setup);
  ~Deformer();
  Deformer(Deformer&&) noexcept;
  Deformer& operator=(Deformer&&) noexcept;

  // One frame: new targets, up to budget.max_iterations iterations (at least one when
  // max_iterations >= 1; the deadline is checked after each). Never allocates, locks or throws.
  StepStats step(const HandleTargets& targets, const StepBudget& budget);

  // Deformed positions, #V*3 doubles in mesh vertex order (x0 y0 z0 x1 ...).
  std::span<const double> positions() const noexcept;
  // The same, #V*4 doubles (x0 y0 z0 0 x1 ...), 64-byte aligned: the input of
  // applyPoseTransferPadded (one vector load per entry of B). Empty unless
  // DeformerOptions::padded_positions.
  std::span<const double> paddedPositions() const noexcept;
  // The same in float (x0 y0 z0 0 x1 ..., each rounded to nearest), for the compact pose transfer's
  // float kernel. Empty unless DeformerOptions::padded_float_positions.
  std::span<const float> paddedFloatPositions() const noexcept;
  Eigen::Vector3d position(std::int32_t v) const;

  // Current rotation of tet t.
  Eigen::Quaterniond rotation(std::int32_t t) const;
  // Every tet's rotation as stored (4 floats w x y z per tet, mesh tet order) into `wxyz`; false
  // (nothing written) unless it holds 4 x tetCount() floats. No allocation, lock or exception.
  bool rotations(std::span<float> wxyz) const noexcept;

  // Replaces every tet rotation (e.g. randomised differential coordinates) and rebuilds delta.
  // Not for the frame path: allocation-free but O(#T).
  void setRotations(std::span<const Eigen::Quaterniond> rotations);

  // Frame guide (DeformerOptions::frame_guide): a rotation increment G per tet composed onto every
  // tet's rotation at the start of the next step() that begins a frame, before its first solve:
  // R' = G R, with the temporal prediction taken beyond the guide (docs/fidelity.md, "Temporal
  // prediction"). Given as a table of unit quaternions (4 floats w x y z per row); tet t takes row
  // source(t): by default its own (one row per tet, mesh tet order), else as setFrameGuideSources
  // says. Used once, then cleared. Returns false (and keeps nothing) without the option or with the
  // wrong size. No allocation, lock or exception.
  bool setFrameGuide(std::span<const float> wxyz_per_source) noexcept;
  // Load time (allocates): tet t takes row source_of_tet[t] of setFrameGuide's table of `sources`
  // rows, for a guide shared by groups of tets (the coarse level: one per coarse tet). Returns false
  // (and keeps the sources it had) without DeformerOptions::frame_guide, with the wrong size or a row
  // outside [0, sources).
  bool setFrameGuideSources(std::span<const std::int32_t> source_of_tet, std::int32_t sources);

  // A linear equality constraint on the positions, g . x = c (DeformerOptions::linear_constraint;
  // g: #V*3 doubles in mesh vertex order, e.g. a volume's gradient, docs/deformation.md "Volume constraint"),
  // enforced by a Lagrange multiplier mu with the same factor. Each solve carries the multiplier so
  // far in its right-hand side and moves what is left along z:
  //   L_ff u_f = b_f + mu g_f,   u_f += m z,   m = (c - g . x) / (g_f . z),   mu += m,
  // z = L_ff^-1 g_f. With z of this g, each global step is the minimum of its quadratic on the plane
  // g . x = c; with the z of an earlier g kept (ConstraintDirection::kKeep: no solve), each step
  // still lands on the plane, and a converged pose (m -> 0) is still the constrained minimum,
  // L u = b + mu g. kSolve solves z here (one solve); the constraint holds for every step until
  // replaced or cleared. Handle components of g count in g . x but cannot move. Returns false (and
  // clears the constraint) without the option, with the wrong size, with a non-finite g or c, when
  // g has no component on a free vertex, and with kKeep when there is no z to keep or g_f . z <= 0
  // (then set it again with kSolve). No allocation, lock or exception.
  bool setLinearConstraint(std::span<const double> g, double c, ConstraintDirection direction = ConstraintDirection::kSolve) noexcept;
  // A new value c for the constraint's g (no solve): false, and no change, without one.
  bool setLinearConstraintValue(double c) noexcept;
  void clearLinearConstraint() noexcept;
  bool hasLinearConstraint() const noexcept;

  // Back to the rest state: rotations I, positions at rest, handle targets at rest, no constraint.
  void reset();

  // The memory a step reads (the tet blocks, the factor, the per-vertex vectors), as byte ranges
  // written to `out` (at most out.size() of them); returns how many there are (more than out.size()
  // when it did not fit). For warming the caches before a frame (tetrig/frame_loop.hpp). Any thread
  // that may read the deformer; no allocation.
  std::size_t frameWorkingSet(std::span<std::span<const std::byte>> out) const noexcept;

  std::int32_t vertexCount() const noexcept;
  std::int32_t tetCount() const noexcept;
  std::int32_t freeVertexCount() const noexcept;     // vertices that are not handles
  std::int64_t factorNonZeros() const noexcept;      // entries of the LDL^T factor
  double factorizeSeconds() const noexcept;          // the load-time factorization's wall time

 private:
  std::unique_ptr<DeformerImpl> impl_;  // the solver's state (tetrig/deformer_impl.hpp, internal)
};

}  // namespace tetrig
