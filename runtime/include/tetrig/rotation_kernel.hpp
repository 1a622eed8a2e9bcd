// The per-tet pass of the iteration (Stoll et al. 2007, section 2.3.2): rotation extraction
// and the differential-coordinate update, fused over blocks of kTetBlockWidth tets.
//
// For tet j with corners c0..c3 (solver order) and current positions x:
//   F_j     = [x_c0 - x_c3, x_c1 - x_c3, x_c2 - x_c3] E_j^-1                  (eq. 2.6)
//   R_j     <- warm-started refinement of R_j towards argmax tr(R^T F_j)       (eq. 2.7-2.8)
//   energy  += a_j ||F_j - R_j||^2 = a_j (||F_j||^2 - 2 tr(R_j^T F_j) + 3)
//   delta_ck += a_j R_j grad phi_k  (k = 0..2),  delta_c3 -= sum_k a_j R_j grad phi_k   (eq. 2.5)
// Inverted or degenerate tets (det F_j <= 1e-12) take the exact rotation (closestRotation).
// Structure of arrays per block so the lane loops vectorise (8 doubles = one AVX-512 register).
// No allocation; the caller owns every buffer. Per-vertex buffers should be 64-byte aligned: a
// vertex's (x, y, z, pad) then never straddles a cache line.
#pragma once

#include <cstdint>

namespace tetrig {

inline constexpr int kTetBlockWidth = 8;

struct alignas(64) TetBlock {
  std::int32_t corner_offset[4][kTetBlockWidth];  // kVectorStride * solver-order vertex index of each corner
  double edge_inverse[9][kTetBlockWidth];     // E^-1, row-major (rows: grad phi_1..3)
  double weight[kTetBlockWidth];              // a_j = stiffness * volume; 0 on padding lanes
  double rotation[4][kTetBlockWidth];         // R_j as a unit quaternion (w, x, y, z)
};

struct RotationPassStats {
  double energy = 0.0;             // sum_j a_j ||F_j - R_j||^2 with the updated R_j
  std::int32_t exact_fallbacks = 0;  // tets that took the exact rotation (inverted/degenerate)
};

// Updates every rotation from positions `xyz` (kVectorStride doubles per vertex: x, y, z, pad;
// solver order) with `steps` refinement steps; if `delta` is not null, also adds each tet's a R G
// into it (same layout; the caller zeroes it first). `exact_lanes` is the caller's scratch of
// block_count bytes: the pass writes there which lanes took the exact rotation (bit l = lane l).
RotationPassStats rotationPass(TetBlock* blocks, std::int32_t block_count, const double* xyz, double* delta,
                               int steps, std::uint8_t* exact_lanes);

// The instruction set the kernels run with on this machine ("avx512f", "avx2", "baseline").
const char* rotationKernelInstructionSet();

// Adds a_j R_j G_j of every tet into `delta` from the stored rotations (no extraction).
void differentialPass(const TetBlock* blocks, std::int32_t block_count, double* delta);

}  // namespace tetrig
