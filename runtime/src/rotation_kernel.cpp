// Fused rotation extraction + differential-coordinate update (Stoll et al. 2007, 2.3.2), with
// the warm-started rotation iteration of Mueller et al. 2016. See rotation_kernel.hpp.
//
// Lanes: one `Lanes` value holds one quantity of the kTetBlockWidth (8) tets of a block, written
// with GCC/Clang vector extensions so every build (AVX-512, AVX2, SSE2, NEON) vectorises the same
// source. Corner positions move between per-vertex vectors (x, y, z, pad) and lanes by shuffles;
// scalar code remains only for the rare exact fallback, which runs after the pass.
//
// Two blocks go through the pass together (Pack<2>): each long dependency chain (the divisions,
// the square root, the refinement steps) then has an independent twin in the same instruction
// stream for the out-of-order core to overlap. The hot loop holds no function call, so its values
// stay in registers.
#include "tetrig/rotation_kernel.hpp"

#include "tetrig/ldlt_factor.hpp"
#include "tetrig/polar.hpp"

#include <cmath>
#include <cstring>

#include "multiversion.hpp"
#include "vector_lanes.hpp"

namespace tetrig {

namespace {

using namespace lanes;
constexpr int W = kTetBlockWidth;
static_assert(sizeof(Lanes) == sizeof(double) * W);

TETRIG_INLINE Lanes splat(double x) { return Lanes{} + x; }
TETRIG_INLINE Lanes select(Mask m, Lanes a, Lanes b) { return m ? a : b; }
TETRIG_INLINE Lanes absolute(Lanes x) { return select(x < 0.0, -x, x); }
TETRIG_INLINE Lanes squareRoot(Lanes x) {
  double lanes[W];
  store(lanes, x);
  for (double& v : lanes) v = __builtin_sqrt(v);  // -fno-math-errno: one vector sqrt
  return load(lanes);
}

// N consecutive blocks processed together: every long dependency chain of the pass (divisions,
// square root, the refinement steps) gets N - 1 independent twins in the same instruction stream,
// which the out-of-order core overlaps; one block alone leaves it waiting on latency.
// Pack<N> is N lane vectors with element-wise operators (each operator is N vector instructions).
template <int N>
struct Pack {
  Lanes v[N];
};
template <int N>
struct PackMask {
  Mask v[N];
};
#define TETRIG_PACK_OP(op)                                                                   \
  template <int N>                                                                           \
  TETRIG_INLINE Pack<N> operator op(const Pack<N>& a, const Pack<N>& b) {                     \
    Pack<N> r;                                                                               \
    for (int n = 0; n < N; ++n) r.v[n] = a.v[n] op b.v[n];                                   \
    return r;                                                                                \
  }                                                                                          \
  template <int N>                                                                           \
  TETRIG_INLINE Pack<N> operator op(double a, const Pack<N>& b) {                             \
    Pack<N> r;                                                                               \
    for (int n = 0; n < N; ++n) r.v[n] = a op b.v[n];                                        \
    return r;                                                                                \
  }                                                                                          \
  template <int N>                                                                           \
  TETRIG_INLINE Pack<N> operator op(const Pack<N>& a, double b) {                             \
    Pack<N> r;                                                                               \
    for (int n = 0; n < N; ++n) r.v[n] = a.v[n] op b;                                        \
    return r;                                                                                \
  }                                                                                          \
  template <int N>                                                                           \
  TETRIG_INLINE Pack<N>& operator op##=(Pack<N>& a, const Pack<N>& b) {                       \
    for (int n = 0; n < N; ++n) a.v[n] = a.v[n] op b.v[n];                                   \
    return a;                                                                                \
  }
TETRIG_PACK_OP(+)
TETRIG_PACK_OP(-)
TETRIG_PACK_OP(*)
TETRIG_PACK_OP(/)
#undef TETRIG_PACK_OP
template <int N>
TETRIG_INLINE Pack<N> operator-(const Pack<N>& a) {
  Pack<N> r;
  for (int n = 0; n < N; ++n) r.v[n] = -a.v[n];
  return r;
}
template <int N>
TETRIG_INLINE PackMask<N> operator>=(const Pack<N>& a, const Pack<N>& b) {
  PackMask<N> r;
  for (int n = 0; n < N; ++n) r.v[n] = a.v[n] >= b.v[n];
  return r;
}
template <int N>
TETRIG_INLINE Pack<N> select(const PackMask<N>& m, const Pack<N>& a, const Pack<N>& b) {
  Pack<N> r;
  for (int n = 0; n < N; ++n) r.v[n] = m.v[n] ? a.v[n] : b.v[n];
  return r;
}
template <int N>
TETRIG_INLINE Pack<N> absolute(const Pack<N>& a) {
  Pack<N> r;
  for (int n = 0; n < N; ++n) r.v[n] = absolute(a.v[n]);
  return r;
}
template <int N>
TETRIG_INLINE Pack<N> squareRoot(const Pack<N>& a) {
  Pack<N> r;
  for (int n = 0; n < N; ++n) r.v[n] = squareRoot(a.v[n]);
  return r;
}
template <int N>
TETRIG_INLINE Pack<N> splatPack(double x) {
  Pack<N> r;
  for (int n = 0; n < N; ++n) r.v[n] = splat(x);
  return r;
}
// Lanes of one TetBlock field (`field(block)` points at its kTetBlockWidth doubles) across N blocks.
#define TETRIG_LOAD_FIELD(N, blocks, expr)                   \
  [&] {                                                      \
    Pack<N> r_;                                              \
    for (int n_ = 0; n_ < N; ++n_) {                         \
      const TetBlock& b = (blocks)[n_];                      \
      r_.v[n_] = load(expr);                                 \
    }                                                        \
    return r_;                                               \
  }()

template <int N>
struct Matrix {
  Pack<N> m[9];
};
// Rotation matrix (row-major m[3 * row + col]) of unit quaternions (w, x, y, z).
template <int N, class V = Pack<N>>
TETRIG_INLINE Matrix<N> quaternionToMatrix(V w, V x, V y, V z) {
  const V xx = x * x, yy = y * y, zz = z * z;
  const V xy = x * y, xz = x * z, yz = y * z, wx = w * x, wy = w * y, wz = w * z;
  return {{1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy),  //
           2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx),  //
           2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)}};
}

// delta_ck += a R grad phi_k (k = 0..2), delta_c3 -= their sum, with grad phi_k = row k of E^-1.
template <int N>
TETRIG_INLINE void scatterBlocks(const TetBlock* blocks, const Matrix<N>& r, double* delta) {
  using V = Pack<N>;
  const V a = TETRIG_LOAD_FIELD(N, blocks, b.weight);
  V m[4][3];  // m[k][row]: component `row` of a R grad phi_k; k = 3: minus their sum
  for (int k = 0; k < 3; ++k) {
    const V e0 = TETRIG_LOAD_FIELD(N, blocks, b.edge_inverse[3 * k]);
    const V e1 = TETRIG_LOAD_FIELD(N, blocks, b.edge_inverse[3 * k + 1]);
    const V e2 = TETRIG_LOAD_FIELD(N, blocks, b.edge_inverse[3 * k + 2]);
    for (int row = 0; row < 3; ++row) m[k][row] = a * (r.m[3 * row] * e0 + r.m[3 * row + 1] * e1 + r.m[3 * row + 2] * e2);
  }
  for (int row = 0; row < 3; ++row) m[3][row] = -(m[0][row] + m[1][row] + m[2][row]);
  for (int n = 0; n < N; ++n) {
    const TetBlock& block = blocks[n];
    for (int k = 0; k < 4; ++k) {
      Vec4 v[W];
      transposeOut(m[k][0].v[n], m[k][1].v[n], m[k][2].v[n], v);
      // One read-modify-write per corner; lanes are applied in order, so two lanes naming the
      // same vertex both land.
      for (int l = 0; l < W; ++l) {
        double* d = delta + block.corner_offset[k][l];
        store4(d, load4(d) + v[l]);
      }
    }
  }
}

template <int N>
TETRIG_INLINE void passBlocks(TetBlock* blocks, const double* xyz, double* delta, int steps, Pack<N>& energy,
                              std::uint8_t* exact_lanes, std::int64_t& flagged) {
  using V = Pack<N>;
  using M = PackMask<N>;
  // Edges x_ck - x_c3 (k = 0..2): corner positions (x, y, z, pad: one 4-wide load each)
  // transposed into lanes.
  V e[9];
  {
    Lanes ex[N][9];
    for (int n = 0; n < N; ++n) {
      Lanes px[4], py[4], pz[4];
      for (int k = 0; k < 4; ++k) {
        Vec4 v[W];
        for (int l = 0; l < W; ++l) v[l] = load4(xyz + blocks[n].corner_offset[k][l]);
        transposeIn(v, px[k], py[k], pz[k]);
      }
      for (int k = 0; k < 3; ++k) {
        ex[n][3 * k] = px[k] - px[3];
        ex[n][3 * k + 1] = py[k] - py[3];
        ex[n][3 * k + 2] = pz[k] - pz[3];
      }
    }
    for (int i = 0; i < 9; ++i)
      for (int n = 0; n < N; ++n) e[i].v[n] = ex[n][i];
  }
  // F = E' E^-1: F(row, col) = sum_k edge_k[row] Einv(k, col)   (eq. 2.6)
  Matrix<N> f;
  {
    V inv[9];
    for (int i = 0; i < 9; ++i) inv[i] = TETRIG_LOAD_FIELD(N, blocks, b.edge_inverse[i]);
    for (int row = 0; row < 3; ++row)
      for (int col = 0; col < 3; ++col)
        f.m[3 * row + col] = e[row] * inv[col] + e[3 + row] * inv[3 + col] + e[6 + row] * inv[6 + col];
  }
  const V det = f.m[0] * (f.m[4] * f.m[8] - f.m[5] * f.m[7]) - f.m[1] * (f.m[3] * f.m[8] - f.m[5] * f.m[6]) +
                f.m[2] * (f.m[3] * f.m[7] - f.m[4] * f.m[6]);
  V ff = f.m[0] * f.m[0];
  for (int i = 1; i < 9; ++i) ff += f.m[i] * f.m[i];
  // Horn's symmetric N(F): q^T N q = |q|^2 tr(R(q)^T F) for any quaternion q (polar.hpp).
  const V n00 = f.m[0] + f.m[4] + f.m[8], n11 = f.m[0] - f.m[4] - f.m[8];
  const V n22 = f.m[4] - f.m[0] - f.m[8], n33 = f.m[8] - f.m[0] - f.m[4];
  const V n01 = f.m[7] - f.m[5], n02 = f.m[2] - f.m[6], n03 = f.m[3] - f.m[1];
  const V n12 = f.m[1] + f.m[3], n13 = f.m[2] + f.m[6], n23 = f.m[5] + f.m[7];

  // Warm-started refinement of q towards argmax tr(R^T F) (Mueller et al. 2016). With g = N q,
  // the gradient of tr(R^T F) over rotation vectors is omega = (q_w g_v - g_w q_v + q_v x g_v) / |q|^2
  // (for unit q, sum_c r_c x f_c). The step rotates q by the half-angle vector
  // damping * omega / (|tr| + eps), i.e. q <- (|tr| + eps, damping * omega) q; multiplied through by
  // |q|^2 this is q <- (|q^T N q| + eps |q|^2, damping |q|^2 omega) q / |q|^2, whose division runs
  // beside the step instead of before it. q is normalised once, at the end. A step is kept only
  // if tr(R^T F) does not drop; a rejected step halves that lane's damping.
  V qw = TETRIG_LOAD_FIELD(N, blocks, b.rotation[0]);
  V qx = TETRIG_LOAD_FIELD(N, blocks, b.rotation[1]);
  V qy = TETRIG_LOAD_FIELD(N, blocks, b.rotation[2]);
  V qz = TETRIG_LOAD_FIELD(N, blocks, b.rotation[3]);
  V norm2 = qw * qw + qx * qx + qy * qy + qz * qz;  // 1 up to rounding
  V gw = n00 * qw + n01 * qx + n02 * qy + n03 * qz;
  V gx = n01 * qw + n11 * qx + n12 * qy + n13 * qz;
  V gy = n02 * qw + n12 * qx + n22 * qy + n23 * qz;
  V gz = n03 * qw + n13 * qx + n23 * qy + n33 * qz;
  V quad = qw * gw + qx * gx + qy * gy + qz * gz;  // |q|^2 tr(R^T F)
  V damping = splatPack<N>(0.5);  // 0.5: (1, omega / 2) is the half-angle form of a rotation by |omega|
  for (int s = 0; s < steps; ++s) {
    const V inv_norm2 = 1.0 / norm2;
    const V ox = damping * (qw * gx - gw * qx + qy * gz - qz * gy);
    const V oy = damping * (qw * gy - gw * qy + qz * gx - qx * gz);
    const V oz = damping * (qw * gz - gw * qz + qx * gy - qy * gx);
    const V dw = absolute(quad) + 1e-9 * norm2;
    const V w1 = (dw * qw - ox * qx - oy * qy - oz * qz) * inv_norm2;  // (dw, o) * q / |q|^2
    const V x1 = (dw * qx + ox * qw + oy * qz - oz * qy) * inv_norm2;
    const V y1 = (dw * qy + oy * qw + oz * qx - ox * qz) * inv_norm2;
    const V z1 = (dw * qz + oz * qw + ox * qy - oy * qx) * inv_norm2;
    const V gw1 = n00 * w1 + n01 * x1 + n02 * y1 + n03 * z1;
    const V gx1 = n01 * w1 + n11 * x1 + n12 * y1 + n13 * z1;
    const V gy1 = n02 * w1 + n12 * x1 + n22 * y1 + n23 * z1;
    const V gz1 = n03 * w1 + n13 * x1 + n23 * y1 + n33 * z1;
    const V quad1 = w1 * gw1 + x1 * gx1 + y1 * gy1 + z1 * gz1;
    const V norm21 = w1 * w1 + x1 * x1 + y1 * y1 + z1 * z1;
    const M accept = quad1 * norm2 >= quad * norm21;  // tr1 >= tr without dividing; false on NaN
    qw = select(accept, w1, qw);
    qx = select(accept, x1, qx);
    qy = select(accept, y1, qy);
    qz = select(accept, z1, qz);
    gw = select(accept, gw1, gw);
    gx = select(accept, gx1, gx);
    gy = select(accept, gy1, gy);
    gz = select(accept, gz1, gz);
    quad = select(accept, quad1, quad);
    norm2 = select(accept, norm21, norm2);
    damping = select(accept, damping, 0.5 * damping);
  }
  const V inv_norm = 1.0 / squareRoot(norm2);
  qw *= inv_norm;
  qx *= inv_norm;
  qy *= inv_norm;
  qz *= inv_norm;
  const V trace = quad * inv_norm * inv_norm;
  for (int n = 0; n < N; ++n) store(blocks[n].rotation[0], qw.v[n]);
  for (int n = 0; n < N; ++n) store(blocks[n].rotation[1], qx.v[n]);
  for (int n = 0; n < N; ++n) store(blocks[n].rotation[2], qy.v[n]);
  for (int n = 0; n < N; ++n) store(blocks[n].rotation[3], qz.v[n]);
  const Matrix<N> r = quaternionToMatrix<N>(qw, qx, qy, qz);

  // Inverted and degenerate tets (det F <= 1e-12) need the exact rotation: the local iteration can
  // stall there. They are rare (after large handle moves): only counted here, and fixed after
  // the pass (fixExactRotations), so this loop holds no call and keeps its values in registers.
  const V weight = TETRIG_LOAD_FIELD(N, blocks, b.weight);
  for (int n = 0; n < N; ++n) {
    const Mask needs_exact = (weight.v[n] > 0.0) & ~(det.v[n] > 1e-12);
    unsigned bits = 0;
    for (int l = 0; l < W; ++l) bits |= static_cast<unsigned>(needs_exact[l] & 1) << l;
    exact_lanes[n] = static_cast<std::uint8_t>(bits);
    flagged |= bits;
  }
  // Energy a (||F||^2 - 2 tr(R^T F) + 3).
  energy += weight * (ff - 2.0 * trace + 3.0);
  if (delta != nullptr) scatterBlocks<N>(blocks, r, delta);
}

// The exact rotation for every tet with det F <= 1e-12 after a pass that gave it the refined one:
// rotation replaced, delta corrected by a (R_exact - R_refined) grad phi_k, energy by
// -2 a (tr(R_exact^T F) - tr(R_refined^T F)). Scalar; runs only when the pass flagged a tet.
__attribute__((noinline, cold)) void fixExactRotations(TetBlock* blocks, std::int32_t block_count, const double* xyz,
                                                        double* delta, const std::uint8_t* exact_lanes,
                                                        RotationPassStats& stats) {
  for (std::int32_t b = 0; b < block_count; ++b) {
    if (exact_lanes[b] == 0) continue;
    TetBlock& block = blocks[b];
    for (int l = 0; l < W; ++l) {
      if (((exact_lanes[b] >> l) & 1) == 0) continue;
      Eigen::Matrix3d edges, inv;
      const double* p3 = xyz + block.corner_offset[3][l];
      for (int k = 0; k < 3; ++k) {
        const double* pk = xyz + block.corner_offset[k][l];
        for (int c = 0; c < 3; ++c) edges(c, k) = pk[c] - p3[c];
      }
      for (int i = 0; i < 9; ++i) inv(i / 3, i % 3) = block.edge_inverse[i][l];
      const Eigen::Matrix3d f = edges * inv;
      const Eigen::Quaterniond refined(block.rotation[0][l], block.rotation[1][l], block.rotation[2][l], block.rotation[3][l]);
      const Eigen::Quaterniond exact = closestRotation(f);
      block.rotation[0][l] = exact.w();
      block.rotation[1][l] = exact.x();
      block.rotation[2][l] = exact.y();
      block.rotation[3][l] = exact.z();
      const Eigen::Matrix3d change = exact.toRotationMatrix() - refined.toRotationMatrix();
      stats.energy -= 2.0 * block.weight[l] * (change.cwiseProduct(f)).sum();
      ++stats.exact_fallbacks;
      if (delta == nullptr) continue;
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector3d d = block.weight[l] * change * inv.row(k).transpose();
        double* out = delta + block.corner_offset[k][l];
        for (int c = 0; c < 3; ++c) out[c] += d[c];
        sum += d;
      }
      double* out = delta + block.corner_offset[3][l];
      for (int c = 0; c < 3; ++c) out[c] -= sum[c];
    }
  }
}

}  // namespace

TETRIG_MULTIVERSION
RotationPassStats rotationPass(TetBlock* blocks, std::int32_t block_count, const double* xyz, double* delta,
                               int steps, std::uint8_t* exact_lanes) {
  RotationPassStats stats;
  Pack<2> energy2 = splatPack<2>(0.0);
  Pack<1> energy1 = splatPack<1>(0.0);
  std::int64_t flagged = 0;
  std::int32_t b = 0;
  // Blocks beyond the L2 cache (128 bytes per tet) stream from memory: there, ask for the pair
  // after next now, so its lines arrive while this pair computes (measured 8-15 % on 27k tets;
  // on meshes that fit in L2 the prefetches only cost, ~3 % on 2.6k tets).
  if (static_cast<std::size_t>(block_count) * sizeof(TetBlock) > (512u << 10)) {
    for (; b + 6 <= block_count; b += 2) {
      const char* next = reinterpret_cast<const char*>(blocks + b + 4);
#pragma GCC unroll 32
      for (std::size_t line = 0; line < 2 * sizeof(TetBlock); line += 64) __builtin_prefetch(next + line);
      passBlocks<2>(blocks + b, xyz, delta, steps, energy2, exact_lanes + b, flagged);
    }
  }
  for (; b + 2 <= block_count; b += 2) passBlocks<2>(blocks + b, xyz, delta, steps, energy2, exact_lanes + b, flagged);
  for (; b < block_count; ++b) passBlocks<1>(blocks + b, xyz, delta, steps, energy1, exact_lanes + b, flagged);
  double total = 0.0;
  for (int l = 0; l < W; ++l) total += energy2.v[0][l] + energy2.v[1][l] + energy1.v[0][l];
  stats.energy = total;
  if (flagged != 0) fixExactRotations(blocks, block_count, xyz, delta, exact_lanes, stats);
  return stats;
}

const char* rotationKernelInstructionSet() {
#if defined(TETRIG_MULTIVERSION_ENABLED)
  // Same order as the target_clones resolver: the widest supported clone wins.
  if (__builtin_cpu_supports("x86-64-v4")) return "x86-64-v4 (AVX-512)";
  if (__builtin_cpu_supports("x86-64-v3")) return "x86-64-v3 (AVX2, FMA)";
  return "x86-64 baseline (SSE2)";
#elif defined(__aarch64__)
  return "aarch64 (NEON, portable build)";
#else
  return "portable build";
#endif
}

TETRIG_MULTIVERSION
void differentialPass(const TetBlock* blocks, std::int32_t block_count, double* delta) {
  for (std::int32_t b = 0; b < block_count; ++b) {
    const TetBlock& block = blocks[b];
    Pack<1> q[4];
    for (int c = 0; c < 4; ++c) q[c].v[0] = load(block.rotation[c]);
    scatterBlocks<1>(&block, quaternionToMatrix<1>(q[0], q[1], q[2], q[3]), delta);
  }
}

}  // namespace tetrig
