// Untangling the published pose (DeformerOptions::untangle, with the implicit guard;
// docs/deformation.md, "Untangling the published pose").
//
// After a frame's last iteration a few body tets may still be nearly or wholly inside out (the
// guard stiffens them, but one conjugate-gradient step per iteration does not carry them all the
// way). Their free corners are relaxed by Gauss-Seidel on the same guarded energy with the
// rotations of the last rotation pass held, and where a tet is still inside out after that, its
// corners and their neighbours (one ring) once more: for a vertex v,
//
//     E(x_v) = sum_{t of v} a_t (1 + alpha_t) ||F_t - R_t||^2,   F_t = sum_k x_k g_{t,k}^T,
//
// with g_{t,k} row k of E_t^-1 for the corners k = 0..2 and g_{t,3} = -(g_{t,0} + g_{t,1} + g_{t,2}),
// is a quadratic in x_v alone with the Hessian 2 sum_t a_t (1 + alpha_t) |g_{t,k}|^2 I, so
//
//     x_v -= sum_t a_t (1 + alpha_t) (F_t - R_t) g_{t,k} / sum_t a_t (1 + alpha_t) |g_{t,k}|^2
//
// is its exact minimum. Each update lowers the energy the frame's iterations lower (alpha_t as the
// guard's at the tet's current volume ratio), so it moves the pose toward the converged one, and
// R_t, a rotation, pulls a turned-over F_t back through zero. Only the published positions change:
// the next frame's first solve starts from the rotations, as without it.
#include "guard_columns.hpp"
#include "tetrig/deformer_impl.hpp"
#include "tetrig/rotation_kernel.hpp"

#include <algorithm>
#include <array>
#include <cmath>

namespace tetrig {
namespace {

// Below this volume ratio (det F) a body tet's corners are relaxed after the frame's last iteration.
constexpr float kUntangleBelow = 0.1f;
// Gauss-Seidel sweeps over those corners.
constexpr int kUntangleSweeps = 8;
// Then, only where a tet is still inside out, sweeps over its corners and their neighbours (about ten
// times the vertices: in every untangling frame, a quarter of HDM05's, that cost over 100 us).
constexpr int kUntangleRingSweeps = 6;

}  // namespace

void DeformerImpl::buildUntangleAdjacency() {
  // Free vertex slot -> the tet slots it is a corner of (CSR).
  const auto free = static_cast<size_t>(free_count_);
  untangle_start_.assign(free + 1, 0);
  const auto forEachFreeCorner = [&](auto&& f) {
    for (std::int32_t s = 0; s < tet_count_; ++s) {
      const TetBlock& block = blocks_[static_cast<size_t>(s / kTetBlockWidth)];
      for (int c = 0; c < 4; ++c) {
        const auto v = static_cast<size_t>(block.corner_offset[c][s % kTetBlockWidth] / kVectorStride);
        if (v < free) f(v, s);
      }
    }
  };
  forEachFreeCorner([&](size_t v, std::int32_t) { ++untangle_start_[v + 1]; });
  for (size_t v = 0; v < free; ++v) untangle_start_[v + 1] += untangle_start_[v];
  untangle_tet_.assign(static_cast<size_t>(untangle_start_[free]), 0);
  std::vector<std::int32_t> fill(untangle_start_.begin(), untangle_start_.end() - 1);
  forEachFreeCorner([&](size_t v, std::int32_t s) { untangle_tet_[static_cast<size_t>(fill[v]++)] = s; });
  untangle_vertex_.clear();
  untangle_vertex_.reserve(free);
  untangle_tangled_.clear();
  untangle_tangled_.reserve(static_cast<size_t>(tet_count_));
  untangle_mark_.assign(free, 0);
}

void DeformerImpl::untangle() {
  // The body tets below kUntangleBelow at the last rotation pass, and their free corners.
  untangle_vertex_.clear();
  untangle_tangled_.clear();
  const auto free = static_cast<size_t>(free_count_);
  const auto addCorners = [&](std::int32_t s) {
    const TetBlock& block = blocks_[static_cast<size_t>(s / kTetBlockWidth)];
    for (int c = 0; c < 4; ++c) {
      const auto v = static_cast<size_t>(block.corner_offset[c][s % kTetBlockWidth] / kVectorStride);
      if (v < free && !untangle_mark_[v]) {
        untangle_mark_[v] = 1;
        untangle_vertex_.push_back(static_cast<std::int32_t>(v));
      }
    }
  };
  forEachGuardedTetBelow(kUntangleBelow, [&](std::int32_t s) {
    untangle_tangled_.push_back(s);
    addCorners(s);
  });
  if (untangle_tangled_.empty()) return;
  // H of slot s at the current displacements (F = I + H) and its det F, as three columns
  // (guard_columns.hpp); dF / dx of the corner at `offset` is cornerGradient's g: (F - R) g is
  // sum_j (h_j - (R - I)_j) g_j.
  using guard_columns::Columns;
  using guard_columns::Vec4;
  const auto determinant = [this](std::int32_t s) {
    return guard_columns::determinantOfIdentityPlus(guard_columns::gradientColumns(gatherTet(blocks_.data(), s), u_.data()));
  };
  const double tau = options_.inversion_guard_threshold;
  const auto relax = [&](int sweeps) {
    for (int sweep = 0; sweep < sweeps; ++sweep) {
      for (const std::int32_t v : untangle_vertex_) {
        const auto offset = static_cast<std::int32_t>(kVectorStride) * v;
        Vec4 gradient{};
        double curvature = 0.0;
        for (std::int32_t i = untangle_start_[static_cast<size_t>(v)]; i < untangle_start_[static_cast<size_t>(v) + 1]; ++i) {
          const std::int32_t s = untangle_tet_[static_cast<size_t>(i)];
          const GuardedTet t = gatherTet(blocks_.data(), s);
          const Columns h = guard_columns::gradientColumns(t, u_.data());
          const Columns r = guard_columns::rotationMinusIdentity(blocks_.data(), s);
          const auto k = static_cast<int>(std::find(t.corner.begin(), t.corner.begin() + 3, offset) - t.corner.begin());
          const std::array<double, 3> g = guard_columns::cornerGradient(t, k);
          double a = blocks_[static_cast<size_t>(s / kTetBlockWidth)].weight[s % kTetBlockWidth];
          if (guard_[static_cast<size_t>(s)] > 0.0f) {
            const double det = guard_columns::determinantOfIdentityPlus(h);
            a *= 1.0 + inversionGuardTerm(guard_[static_cast<size_t>(s)], tau, det, 0.0, /*push_cap=*/false).alpha;
          }
          gradient += ((h.c[0] - r.c[0]) * g[0] + (h.c[1] - r.c[1]) * g[1] + (h.c[2] - r.c[2]) * g[2]) * a;
          curvature += a * (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
        }
        if (!(curvature > 0.0)) continue;
        const Vec4 step = gradient / curvature;
        if (!(std::isfinite(step[0]) && std::isfinite(step[1]) && std::isfinite(step[2]))) continue;
        for (int c = 0; c < 3; ++c) u_[static_cast<size_t>(offset + c)] -= step[c];
      }
    }
  };
  relax(kUntangleSweeps);
  // A tet still inside out: its corners' neighbours make room too (one ring more; rare, so the
  // ring's cost stays off the frames the corners alone untangle).
  const bool inverted = std::any_of(untangle_tangled_.begin(), untangle_tangled_.end(),
                                    [&](std::int32_t s) { return !(determinant(s) > 0.0); });
  if (inverted) {
    const size_t corners = untangle_vertex_.size();
    for (size_t i = 0; i < corners; ++i) {
      const auto v = static_cast<size_t>(untangle_vertex_[i]);
      for (std::int32_t j = untangle_start_[v]; j < untangle_start_[v + 1]; ++j) addCorners(untangle_tet_[static_cast<size_t>(j)]);
    }
    relax(kUntangleRingSweeps);
  }
  for (const std::int32_t v : untangle_vertex_) untangle_mark_[static_cast<size_t>(v)] = 0;
}

}  // namespace tetrig
