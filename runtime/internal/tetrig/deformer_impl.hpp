// The deformer's state and solver (internal): what tetrig::Deformer (tetrig/deformer.hpp) holds behind
// its pointer. The equations, the iteration and the threading rules are those of deformer.hpp; the
// storage is the solver's own: the split LDL^T factor (ldlt_factor.hpp), tets in blocks of vector
// lanes (rotation_kernel.hpp), every array in solver order. deformer.cpp and inversion_guard.cpp
// implement it; only the runtime and its tests include this header.
#pragma once

#include "tetrig/aligned_vector.hpp"
#include "tetrig/deformer.hpp"
#include "tetrig/laplacian.hpp"
#include "tetrig/ldlt_factor.hpp"
#include "tetrig/rotation_kernel.hpp"
#include "tetrig/tet_mesh.hpp"
#include "tetrig/working_set.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/SparseCore>

#include <array>
#include <cstdint>
#include <span>
#include <vector>

namespace tetrig {

// The indices of the blocks of kTetBlockWidth slots (det: block_count * kTetBlockWidth values) with
// some det <= bound, ascending, into out (block_count values at most); returns how many. One vector
// compare per block (inversion_guard.cpp).
std::size_t blocksWithDetAtMost(const float* det, std::size_t block_count, float bound, std::int32_t* out) noexcept;

// A tet the implicit inversion guard holds, gathered once from its block (inversion_guard.cpp): its
// slot, corner offsets (solver order, stride 4), rest edge inverse E^-1 and alpha_j a_j.
struct GuardedTet {
  std::int32_t slot = 0;
  std::array<std::int32_t, 4> corner{};
  Eigen::Matrix3d einv;
  double coef = 0.0;
};

// Slot s's corners and E^-1 from its block (coef left 0). Forced inline, as the kernels' helpers
// are: a call would leave a multiversioned loop's instruction set. Its matrices in the passes over
// it: runtime/src/guard_columns.hpp.
__attribute__((always_inline)) inline GuardedTet gatherTet(const TetBlock* blocks, std::int32_t s) {
  const TetBlock& block = blocks[s / kTetBlockWidth];
  const int l = s % kTetBlockWidth;
  GuardedTet t;
  t.slot = s;
  for (size_t c = 0; c < 4; ++c) t.corner[c] = block.corner_offset[c][l];
  for (int i = 0; i < 9; ++i) t.einv(i / 3, i % 3) = block.edge_inverse[i][l];
  return t;
}

class DeformerImpl {
 public:
  // The members of tetrig::Deformer of the same names, which forward here (deformer.hpp documents them).
  DeformerImpl(const TetMesh& mesh, const DeformerSetup& setup);
  StepStats step(const HandleTargets& targets, const StepBudget& budget);
  std::span<const double> positions() const { return positions_; }
  std::span<const double> paddedPositions() const { return padded_positions_; }
  std::span<const float> paddedFloatPositions() const { return padded_float_positions_; }
  Eigen::Vector3d position(std::int32_t v) const;
  Eigen::Quaterniond rotation(std::int32_t t) const;
  bool rotations(std::span<float> wxyz) const noexcept;
  void setRotations(std::span<const Eigen::Quaterniond> rotations);
  bool setFrameGuide(std::span<const float> wxyz_per_source) noexcept;
  bool setFrameGuideSources(std::span<const std::int32_t> source_of_tet, std::int32_t sources);
  bool setLinearConstraint(std::span<const double> g, double c, ConstraintDirection direction) noexcept;
  bool setLinearConstraintValue(double c) noexcept;
  void clearLinearConstraint() noexcept { constraint_active_ = false; }
  std::size_t frameWorkingSet(std::span<std::span<const std::byte>> out) const noexcept {
    std::size_t n = appendWorkingSet(out, 0, blocks_);
    n = factor_.workingSet(out, n);
    n = appendWorkingSet(out, n, u_);
    n = appendWorkingSet(out, n, delta_);
    n = appendWorkingSet(out, n, rest_solver_);
    n = appendWorkingSet(out, n, rhs_constant_);
    n = appendWorkingSet(out, n, padded_positions_);
    n = appendWorkingSet(out, n, padded_float_positions_);
    return appendWorkingSet(out, n, guard_det_);
  }
  bool hasLinearConstraint() const noexcept { return constraint_active_; }
  void reset();
  std::int32_t vertexCount() const { return vertex_count_; }
  std::int32_t tetCount() const { return tet_count_; }
  std::int32_t freeVertexCount() const { return free_count_; }
  std::int64_t factorNonZeros() const { return factor_.factorNonZeros(); }
  double factorizeSeconds() const { return factorize_seconds_; }

 private:
  // Load-time steps of the constructor, in order (deformer.cpp).
  void checkOptions();
  void checkMeshUsable(const TetMesh& mesh);
  std::vector<std::int32_t> assignHandleSlots(const TetMesh& mesh, const DeformerSetup& setup);
  void factorReducedSystem(const TetMesh& mesh, const DeformerSetup& setup, const Eigen::SparseMatrix<double>& laplacian,
                           const std::vector<std::int32_t>& free_index);
  void buildSolverOrder(const TetMesh& mesh, const std::vector<std::int32_t>& handle_of_vertex,
                        const std::vector<std::int32_t>& free_index);
  void buildHandleCoupling(const Eigen::SparseMatrix<double>& laplacian, const std::vector<std::int32_t>& handle_of_vertex,
                           const std::vector<std::int32_t>& free_index);
  void buildPointHandles(const TetMesh& mesh, const DeformerSetup& setup);
  void buildTetBlocks(const TetMesh& mesh, const TetRestFrames& frames, const std::vector<double>& weights);
  void buildHarmonicWeights(const TetMesh& mesh, const DeformerSetup& setup, const std::vector<std::int32_t>& handle_of_vertex);
  void buildRigidGroupsAndCoefficients(const DeformerSetup& setup);

  bool acceptTargets(const HandleTargets& targets, std::uint32_t& flags);
  void updateConstantRhs();
  bool interpolateRotations();  // true when it turned any tet (delta_ then needs rebuildDelta)
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
  bool delta_stale_ = false;                    // the last rotation pass left delta_ out (step(): the next step builds it)
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
  // The row of setFrameGuide's table each slot takes (-1 in padding lanes), and the table's rows.
  std::vector<std::int32_t> guide_source_of_slot_;
  std::int32_t guide_sources_ = 0;

  // Volume term (options_.volume_weight > 0): w per slot, the blocks' lane layout; 0 in padding
  // lanes and rigid groups. Empty otherwise.
  AlignedVector<float> volume_weight_;
  const float* volumeWeights() const { return volume_weight_.empty() ? nullptr : volume_weight_.data(); }
  // Inversion guard (options_.inversion_guard > 0): k per slot, 0 for unguarded tets and padding
  AlignedVector<float> guard_;
  // The kernels' (explicit) guard; nullptr when the guard is implicit.
  const float* guard() const { return guard_.empty() || options_.inversion_guard_solves > 0 ? nullptr : guard_.data(); }
  // Implicit guard (options_.inversion_guard_solves > 0; inversion_guard.cpp): the tets squashed
  // below tau at the last rotation pass, and the conjugate-gradient vectors.
  std::vector<GuardedTet> guarded_;
  AlignedVector<float> guard_det_;  // det F per slot at the last rotation pass (written by it)
  mutable std::vector<std::int32_t> guard_blocks_;  // forEachGuardedTetBelow's scratch: a block index each
  std::size_t guarded_count_ = 0;
  AlignedVector<double> cg_r_, cg_z_, cg_p_, cg_lp_;  // cg_r_ is 0 between solves
  AlignedVector<float> cg_float_;  // z = L^-1 r solved in float (the factor's float copy)
  // The held tets' corners (offsets into the per-vertex vectors, each once; handles too): r_0 lives
  // there. guard_corner_mark_ is all 0 between collectGuardedTets calls.
  std::vector<std::int32_t> guard_corners_;
  std::size_t guard_corner_count_ = 0;
  std::vector<std::uint8_t> guard_corner_mark_;
  // f(slot) for every guarded tet (guard_ > 0) whose det F at the last rotation pass is below
  // `bound`, in slot order; a block of 16 is skipped by one vector compare when none is.
  template <class F>
  void forEachGuardedTetBelow(double bound, F&& f) const {
    // <=: every float below bound.
    const std::size_t candidates = blocksWithDetAtMost(guard_det_.data(), blocks_.size(), static_cast<float>(bound), guard_blocks_.data());
    for (std::size_t i = 0; i < candidates; ++i) {
      const auto b = static_cast<size_t>(guard_blocks_[i]);
      for (size_t l = 0; l < kTetBlockWidth; ++l) {
        const size_t s = b * kTetBlockWidth + l;
        if (!(guard_det_[s] < bound) || guard_[s] <= 0.0f) continue;  // not below, unguarded, padding; NaN too
        f(static_cast<std::int32_t>(s));
      }
    }
  }
  void collectGuardedTets();
  void precondition();  // cg_z_ = M^-1 cg_r_ over every free vertex (inversion_guard.cpp)
  void implicitGuardSolve();
  // Untangling the published pose (untangle.cpp; with the implicit guard): the free vertex -> tet
  // slot adjacency (CSR), the tets found below the threshold, the vertices being relaxed and their marks.
  std::vector<std::int32_t> untangle_start_, untangle_tet_, untangle_tangled_, untangle_vertex_;
  std::vector<std::uint8_t> untangle_mark_;
  void buildUntangleAdjacency();
  void untangle();

  // Rigid groups: CSR over tet slots.
  std::vector<std::int32_t> group_start_, group_slot_;

  // Linear constraint (options_.linear_constraint): g and z = L_ff^-1 g_f (of this g, or of an
  // earlier one when kept) in solver order (kVectorStride per vertex), c - g . x_rest, g_f . z.
  AlignedVector<double> constraint_g_, constraint_z_;
  double constraint_rhs_ = 0.0, constraint_gz_ = 0.0, constraint_rest_dot_ = 0.0;
  double constraint_mu_ = 0.0;  // the multiplier so far: the solves carry mu g_f in their right-hand side
  bool constraint_active_ = false;
  void applyLinearConstraint();
};

}  // namespace tetrig
