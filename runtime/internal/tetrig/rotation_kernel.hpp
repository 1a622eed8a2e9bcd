// The per-tet pass of the iteration (Stoll et al. 2007, section 2.3.2): rotation extraction
// and the differential-coordinate update, fused over blocks of kTetBlockWidth tets.
//
// Displacement form. The solver state is u = x - x_rest, so the rest state is exactly u = 0,
// R = I, delta = 0. For tet j with corners c0..c3 (solver order):
//   H_j     = [u_c0 - u_c3, u_c1 - u_c3, u_c2 - u_c3] E_j^-1,   F_j = I + H_j      (eq. 2.6)
//   R_j     <- warm-started refinement of R_j towards argmax tr(R^T F_j)       (eq. 2.7-2.8)
//   energy  += a_j ||F_j - R_j||^2 = a_j ||H_j - (R_j - I)||^2
//   delta_ck += a_j (R_j - I) grad phi_k  (k = 0..2),  delta_c3 -= their sum       (eq. 2.5)
// Subtracting I from both sides of eq. 2.5 is exact: sum_j a_j G_j^T I = L x_rest, so the system
// L u = delta holds the same solutions as L x = G^T D R (deformer.cpp).
//
// Precision: displacements are double (edges are differences of them, taken in double); a block's
// frame (E^-1, a_j), its rotations, the per-tet arithmetic and delta are float. The rounding
// (~1e-7) is relative to the deformation (H_j, R_j - I), not to the shape: the rest state is
// reproduced exactly, and a converged state is within ~1e-7 of the double-precision one
// (docs/deformation.md).
//
// Inverted or degenerate tets (det F_j <= 1e-12) take the exact rotation (closestRotation, double).
// Structure of arrays per block so the lane loops vectorise (16 floats = one AVX-512 register).
// No allocation; the caller owns every buffer. Per-vertex buffers should be 64-byte aligned: a
// vertex's (x, y, z, pad) then never straddles a cache line.
#pragma once

#include <cstdint>

namespace tetrig {

inline constexpr int kTetBlockWidth = 16;

// 72 bytes per tet (1152 per block, 18 cache lines).
struct alignas(64) TetBlock {
  std::int32_t corner_offset[4][kTetBlockWidth];  // kVectorStride * solver-order vertex index of each corner
  float edge_inverse[9][kTetBlockWidth];          // E^-1, row-major (rows: grad phi_1..3)
  float weight[kTetBlockWidth];                   // a_j = stiffness * volume; 0 on padding lanes
  float rotation[4][kTetBlockWidth];              // R_j as a unit quaternion (w, x, y, z)
};

struct RotationPassStats {
  double energy = 0.0;             // sum_j a_j ||F_j - R_j||^2 with the updated R_j
  std::int32_t exact_fallbacks = 0;  // tets that took the exact rotation (inverted/degenerate)
};

// Updates every rotation from displacements `u` (kVectorStride doubles per vertex: x, y, z, pad;
// solver order) with `steps` refinement steps; if `delta` is not null, also adds each tet's
// a (R - I) G into it (kVectorStride floats per vertex, same order; the caller zeroes it first). `exact_lanes` is the caller's
// scratch of block_count entries: the pass writes there which lanes took the exact rotation
// (bit l = lane l).
// Over-relaxation: with relax = omega - 1 > 0, each tet's rotation is carried past the refined one,
//   D = R_refined R_start^-1 (in the hemisphere of the identity),  R = D^relax R_refined,
// where D^relax scales D's half-angle tangent by relax (its angle by relax, to first order). The
// fixed points are those of the plain iteration (D = I there); the slow, smooth modes of the
// local/global iteration contract by 1 - omega (1 - rho) instead of rho per iteration
// (docs/fidelity.md, "Over-relaxation"). Tets that take the exact rotation are not relaxed.
// Volume term: with `volume_weight` (one float per slot, the blocks' lane layout: w_j in [0, 1)),
// tet j's energy is a_j [(1 - w_j) ||F_j - R_j||^2 + w_j ||F_j - T_j||^2], T_j = F_j + s_j R_j with
// det T_j = 1, and delta receives a_j (M_j - I) G_j with M_j = (1 - w_j) R_j + w_j T_j instead of
// a_j (R_j - I) G_j: the factor does not change (volumeBlend in rotation_kernel.cpp). The energy
// returned is then this combined one. nullptr: the plain as-rigid-as-possible pass.
// `det_out` (one float per slot, the blocks' lane layout), if not null, receives each tet's det F
// at `u` (the implicit inversion guard's input: inversion_guard.cpp).
RotationPassStats rotationPass(TetBlock* blocks, std::int32_t block_count, const double* u, float* delta,
                               int steps, std::uint16_t* exact_lanes, float relax = 0.0f,
                               const float* volume_weight = nullptr, const float* guard = nullptr,
                               float guard_threshold = 0.5f, float* det_out = nullptr);

// The inversion guard's largest push alpha ||R - F|| (Frobenius): a tet far from any rotation (a
// frame's first iteration after a jump) is not kicked; beyond it the guard's energy grows linearly
// (rotation_kernel.cpp, inversionGuard). 1 leaves the steady guard whole and removes the kick at a
// cold start; smaller caps weaken the steady guard.
inline constexpr float kInversionGuardPushCap = 1.0f;

// The inversion guard of one tet in double (the scalar form of the kernel's inversionGuard, for
// the exact-rotation fallback and for reference energies): k and tau as in DeformerOptions, det F,
// and off = ||F - R||. `alpha` is the push's factor (target R + alpha (R - F)), `extra` the
// guard's energy over a: alpha off^2, or 2 c off - c^2 / alpha beyond the push cap c.
struct InversionGuardTerm {
  double alpha = 0.0;
  double extra = 0.0;
};
// push_cap false: the implicit guard's (DeformerOptions::inversion_guard_solves > 0), uncapped.
inline InversionGuardTerm inversionGuardTerm(double k, double tau, double det, double off, bool push_cap = true) {
  const double alpha = k * (tau - det) / tau;
  if (!(alpha > 0.0)) return {};
  const double a = alpha < k ? alpha : k;
  const double c = kInversionGuardPushCap;
  if (!push_cap || a * off <= c) return {a, a * off * off};
  return {c / off, c * (2.0 * off - c / a)};
}

// The instruction set the kernels run with on this machine ("avx512f", "avx2", "baseline").
const char* rotationKernelInstructionSet();

// Adds a_j (R_j - I) G_j of every tet into `delta` from the stored rotations (no extraction);
// with `volume_weight`, a_j (M_j - I) G_j with the volume target of the displacements `u`.
void differentialPass(const TetBlock* blocks, std::int32_t block_count, float* delta, const double* u = nullptr,
                      const float* volume_weight = nullptr, const float* guard = nullptr,
                      float guard_threshold = 0.5f);

}  // namespace tetrig
