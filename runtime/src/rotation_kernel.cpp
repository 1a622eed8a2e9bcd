// Fused rotation extraction + differential-coordinate update (Stoll et al. 2007, 2.3.2), with
// the warm-started rotation iteration of Mueller et al. 2016. See rotation_kernel.hpp.
#include "tetrig/rotation_kernel.hpp"

#include "tetrig/polar.hpp"

#include <cmath>

// x86-64: compile the lane loops for AVX-512, AVX2 and baseline, chosen at load time by the
// dynamic loader (ifunc). Other targets (aarch64) get the portable build only.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(TETRIG_NO_MULTIVERSION)
#define TETRIG_KERNEL_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define TETRIG_KERNEL_CLONES
#endif

namespace tetrig {

namespace {

constexpr int W = kTetBlockWidth;

// Rotation matrix of a unit quaternion, row-major r[3 * row + col].
inline void quaternionToMatrix(double w, double x, double y, double z, double* r) {
  const double xx = x * x, yy = y * y, zz = z * z;
  const double xy = x * y, xz = x * z, yz = y * z, wx = w * x, wy = w * y, wz = w * z;
  r[0] = 1.0 - 2.0 * (yy + zz);
  r[1] = 2.0 * (xy - wz);
  r[2] = 2.0 * (xz + wy);
  r[3] = 2.0 * (xy + wz);
  r[4] = 1.0 - 2.0 * (xx + zz);
  r[5] = 2.0 * (yz - wx);
  r[6] = 2.0 * (xz - wy);
  r[7] = 2.0 * (yz + wx);
  r[8] = 1.0 - 2.0 * (xx + yy);
}

// Scatter of a R E^-T into delta for one block, from per-lane rotation matrices r[9][W].
inline void scatterBlock(const TetBlock& block, const double (&r)[9][W], double* delta) {
  double m[9][W];  // m[3 * row + k]: component `row` of a R grad phi_k
#pragma omp simd
  for (int l = 0; l < W; ++l) {
    for (int row = 0; row < 3; ++row) {
      for (int k = 0; k < 3; ++k) {
        m[3 * row + k][l] = block.weight[l] * (r[3 * row][l] * block.edge_inverse[3 * k][l] +
                                               r[3 * row + 1][l] * block.edge_inverse[3 * k + 1][l] +
                                               r[3 * row + 2][l] * block.edge_inverse[3 * k + 2][l]);
      }
    }
  }
  for (int l = 0; l < W; ++l) {
    for (int k = 0; k < 3; ++k) {
      double* d = delta + 3 * block.corner[k][l];
      d[0] += m[k][l];
      d[1] += m[3 + k][l];
      d[2] += m[6 + k][l];
    }
    double* d = delta + 3 * block.corner[3][l];
    d[0] -= m[0][l] + m[1][l] + m[2][l];
    d[1] -= m[3][l] + m[4][l] + m[5][l];
    d[2] -= m[6][l] + m[7][l] + m[8][l];
  }
}

}  // namespace

TETRIG_KERNEL_CLONES
RotationPassStats rotationPass(TetBlock* blocks, std::int32_t block_count, const double* xyz, double* delta,
                               int steps) {
  RotationPassStats stats;
  double energy = 0.0;
  for (std::int32_t b = 0; b < block_count; ++b) {
    TetBlock& block = blocks[b];
    // Gather the edges x_ck - x_c3.
    double e[9][W];  // e[3 * k + c]: component c of edge k
    for (int l = 0; l < W; ++l) {
      const double* p3 = xyz + 3 * block.corner[3][l];
      for (int k = 0; k < 3; ++k) {
        const double* pk = xyz + 3 * block.corner[k][l];
        e[3 * k][l] = pk[0] - p3[0];
        e[3 * k + 1][l] = pk[1] - p3[1];
        e[3 * k + 2][l] = pk[2] - p3[2];
      }
    }
    // F = E' E^-1: F(row, col) = sum_k e_k[row] * Einv(k, col).
    double f[9][W];
    double det[W];
#pragma omp simd
    for (int l = 0; l < W; ++l) {
      for (int row = 0; row < 3; ++row) {
        for (int col = 0; col < 3; ++col) {
          f[3 * row + col][l] = e[row][l] * block.edge_inverse[col][l] +
                                e[3 + row][l] * block.edge_inverse[3 + col][l] +
                                e[6 + row][l] * block.edge_inverse[6 + col][l];
        }
      }
      det[l] = f[0][l] * (f[4][l] * f[8][l] - f[5][l] * f[7][l]) -
               f[1][l] * (f[3][l] * f[8][l] - f[5][l] * f[6][l]) +
               f[2][l] * (f[3][l] * f[7][l] - f[4][l] * f[6][l]);
    }
    // Current rotation and its trace against F.
    double r[9][W], trace[W], damping[W];
#pragma omp simd
    for (int l = 0; l < W; ++l) {
      damping[l] = 0.5;  // (1, omega / 2): the half-angle vector; halved again after a rejected step
      double rl[9];
      quaternionToMatrix(block.rotation[0][l], block.rotation[1][l], block.rotation[2][l], block.rotation[3][l], rl);
      double t = 0.0;
      for (int i = 0; i < 9; ++i) {
        r[i][l] = rl[i];
        t += rl[i] * f[i][l];
      }
      trace[l] = t;
    }
    // Warm-started refinement: q <- normalize((1, omega / 2) q), kept only if tr(R^T F) does not
    // drop; a rejected step halves that lane's step for the rest of the pass.
    for (int s = 0; s < steps; ++s) {
#pragma omp simd
      for (int l = 0; l < W; ++l) {
        // omega = sum_c r_c x f_c over columns c, scaled by 1 / (|tr| + eps).
        double ox = 0.0, oy = 0.0, oz = 0.0;
        for (int c = 0; c < 3; ++c) {
          ox += r[3 + c][l] * f[6 + c][l] - r[6 + c][l] * f[3 + c][l];
          oy += r[6 + c][l] * f[c][l] - r[c][l] * f[6 + c][l];
          oz += r[c][l] * f[3 + c][l] - r[3 + c][l] * f[c][l];
        }
        const double scale = damping[l] / (std::abs(trace[l]) + 1e-9);
        const double hx = ox * scale, hy = oy * scale, hz = oz * scale;  // (1, h): half-angle vector
        const double w0 = block.rotation[0][l], x0 = block.rotation[1][l], y0 = block.rotation[2][l],
                     z0 = block.rotation[3][l];
        double w1 = w0 - hx * x0 - hy * y0 - hz * z0;
        double x1 = x0 + hx * w0 + hy * z0 - hz * y0;
        double y1 = y0 + hy * w0 + hz * x0 - hx * z0;
        double z1 = z0 + hz * w0 + hx * y0 - hy * x0;
        const double inv_norm = 1.0 / std::sqrt(w1 * w1 + x1 * x1 + y1 * y1 + z1 * z1);
        w1 *= inv_norm;
        x1 *= inv_norm;
        y1 *= inv_norm;
        z1 *= inv_norm;
        double rl[9];
        quaternionToMatrix(w1, x1, y1, z1, rl);
        double t = 0.0;
        for (int i = 0; i < 9; ++i) t += rl[i] * f[i][l];
        const bool accept = t >= trace[l];  // false on NaN as well
        block.rotation[0][l] = accept ? w1 : w0;
        block.rotation[1][l] = accept ? x1 : x0;
        block.rotation[2][l] = accept ? y1 : y0;
        block.rotation[3][l] = accept ? z1 : z0;
        for (int i = 0; i < 9; ++i) r[i][l] = accept ? rl[i] : r[i][l];
        trace[l] = accept ? t : trace[l];
        damping[l] = accept ? damping[l] : 0.5 * damping[l];
      }
    }
    // Exact rotation for inverted and degenerate tets, where the local iteration can stall.
    for (int l = 0; l < W; ++l) {
      if (block.weight[l] > 0.0 && !(det[l] > 1e-12)) {
        Eigen::Matrix3d fl;
        for (int i = 0; i < 9; ++i) fl(i / 3, i % 3) = f[i][l];
        const Eigen::Quaterniond q = closestRotation(fl);
        block.rotation[0][l] = q.w();
        block.rotation[1][l] = q.x();
        block.rotation[2][l] = q.y();
        block.rotation[3][l] = q.z();
        double rl[9];
        quaternionToMatrix(q.w(), q.x(), q.y(), q.z(), rl);
        double t = 0.0;
        for (int i = 0; i < 9; ++i) {
          r[i][l] = rl[i];
          t += rl[i] * f[i][l];
        }
        trace[l] = t;
        ++stats.exact_fallbacks;
      }
    }
    // Energy a (||F||^2 - 2 tr + 3).
    double block_energy = 0.0;
#pragma omp simd reduction(+ : block_energy)
    for (int l = 0; l < W; ++l) {
      double ff = 0.0;
      for (int i = 0; i < 9; ++i) ff += f[i][l] * f[i][l];
      block_energy += block.weight[l] * (ff - 2.0 * trace[l] + 3.0);
    }
    energy += block_energy;
    if (delta != nullptr) scatterBlock(block, r, delta);
  }
  stats.energy = energy;
  return stats;
}

TETRIG_KERNEL_CLONES
void differentialPass(const TetBlock* blocks, std::int32_t block_count, double* delta) {
  for (std::int32_t b = 0; b < block_count; ++b) {
    const TetBlock& block = blocks[b];
    double r[9][W];
#pragma omp simd
    for (int l = 0; l < W; ++l) {
      double rl[9];
      quaternionToMatrix(block.rotation[0][l], block.rotation[1][l], block.rotation[2][l], block.rotation[3][l], rl);
      for (int i = 0; i < 9; ++i) r[i][l] = rl[i];
    }
    scatterBlock(block, r, delta);
  }
}

}  // namespace tetrig
