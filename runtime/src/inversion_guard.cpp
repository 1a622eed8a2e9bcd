// The implicit inversion guard (DeformerOptions::inversion_guard_solves > 0; docs/deformation.md,
// "Implicit inversion guard").
//
// A guarded tet j whose volume ratio J = det F_j fell below tau at the last rotation pass takes
// extra stiffness alpha_j = k min(1, (tau - J) / tau) on its rotation term, as with the explicit
// guard, but the extra term enters the global step itself:
//
//     (L + sum_j alpha_j a_j G_j^T G_j) u = b + sum_j alpha_j a_j G_j^T (R_j - I),
//
// with L u = b the plain step (b: the rotation pass's delta and the handle terms), G_j the tet's
// displacement gradient (H_j = G_j u: corner k's column u_k - u_3 times E_j^-1), R_j its stored
// rotation. The factor is L's: the system is solved by preconditioned conjugate gradients with L^-1
// as the preconditioner, started from the plain solution u_0 = L^-1 b. Its residual
//
//     r_0 = sum_j alpha_j a_j G_j^T (R_j - I - H_j(u_0))
//
// lives on the guarded tets' corners only, and L^-1 (L + U) = I + L^-1 U differs from I by a
// matrix of rank 3 x (guarded tets), so a few steps remove most of it. L p is kept by the
// recurrence L p_{i+1} = r_{i+1} + beta L p_i (L z = r), so each step costs one solve with the
// factor (three right-hand sides, one per coordinate: the system is the same for x, y and z, and
// each coordinate takes its own step lengths) plus the guarded tets' product. That solve runs on
// the factor rounded to float (M = L to ~1e-7 of its entries): L z = r and p^T L p = r . z then
// hold to ~1e-6, and the step u += gamma p stays a descent step of the guarded energy. No bound on k: the
// splitting of the explicit guard is not used, so nothing limits it to k <= 1 and no push cap is
// needed. Handles do not move: their components of r, z, p are kept 0.
#include "tetrig/deformer_impl.hpp"
#include "tetrig/rotation_kernel.hpp"
#include "guard_columns.hpp"
#include "multiversion.hpp"
#include "padded_dot.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <span>

namespace tetrig {
namespace {

// The per-tet passes over the held tets, compiled for the widest instruction set (a 3x3 matrix as
// three (x, y, z, 0) columns: guard_columns.hpp).
using guard_columns::Columns;
using guard_columns::gradientColumns;
using guard_columns::rotationMinusIdentity;
using guard_columns::scatterColumns;
using lanes::Vec4;

// out += sum_j alpha_j a_j G_j^T (R_j - I - H_j(u)) (out's handle components are cleared by the caller).
TETRIG_MULTIVERSION void addGuardResidual(std::span<const GuardedTet> held, const TetBlock* blocks, const double* u, double* out) {
  for (const GuardedTet& t : held) {
    const Columns r = rotationMinusIdentity(blocks, t.slot), h = gradientColumns(t, u);
    Columns x;
    for (int j = 0; j < 3; ++j) x.c[j] = (r.c[j] - h.c[j]) * t.coef;
    scatterColumns(t, x, out);
  }
}

// sum_j alpha_j a_j ||row c of G_j p||^2 for c = x, y, z, added into pap (p in double, or the float
// solve's own output).
template <typename T>
TETRIG_INLINE void guardCurvature(std::span<const GuardedTet> held, const T* p, std::array<double, 3>& pap) {
  Vec4 sum{};
  for (const GuardedTet& t : held) {
    const Columns h = gradientColumns(t, p);
    sum += (h.c[0] * h.c[0] + h.c[1] * h.c[1] + h.c[2] * h.c[2]) * t.coef;
  }
  for (size_t c = 0; c < 3; ++c) pap[c] += sum[c];
}
TETRIG_MULTIVERSION void addGuardCurvature(std::span<const GuardedTet> held, const double* p, std::array<double, 3>& pap) {
  guardCurvature(held, p, pap);
}
TETRIG_MULTIVERSION void addGuardCurvature(std::span<const GuardedTet> held, const float* p, std::array<double, 3>& pap) {
  guardCurvature(held, p, pap);
}

// sum over the free corners c of r_c z_c, per lane (r is 0 at every other free vertex).
std::array<double, 3> cornerDot(std::span<const std::int32_t> corners, std::size_t free4, const double* r, const float* z) {
  std::array<double, 3> sum{};
  for (const std::int32_t c : corners) {
    if (static_cast<std::size_t>(c) >= free4) continue;
    for (size_t k = 0; k < 3; ++k) sum[k] += r[static_cast<size_t>(c) + k] * static_cast<double>(z[static_cast<size_t>(c) + k]);
  }
  return sum;
}

// The step length along p per coordinate, gamma_c = (r . z)_c / (p^T A p)_c (0 where either is not
// positive).
std::array<double, 3> stepLengths(const std::array<double, 3>& rz, const std::array<double, 3>& pap) {
  std::array<double, 3> gamma{};
  for (size_t c = 0; c < 3; ++c) gamma[c] = pap[c] > 0.0 && rz[c] > 0.0 ? rz[c] / pap[c] : 0.0;
  return gamma;
}

// out -= gamma (per coordinate) G^T G p summed over the held tets: the guarded part of A p.
TETRIG_MULTIVERSION void subtractGuardProduct(std::span<const GuardedTet> held, const std::array<double, 3>& gamma, const double* p,
                                              double* out) {
  const Vec4 minus_gamma{-gamma[0], -gamma[1], -gamma[2], 0.0};
  for (const GuardedTet& t : held) {
    Columns x = gradientColumns(t, p);
    for (int j = 0; j < 3; ++j) x.c[j] *= minus_gamma * t.coef;
    scatterColumns(t, x, out);
  }
}

}  // namespace

TETRIG_MULTIVERSION std::size_t blocksWithDetAtMost(const float* det, std::size_t block_count, float bound, std::int32_t* out) noexcept {
  const lanes::FLanes at = lanes::FLanes{} + bound;
  std::size_t n = 0;
  for (std::size_t b = 0; b < block_count; ++b) {
    // Lanes 0 or -1, folded by halves (a scalar OR of 16 extracted lanes took 8 ns a block).
    const lanes::FMask below = lanes::loadF(det + b * kTetBlockWidth) <= at;
    using Mask8 = int __attribute__((vector_size(8 * sizeof(int))));
    using Mask4 = int __attribute__((vector_size(4 * sizeof(int))));
    const Mask8 m8 = __builtin_shufflevector(below, below, 0, 1, 2, 3, 4, 5, 6, 7) |
                     __builtin_shufflevector(below, below, 8, 9, 10, 11, 12, 13, 14, 15);
    const Mask4 m4 = __builtin_shufflevector(m8, m8, 0, 1, 2, 3) | __builtin_shufflevector(m8, m8, 4, 5, 6, 7);
    const Mask4 m2 = m4 | __builtin_shufflevector(m4, m4, 2, 3, 0, 1);
    const int any = m2[0] | m2[1];
    out[n] = static_cast<std::int32_t>(b);
    n += any != 0 ? 1 : 0;
  }
  return n;
}

void DeformerImpl::collectGuardedTets() {
  // det F of every slot from the rotation pass (float, as the explicit guard's); most tets are
  // above tau, so this is a scan of two float arrays. alpha as the explicit guard's scalar form
  // (inversionGuardTerm), without its push cap. Each held tet's corners and E^-1 are gathered here
  // once (16 lanes apart in its block), for the two or more passes over them in the solve.
  const double tau = options_.inversion_guard_threshold;
  std::size_t n = 0;
  forEachGuardedTetBelow(tau, [&](std::int32_t s) {
    const double alpha = inversionGuardTerm(guard_[static_cast<size_t>(s)], tau, guard_det_[static_cast<size_t>(s)], 0.0, /*push_cap=*/false).alpha;
    GuardedTet& t = guarded_[n++];
    t = gatherTet(blocks_.data(), s);
    t.coef = alpha * blocks_[static_cast<size_t>(s / kTetBlockWidth)].weight[s % kTetBlockWidth];
  });
  guarded_count_ = n;
  // Their corners, each once (the residual r_0 lives there).
  std::size_t corners = 0;
  for (std::size_t i = 0; i < n; ++i) {
    for (const std::int32_t c : guarded_[i].corner) {
      std::uint8_t& mark = guard_corner_mark_[static_cast<size_t>(c) / kVectorStride];
      if (mark != 0) continue;
      mark = 1;
      guard_corners_[corners++] = c;
    }
  }
  for (std::size_t i = 0; i < corners; ++i) guard_corner_mark_[static_cast<size_t>(guard_corners_[i]) / kVectorStride] = 0;
  guard_corner_count_ = corners;
}

void DeformerImpl::precondition() {
  // z = M^-1 r with M the factor rounded to float, solved in float: the solve reads half the bytes,
  // and a search direction needs no more digits (the step length is computed for the direction it
  // is given).
  const size_t free4 = static_cast<size_t>(free_count_) * kVectorStride;
  float* zf = cg_float_.data();
  toFloat(cg_r_.data(), zf, free4);
  factor_.solveInPlace(zf);
  toDouble(zf, cg_z_.data(), free4);
  std::fill(cg_z_.begin() + static_cast<std::ptrdiff_t>(free4), cg_z_.end(), 0.0);
}

void DeformerImpl::implicitGuardSolve() {
  const size_t free4 = static_cast<size_t>(free_count_) * kVectorStride;
  const std::span<const GuardedTet> held(guarded_.data(), guarded_count_);
  const std::span<const std::int32_t> corners(guard_corners_.data(), guard_corner_count_);
  // r_0 = sum_j alpha_j a_j G_j^T (R_j - I - H_j(u_0)), on the held tets' corners only (cg_r_ is 0
  // everywhere else; its handle components are never read). R_j is read here, not when the tet was
  // gathered: the frame's prediction and guide may have turned it since.
  addGuardResidual(held, blocks_.data(), u_.data(), cg_r_.data());
  // z_0 = M^-1 r_0 in float, r_0 written at its corners only. r_0 is zero but at the guarded tets'
  // vertices: the forward pass skips the supernodes it does not reach (about a fifth of the solve
  // on the shipped asset).
  float* zf = cg_float_.data();
  std::fill_n(zf, free4, 0.0f);
  for (const std::int32_t c : corners) {
    if (static_cast<size_t>(c) >= free4) continue;
    for (size_t k = 0; k < kVectorStride; ++k) zf[static_cast<size_t>(c) + k] = static_cast<float>(cg_r_[static_cast<size_t>(c) + k]);
  }
  if (free_count_ > 0) factor_.solveInPlace(zf, /*skip_zero_nodes=*/true);
  std::array<double, 3> rz = cornerDot(corners, free4, cg_r_.data(), zf);
  if (options_.inversion_guard_solves == 1) {
    // The live setting: one step along p_0 = z_0, read from the float solve where it lies (widened
    // exactly; the same step as from its double copy). p_0^T L p_0 = r_0 . z_0.
    std::array<double, 3> pap = rz;
    addGuardCurvature(held, zf, pap);
    const std::array<double, 3> gamma = stepLengths(rz, pap);
    // u += gamma p, landing back on the linear constraint's plane when there is one: g . u was its
    // right-hand side before this step (applyLinearConstraint), so what the step moved it by,
    // gamma_c (g . p)_c, is taken out along z in the same pass and added to the multiplier.
    if (constraint_active_) {
      const std::array<double, kVectorStride> gp = paddedDotByLane(constraint_g_.data(), zf, free4);
      const double mu_left = -(gamma[0] * gp[0] + gamma[1] * gp[1] + gamma[2] * gp[2]) / constraint_gz_;
      addScaledByLaneAndScaled(u_.data(), gamma, zf, mu_left, constraint_z_.data(), free4);
      constraint_mu_ += mu_left;
    } else {
      addScaledByLane(u_.data(), gamma, zf, free4);
    }
    for (const std::int32_t c : corners) std::fill_n(&cg_r_[static_cast<size_t>(c)], kVectorStride, 0.0);
    return;
  }
  toDouble(zf, cg_z_.data(), free4);
  std::fill(cg_z_.begin() + static_cast<std::ptrdiff_t>(free4), cg_z_.end(), 0.0);
  std::fill(cg_r_.begin() + static_cast<std::ptrdiff_t>(free4), cg_r_.end(), 0.0);
  const auto dot3 = [free4](const double* a, const double* b) {
    const std::array<double, kVectorStride> d = paddedDotByLane(a, b, free4);
    return std::array<double, 3>{d[0], d[1], d[2]};
  };
  // p_0 = z_0 and L p_0 = L z_0 = r_0: the first step reads them where they are (and p_0^T L p_0 is
  // r_0 . z_0); they are copied out only when a further step follows (then z and r change).
  const double* p = cg_z_.data();
  const double* lp = cg_r_.data();
  for (int step = 0; step < options_.inversion_guard_solves; ++step) {
    // p^T A p = p^T L p + sum_j alpha_j a_j ||G_j p||^2, per coordinate (row c of G_j p). A p is
    // never stored: its dense part is L p, its guarded part is local.
    std::array<double, 3> pap = step == 0 ? rz : dot3(p, lp);
    addGuardCurvature(held, p, pap);
    const std::array<double, 3> gamma = stepLengths(rz, pap);
    // u += gamma p; then, unless this was the last step, r -= gamma A p (the dense part here, the
    // guarded part below). The last step also lands u back on the linear constraint's plane.
    if (step + 1 == options_.inversion_guard_solves) {
      addScaledByLane(u_.data(), gamma, p, free4);
      if (constraint_active_) applyLinearConstraint();
      break;
    }
    addScaledByLane(u_.data(), gamma, p, free4);
    if (step == 0) {
      std::copy(cg_z_.begin(), cg_z_.end(), cg_p_.begin());
      std::copy(cg_r_.begin(), cg_r_.end(), cg_lp_.begin());
      p = cg_p_.data();
      lp = cg_lp_.data();
    }
    addScaledByLane(cg_r_.data(), {-gamma[0], -gamma[1], -gamma[2]}, lp, free4);
    subtractGuardProduct(held, gamma, p, cg_r_.data());
    std::fill(cg_r_.begin() + static_cast<std::ptrdiff_t>(free4), cg_r_.end(), 0.0);
    precondition();
    const std::array<double, 3> rz_next = dot3(cg_r_.data(), cg_z_.data());
    std::array<double, 3> beta{};
    for (size_t c = 0; c < 3; ++c) beta[c] = rz[c] > 0.0 ? rz_next[c] / rz[c] : 0.0;
    for (size_t i = 0; i < free4; i += kVectorStride) {
      for (size_t c = 0; c < 3; ++c) {
        cg_p_[i + c] = cg_z_[i + c] + beta[c] * cg_p_[i + c];
        cg_lp_[i + c] = cg_r_[i + c] + beta[c] * cg_lp_[i + c];
      }
    }
    rz = rz_next;
  }
  std::fill(cg_r_.begin(), cg_r_.end(), 0.0);  // r has spread over every vertex: 0 again for the next solve
}

}  // namespace tetrig
