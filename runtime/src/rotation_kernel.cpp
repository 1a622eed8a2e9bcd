// Fused rotation extraction + differential-coordinate update (Stoll et al. 2007, 2.3.2), with
// the warm-started rotation iteration of Mueller et al. 2016. See rotation_kernel.hpp.
//
// Lanes: one `Lanes` value holds one quantity of the kTetBlockWidth (8) tets of a block, written
// with GCC/Clang vector extensions so every build (AVX-512, AVX2, SSE2, NEON) vectorises the same
// source. Corner positions move between per-vertex vectors (x, y, z, pad) and lanes by shuffles;
// scalar code remains only for the rare exact fallback.
#include "tetrig/rotation_kernel.hpp"

#include "tetrig/ldlt_factor.hpp"
#include "tetrig/polar.hpp"

#include <cmath>
#include <cstring>

#include "multiversion.hpp"

namespace tetrig {

namespace {

constexpr int W = kTetBlockWidth;
using Lanes = double __attribute__((vector_size(W * sizeof(double))));
using Mask = long long __attribute__((vector_size(W * sizeof(double))));
static_assert(sizeof(Lanes) == sizeof(double) * W);

inline Lanes load(const double* p) {
  Lanes v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
inline void store(double* p, Lanes v) { std::memcpy(p, &v, sizeof v); }
inline Lanes splat(double x) { return Lanes{} + x; }
inline Lanes select(Mask m, Lanes a, Lanes b) { return m ? a : b; }
inline Lanes absolute(Lanes x) { return select(x < 0.0, -x, x); }
inline Lanes squareRoot(Lanes x) {
  double lanes[W];
  store(lanes, x);
  for (double& v : lanes) v = __builtin_sqrt(v);  // -fno-math-errno: one vector sqrt
  return load(lanes);
}

// One vertex's x, y, z, pad (stride kVectorStride), and the 8-lane <-> 8 x 4 transposes between
// per-vertex vectors and per-coordinate lanes (shuffles instead of scalar loads and inserts).
using Vec4 = double __attribute__((vector_size(4 * sizeof(double))));
static_assert(W == 8 && kVectorStride == 4, "the transposes below are written for 8 lanes of 4");
inline Vec4 load4(const double* p) {
  Vec4 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
inline void store4(double* p, Vec4 v) { std::memcpy(p, &v, sizeof v); }
inline Lanes concat(Vec4 a, Vec4 b) { return __builtin_shufflevector(a, b, 0, 1, 2, 3, 4, 5, 6, 7); }

// v[l] = (x, y, z, pad) of lane l  ->  x, y, z as lanes.
inline void transposeIn(const Vec4 (&v)[W], Lanes& x, Lanes& y, Lanes& z) {
  const Lanes a = concat(v[0], v[1]), b = concat(v[2], v[3]), c = concat(v[4], v[5]), d = concat(v[6], v[7]);
  const Lanes ab_xy = __builtin_shufflevector(a, b, 0, 4, 8, 12, 1, 5, 9, 13);  // x0..x3 y0..y3
  const Lanes ab_z = __builtin_shufflevector(a, b, 2, 6, 10, 14, 3, 7, 11, 15);  // z0..z3 pad
  const Lanes cd_xy = __builtin_shufflevector(c, d, 0, 4, 8, 12, 1, 5, 9, 13);
  const Lanes cd_z = __builtin_shufflevector(c, d, 2, 6, 10, 14, 3, 7, 11, 15);
  x = __builtin_shufflevector(ab_xy, cd_xy, 0, 1, 2, 3, 8, 9, 10, 11);
  y = __builtin_shufflevector(ab_xy, cd_xy, 4, 5, 6, 7, 12, 13, 14, 15);
  z = __builtin_shufflevector(ab_z, cd_z, 0, 1, 2, 3, 8, 9, 10, 11);
}

// x, y, z lanes  ->  v[l] = (x_l, y_l, z_l, 0).
inline void transposeOut(Lanes x, Lanes y, Lanes z, Vec4 (&v)[W]) {
  const Lanes zero = splat(0.0);
  const Lanes xy_lo = __builtin_shufflevector(x, y, 0, 8, 1, 9, 2, 10, 3, 11);   // x0 y0 x1 y1 x2 y2 x3 y3
  const Lanes xy_hi = __builtin_shufflevector(x, y, 4, 12, 5, 13, 6, 14, 7, 15);
  const Lanes z0_lo = __builtin_shufflevector(z, zero, 0, 8, 1, 9, 2, 10, 3, 11);  // z0 0 z1 0 ...
  const Lanes z0_hi = __builtin_shufflevector(z, zero, 4, 12, 5, 13, 6, 14, 7, 15);
  const Lanes l01 = __builtin_shufflevector(xy_lo, z0_lo, 0, 1, 8, 9, 2, 3, 10, 11);  // lane 0, lane 1
  const Lanes l23 = __builtin_shufflevector(xy_lo, z0_lo, 4, 5, 12, 13, 6, 7, 14, 15);
  const Lanes l45 = __builtin_shufflevector(xy_hi, z0_hi, 0, 1, 8, 9, 2, 3, 10, 11);
  const Lanes l67 = __builtin_shufflevector(xy_hi, z0_hi, 4, 5, 12, 13, 6, 7, 14, 15);
  v[0] = __builtin_shufflevector(l01, l01, 0, 1, 2, 3);
  v[1] = __builtin_shufflevector(l01, l01, 4, 5, 6, 7);
  v[2] = __builtin_shufflevector(l23, l23, 0, 1, 2, 3);
  v[3] = __builtin_shufflevector(l23, l23, 4, 5, 6, 7);
  v[4] = __builtin_shufflevector(l45, l45, 0, 1, 2, 3);
  v[5] = __builtin_shufflevector(l45, l45, 4, 5, 6, 7);
  v[6] = __builtin_shufflevector(l67, l67, 0, 1, 2, 3);
  v[7] = __builtin_shufflevector(l67, l67, 4, 5, 6, 7);
}

// Rotation matrix (row-major r[3 * row + col]) of unit quaternions (w, x, y, z).
struct Matrix {
  Lanes m[9];
};
inline Matrix quaternionToMatrix(Lanes w, Lanes x, Lanes y, Lanes z) {
  const Lanes xx = x * x, yy = y * y, zz = z * z;
  const Lanes xy = x * y, xz = x * z, yz = y * z, wx = w * x, wy = w * y, wz = w * z;
  return {{1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy),  //
           2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx),  //
           2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)}};
}

// delta_ck += a R grad phi_k (k = 0..2), delta_c3 -= their sum, with grad phi_k = row k of E^-1.
inline void scatterBlock(const TetBlock& block, const Matrix& r, double* delta) {
  const Lanes a = load(block.weight);
  Lanes e[9];
  for (int i = 0; i < 9; ++i) e[i] = load(block.edge_inverse[i]);
  Lanes m[3][3];  // m[k][row]: component `row` of a R grad phi_k
  for (int k = 0; k < 3; ++k)
    for (int row = 0; row < 3; ++row)
      m[k][row] = a * (r.m[3 * row] * e[3 * k] + r.m[3 * row + 1] * e[3 * k + 1] + r.m[3 * row + 2] * e[3 * k + 2]);
  Vec4 v[W];
  for (int k = 0; k < 4; ++k) {
    if (k < 3) {
      transposeOut(m[k][0], m[k][1], m[k][2], v);
    } else {
      transposeOut(-(m[0][0] + m[1][0] + m[2][0]), -(m[0][1] + m[1][1] + m[2][1]), -(m[0][2] + m[1][2] + m[2][2]), v);
    }
    // One read-modify-write per corner; lanes are applied in order, so two lanes naming the same
    // vertex both land.
    for (int l = 0; l < W; ++l) {
      double* d = delta + kVectorStride * block.corner[k][l];
      store4(d, load4(d) + v[l]);
    }
  }
}

}  // namespace

TETRIG_MULTIVERSION
RotationPassStats rotationPass(TetBlock* blocks, std::int32_t block_count, const double* xyz, double* delta,
                               int steps) {
  RotationPassStats stats;
  Lanes energy = splat(0.0);
  for (std::int32_t b = 0; b < block_count; ++b) {
    TetBlock& block = blocks[b];
    // Corner positions (x, y, z, pad: one 4-wide load each), transposed into lanes.
    Lanes px[4], py[4], pz[4];
    for (int k = 0; k < 4; ++k) {
      Vec4 v[W];
      for (int l = 0; l < W; ++l) v[l] = load4(xyz + kVectorStride * block.corner[k][l]);
      transposeIn(v, px[k], py[k], pz[k]);
    }
    // F = E' E^-1: F(row, col) = sum_k edge_k[row] Einv(k, col)   (eq. 2.6)
    Matrix f;
    {
      Lanes e[9], inv[9];
      for (int k = 0; k < 3; ++k) {  // edges x_ck - x_c3
        e[3 * k] = px[k] - px[3];
        e[3 * k + 1] = py[k] - py[3];
        e[3 * k + 2] = pz[k] - pz[3];
      }
      for (int i = 0; i < 9; ++i) inv[i] = load(block.edge_inverse[i]);
      for (int row = 0; row < 3; ++row)
        for (int col = 0; col < 3; ++col)
          f.m[3 * row + col] = e[row] * inv[col] + e[3 + row] * inv[3 + col] + e[6 + row] * inv[6 + col];
    }
    const Lanes det = f.m[0] * (f.m[4] * f.m[8] - f.m[5] * f.m[7]) - f.m[1] * (f.m[3] * f.m[8] - f.m[5] * f.m[6]) +
                      f.m[2] * (f.m[3] * f.m[7] - f.m[4] * f.m[6]);
    Lanes ff = f.m[0] * f.m[0];
    for (int i = 1; i < 9; ++i) ff += f.m[i] * f.m[i];
    // Horn's symmetric N(F): q^T N q = |q|^2 tr(R(q)^T F) for any quaternion q (polar.hpp).
    const Lanes n00 = f.m[0] + f.m[4] + f.m[8], n11 = f.m[0] - f.m[4] - f.m[8];
    const Lanes n22 = f.m[4] - f.m[0] - f.m[8], n33 = f.m[8] - f.m[0] - f.m[4];
    const Lanes n01 = f.m[7] - f.m[5], n02 = f.m[2] - f.m[6], n03 = f.m[3] - f.m[1];
    const Lanes n12 = f.m[1] + f.m[3], n13 = f.m[2] + f.m[6], n23 = f.m[5] + f.m[7];

    // Warm-started refinement of q towards argmax tr(R^T F) (Mueller et al. 2016). With g = N q,
    // the gradient of tr(R^T F) over rotation vectors is omega = (q_w g_v - g_w q_v + q_v x g_v) / |q|^2
    // (for unit q, sum_c r_c x f_c). The step rotates q by the half-angle vector
    // damping * omega / (|tr| + eps), i.e. q <- (|tr| + eps, damping * omega) q, unnormalised:
    // q only needs normalising once, at the end. A step is kept only if tr(R^T F) does not drop;
    // a rejected step halves that lane's damping.
    Lanes qw = load(block.rotation[0]), qx = load(block.rotation[1]), qy = load(block.rotation[2]),
          qz = load(block.rotation[3]);
    Lanes norm2 = qw * qw + qx * qx + qy * qy + qz * qz;  // 1 up to rounding
    Lanes gw = n00 * qw + n01 * qx + n02 * qy + n03 * qz;
    Lanes gx = n01 * qw + n11 * qx + n12 * qy + n13 * qz;
    Lanes gy = n02 * qw + n12 * qx + n22 * qy + n23 * qz;
    Lanes gz = n03 * qw + n13 * qx + n23 * qy + n33 * qz;
    Lanes quad = qw * gw + qx * gx + qy * gy + qz * gz;  // |q|^2 tr(R^T F)
    Lanes damping = splat(0.5);  // 0.5: (1, omega / 2) is the half-angle form of a rotation by |omega|
    for (int s = 0; s < steps; ++s) {
      const Lanes inv_norm2 = 1.0 / norm2;
      const Lanes trace = quad * inv_norm2;
      const Lanes k = damping * inv_norm2;
      const Lanes ox = k * (qw * gx - gw * qx + qy * gz - qz * gy);
      const Lanes oy = k * (qw * gy - gw * qy + qz * gx - qx * gz);
      const Lanes oz = k * (qw * gz - gw * qz + qx * gy - qy * gx);
      const Lanes dw = absolute(trace) + 1e-9;
      const Lanes w1 = dw * qw - ox * qx - oy * qy - oz * qz;  // (dw, o) * q
      const Lanes x1 = dw * qx + ox * qw + oy * qz - oz * qy;
      const Lanes y1 = dw * qy + oy * qw + oz * qx - ox * qz;
      const Lanes z1 = dw * qz + oz * qw + ox * qy - oy * qx;
      const Lanes gw1 = n00 * w1 + n01 * x1 + n02 * y1 + n03 * z1;
      const Lanes gx1 = n01 * w1 + n11 * x1 + n12 * y1 + n13 * z1;
      const Lanes gy1 = n02 * w1 + n12 * x1 + n22 * y1 + n23 * z1;
      const Lanes gz1 = n03 * w1 + n13 * x1 + n23 * y1 + n33 * z1;
      const Lanes quad1 = w1 * gw1 + x1 * gx1 + y1 * gy1 + z1 * gz1;
      const Lanes norm21 = w1 * w1 + x1 * x1 + y1 * y1 + z1 * z1;
      const Mask accept = quad1 * norm2 >= quad * norm21;  // tr1 >= tr without dividing; false on NaN
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
    const Lanes inv_norm = 1.0 / squareRoot(norm2);
    qw *= inv_norm;
    qx *= inv_norm;
    qy *= inv_norm;
    qz *= inv_norm;
    Lanes trace = quad * inv_norm * inv_norm;
    store(block.rotation[0], qw);
    store(block.rotation[1], qx);
    store(block.rotation[2], qy);
    store(block.rotation[3], qz);
    Matrix r = quaternionToMatrix(qw, qx, qy, qz);

    // Inverted and degenerate tets take the exact rotation: the local iteration can stall there.
    const Mask needs_exact = (load(block.weight) > 0.0) & ~(det > 1e-12);
    long long any_exact = 0;
    for (int l = 0; l < W; ++l) any_exact |= needs_exact[l];
    for (int l = 0; any_exact != 0 && l < W; ++l) {
      if (!needs_exact[l]) continue;
      Eigen::Matrix3d fl;
      for (int i = 0; i < 9; ++i) fl(i / 3, i % 3) = f.m[i][l];
      const Eigen::Quaterniond q = closestRotation(fl);
      block.rotation[0][l] = q.w();
      block.rotation[1][l] = q.x();
      block.rotation[2][l] = q.y();
      block.rotation[3][l] = q.z();
      const Eigen::Matrix3d rl = q.toRotationMatrix();
      double t = 0.0;
      for (int i = 0; i < 9; ++i) {
        r.m[i][l] = rl(i / 3, i % 3);
        t += rl(i / 3, i % 3) * fl(i / 3, i % 3);
      }
      trace[l] = t;
      ++stats.exact_fallbacks;
    }
    // Energy a (||F||^2 - 2 tr(R^T F) + 3).
    energy += load(block.weight) * (ff - 2.0 * trace + 3.0);
    if (delta != nullptr) scatterBlock(block, r, delta);
  }
  double total = 0.0;
  for (int l = 0; l < W; ++l) total += energy[l];
  stats.energy = total;
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
    const Matrix r = quaternionToMatrix(load(block.rotation[0]), load(block.rotation[1]), load(block.rotation[2]),
                                        load(block.rotation[3]));
    scatterBlock(block, r, delta);
  }
}

}  // namespace tetrig
