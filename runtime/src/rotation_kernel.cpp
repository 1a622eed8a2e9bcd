// Fused rotation extraction + differential-coordinate update (Stoll et al. 2007, 2.3.2), with
// the warm-started rotation iteration of Mueller et al. 2016, in displacement form and float
// lanes. See rotation_kernel.hpp.
//
// Lanes: one `FLanes` value holds one quantity of the kTetBlockWidth (16) tets of a block, in
// float, written with GCC/Clang vector extensions so every build (AVX-512, AVX2, SSE2, NEON)
// vectorises the same source. Displacements stay double: corner displacements are gathered and
// their edge differences taken in double (two halves of 8 lanes), then converted. The per-corner
// results are added into a float delta (x, y, z, pad per vertex: one 16-byte read-modify-write
// per corner; cheaper than a double delta, whose conversions and 8-lane transposes cost more
// shuffles). Scalar code remains only for the rare exact fallback, which
// runs after the pass.
//
// Why float: the pass streams 72 bytes per tet instead of 128, and each vector instruction
// serves 16 tets instead of 8 (the figures: docs/deformation.md). Why displacement form: rounding then scales with the deformation, so the
// rest state stays an exact fixed point.
#include "tetrig/rotation_kernel.hpp"

#include "tetrig/ldlt_factor.hpp"
#include "tetrig/polar.hpp"

#include <cmath>
#include <cstddef>
#include <cstring>

#include "multiversion.hpp"
#include "vector_lanes.hpp"

namespace tetrig {

namespace {

using namespace lanes;
constexpr int W = kTetBlockWidth;
constexpr int kHalf = kLanes;  // lanes per half block (one Lanes of doubles)

// Two consecutive blocks go through the pass together (Pack<2>: two registers per quantity on
// AVX-512): each long dependency chain (the divisions, the square root, the refinement steps)
// then has an independent twin in the same instruction stream for the out-of-order core to
// overlap. A last odd block goes alone (Pack<1>).
// Pack<N>: N FLanes (N consecutive blocks' 16 lanes each) with element-wise operators, each
// operator N vector instructions. (A 32-float vector type instead compiles to spills: GCC lowers
// oversized generic vectors through memory.)
template <int N>
struct Pack {
  FLanes v[N];
};
template <int N>
struct PackMask {
  FMask v[N];
};
#define TETRIG_PACK_OP(op)                                                                   \
  template <int N>                                                                           \
  TETRIG_INLINE Pack<N> operator op(const Pack<N>& a, const Pack<N>& b) {                     \
    Pack<N> r;                                                                               \
    for (int n = 0; n < N; ++n) r.v[n] = a.v[n] op b.v[n];                                   \
    return r;                                                                                \
  }                                                                                          \
  template <int N>                                                                           \
  TETRIG_INLINE Pack<N> operator op(float a, const Pack<N>& b) {                              \
    Pack<N> r;                                                                               \
    for (int n = 0; n < N; ++n) r.v[n] = a op b.v[n];                                        \
    return r;                                                                                \
  }                                                                                          \
  template <int N>                                                                           \
  TETRIG_INLINE Pack<N> operator op(const Pack<N>& a, float b) {                              \
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
TETRIG_INLINE PackMask<N> notAbove(const Pack<N>& a, float b) {  // !(a > b): true on NaN
  PackMask<N> r;
  for (int n = 0; n < N; ++n) r.v[n] = ~(a.v[n] > b);
  return r;
}
template <int N>
TETRIG_INLINE PackMask<N> notBelow(const Pack<N>& a, float b) {  // !(a < b): true on NaN
  PackMask<N> r;
  for (int n = 0; n < N; ++n) r.v[n] = ~(a.v[n] < b);
  return r;
}
template <int N>
TETRIG_INLINE PackMask<N> operator|(const PackMask<N>& a, const PackMask<N>& b) {
  PackMask<N> r;
  for (int n = 0; n < N; ++n) r.v[n] = a.v[n] | b.v[n];
  return r;
}
template <int N>
TETRIG_INLINE Pack<N> select(const PackMask<N>& m, const Pack<N>& a, const Pack<N>& b) {
  Pack<N> r;
  for (int n = 0; n < N; ++n) r.v[n] = m.v[n] ? a.v[n] : b.v[n];
  return r;
}
template <int N>
TETRIG_INLINE Pack<N> absolute(const Pack<N>& a) {  // clears the sign bit (compare-and-select compiles to scalar code)
  Pack<N> r;
  for (int n = 0; n < N; ++n) r.v[n] = reinterpret_cast<FLanes>(reinterpret_cast<FMask>(a.v[n]) & 0x7fffffff);
  return r;
}
template <int N>
TETRIG_INLINE Pack<N> squareRoot(const Pack<N>& a) {
  Pack<N> r;
  for (int n = 0; n < N; ++n) {
    float lanes[W];
    storeF(lanes, a.v[n]);
    for (float& x : lanes) x = __builtin_sqrtf(x);  // -fno-math-errno: one vector sqrt
    r.v[n] = loadF(lanes);
  }
  return r;
}
template <int N>
TETRIG_INLINE Pack<N> splat(float x) {
  Pack<N> r;
  for (int n = 0; n < N; ++n) r.v[n] = FLanes{} + x;
  return r;
}
// A float field of N consecutive blocks (`offset` bytes into a TetBlock), and its store.
template <int N>
TETRIG_INLINE Pack<N> loadField(const TetBlock* blocks, std::size_t offset) {
  Pack<N> r;
  for (int n = 0; n < N; ++n)
    r.v[n] = loadF(reinterpret_cast<const float*>(reinterpret_cast<const char*>(blocks + n) + offset));
  return r;
}
template <int N>
TETRIG_INLINE void storeField(TetBlock* blocks, std::size_t offset, const Pack<N>& p) {
  for (int n = 0; n < N; ++n) storeF(reinterpret_cast<float*>(reinterpret_cast<char*>(blocks + n) + offset), p.v[n]);
}
// Byte offset of row `row` of a TetBlock field (16 floats per row).
#define TETRIG_FIELD(member, row) (offsetof(TetBlock, member) + static_cast<std::size_t>(row) * sizeof(float) * W)

// R - I (row-major m[3 * row + col]) of unit quaternions (w, x, y, z). The diagonal is written
// without its 1, so small rotations keep their relative precision in float.
template <int N>
struct Matrix {
  Pack<N> m[9];
};
template <int N, class V = Pack<N>>
TETRIG_INLINE Matrix<N> rotationMinusIdentity(V w, V x, V y, V z) {
  const V xx = x * x, yy = y * y, zz = z * z;
  const V xy = x * y, xz = x * z, yz = y * z, wx = w * x, wy = w * y, wz = w * z;
  return {{-2.0f * (yy + zz), 2.0f * (xy - wz), 2.0f * (xz + wy),  //
           2.0f * (xy + wz), -2.0f * (xx + zz), 2.0f * (yz - wx),  //
           2.0f * (xz - wy), 2.0f * (yz + wx), -2.0f * (xx + yy)}};
}

// delta_ck += a (R - I) grad phi_k (k = 0..2), delta_c3 -= their sum, with grad phi_k = row k of E^-1.
template <int N>
TETRIG_INLINE void scatterBlocks(const TetBlock* blocks, const Matrix<N>& rm, float* delta) {
  using V = Pack<N>;
  const V a = loadField<N>(blocks, TETRIG_FIELD(weight, 0));
  V m[4][3];  // m[k][row]: component `row` of a (R - I) grad phi_k; k = 3: minus their sum
  for (int k = 0; k < 3; ++k) {
    const V e0 = loadField<N>(blocks, TETRIG_FIELD(edge_inverse, 3 * k));
    const V e1 = loadField<N>(blocks, TETRIG_FIELD(edge_inverse, 3 * k + 1));
    const V e2 = loadField<N>(blocks, TETRIG_FIELD(edge_inverse, 3 * k + 2));
    for (int row = 0; row < 3; ++row)
      m[k][row] = a * (rm.m[3 * row] * e0 + rm.m[3 * row + 1] * e1 + rm.m[3 * row + 2] * e2);
  }
  for (int row = 0; row < 3; ++row) m[3][row] = -(m[0][row] + m[1][row] + m[2][row]);
  for (int n = 0; n < N; ++n) {
    const TetBlock& block = blocks[n];
    for (int k = 0; k < 4; ++k) {
      Vec4f v[W];
      transposeOut16(m[k][0].v[n], m[k][1].v[n], m[k][2].v[n], v);
      // One read-modify-write per corner; lanes are applied in order, so two lanes naming the
      // same vertex both land.
      for (int l = 0; l < W; ++l) {
        float* d = delta + block.corner_offset[k][l];
        store4f(d, load4f(d) + v[l]);
      }
    }
  }
}

// H = E'_u E^-1 of N consecutive blocks (eq. 2.6): the edges u_ck - u_c3 (k = 0..2) in double per
// half block (corner displacements x, y, z, pad: one 4-wide load each, transposed into lanes), then
// H(row, col) = sum_k edge_k[row] Einv(k, col) in float.
template <int N>
TETRIG_INLINE void displacementGradient(const TetBlock* blocks, const double* u, Pack<N> (&h)[9]) {
  using V = Pack<N>;
  V e[9];
  for (int n = 0; n < N; ++n) {
    Lanes ex[2][9];
    for (int half = 0; half < 2; ++half) {
      Lanes px[4], py[4], pz[4];
      for (int k = 0; k < 4; ++k) {
        Vec4 v[kHalf];
        for (int l = 0; l < kHalf; ++l) v[l] = load4(u + blocks[n].corner_offset[k][kHalf * half + l]);
        transposeIn(v, px[k], py[k], pz[k]);
      }
      for (int k = 0; k < 3; ++k) {
        ex[half][3 * k] = px[k] - px[3];
        ex[half][3 * k + 1] = py[k] - py[3];
        ex[half][3 * k + 2] = pz[k] - pz[3];
      }
    }
    for (int i = 0; i < 9; ++i) e[i].v[n] = toFloat(ex[0][i], ex[1][i]);
  }
  V inv[9];
  for (int i = 0; i < 9; ++i) inv[i] = loadField<N>(blocks, TETRIG_FIELD(edge_inverse, i));
  for (int row = 0; row < 3; ++row)
    for (int col = 0; col < 3; ++col)
      h[3 * row + col] = e[row] * inv[col] + e[3 + row] * inv[3 + col] + e[6 + row] * inv[6 + col];
}

// The volume term (DeformerOptions::volume_weight; docs/deformation.md, "Volume term"). A tet's
// energy becomes a [(1 - w) ||F - R||^2 + w ||F - T||^2], where T is the volume-preserving
// target: F pushed along its own rotation until its determinant is 1,
//   T = F + s R,   det(F + s R) = det(R^T F + s I) = 1,
// the closest unit-determinant matrix to F when F's singular values are equal (U (Sigma + s I) V^T;
// to first order otherwise). With D = R^T (F - R) = R^T (H - (R - I)), t = tr D, c = the sum of
// D's principal 2x2 minors, d = det D, and g = 1 + s:
//   det(R^T F + s I) - 1 = s (3 + 3 s + s^2) + t g^2 + c g + d       (no cancellation near rest)
// whose root s is taken by three Newton steps from 0 (the function is increasing and convex for
// s > -sigma_min: after the first step Newton approaches the root from above), clamped to
// [-0.5, 0.5]; inverted and degenerate tets take none. The global step then targets
// M = (1 - w) R + w T, so the factor does not change:
//   M - I = (R - I) + w (F - R + s R),   energy a [(1 - w) ||F - R||^2 + 3 w s^2].
// `rm` holds R - I and `residual` ||F - R||^2 on entry; rm is replaced by M - I, residual by the
// tet's energy over a. Lanes with w = 0 keep both exactly.
template <int N>
TETRIG_INLINE void volumeBlend(const Pack<N> (&h)[9], Matrix<N>& rm, Pack<N> w, Pack<N>& residual) {
  using V = Pack<N>;
  V e[9];  // F - R = H - (R - I)
  for (int i = 0; i < 9; ++i) e[i] = h[i] - rm.m[i];
  V ee = e[0] * e[0];
  for (int i = 1; i < 9; ++i) ee += e[i] * e[i];
  V d[9];  // D = R^T E
  for (int row = 0; row < 3; ++row)
    for (int col = 0; col < 3; ++col)
      d[3 * row + col] = rm.m[row] * e[col] + rm.m[3 + row] * e[3 + col] + rm.m[6 + row] * e[6 + col] + e[3 * row + col];
  const V t = d[0] + d[4] + d[8];
  const V c = d[0] * d[4] - d[1] * d[3] + d[0] * d[8] - d[2] * d[6] + d[4] * d[8] - d[5] * d[7];
  const V det = d[0] * (d[4] * d[8] - d[5] * d[7]) - d[1] * (d[3] * d[8] - d[5] * d[6]) + d[2] * (d[3] * d[7] - d[4] * d[6]);
  // No volume term (w = 0) for inverted and degenerate tets (det F = 1 + t + c + d <= 1e-6: the
  // root is not near 0 there, and they take the exact rotation, fixExactRotations) and for F out of
  // float range (||F - R||^2 >= 1e12, inf or NaN). Those lanes, and lanes given w = 0, keep R - I
  // and the energy exactly: e is zeroed there, so a non-finite F cannot reach delta as 0 * inf.
  const PackMask<N> off = notAbove(w, 0.0f) | notBelow(ee, 1e12f) | notAbove(1.0f + t + c + det, 1e-6f);
  w = select(off, splat<N>(0.0f), w);
  for (int i = 0; i < 9; ++i) e[i] = select(off, splat<N>(0.0f), e[i]);
  V s = splat<N>(0.0f);
  for (int it = 0; it < 3; ++it) {
    const V g = 1.0f + s;
    const V f = s * (3.0f + s * (3.0f + s)) + t * g * g + c * g + det;
    const V slope = 3.0f * g * g + 2.0f * t * g + c;
    s = s - f / slope;
  }
  // Clamp to [-0.5, 0.5]; NaN (a zero slope) becomes 0: no volume push.
  s = select(notAbove(s, 0.5f), s, splat<N>(0.5f));
  s = select(notBelow(s, -0.5f), s, splat<N>(-0.5f));
  s = select(s >= splat<N>(-1.0f), s, splat<N>(0.0f));  // false on NaN
  residual = (1.0f - w) * residual + 3.0f * w * s * s;
  const V ws = w * s;
  for (int i = 0; i < 9; ++i) rm.m[i] = rm.m[i] + w * e[i] + ws * rm.m[i];
  for (int i = 0; i < 9; i += 4) rm.m[i] = rm.m[i] + ws;  // the diagonal: s R = s (R - I) + s I
}

// The inversion guard (DeformerOptions::inversion_guard; docs/deformation.md, "Inversion guard").
// A tet squashed below a volume ratio J = det F < tau takes extra stiffness alpha a on its
// rotation term, alpha = k min(1, (tau - J) / tau) (k at J <= 0), without a new factor: the extra
// term's pull is moved to the right-hand side with the current F,
//   M - I = (R - I) + alpha (R - F),
// so a fixed point minimises a (1 + alpha) ||F - R||^2 for those tets (a Jacobi-like splitting,
// stable for k < 1 per tet, and a tet shares its vertices with its neighbours). `rm` holds the
// target minus I on entry (R - I, or the volume term's M - I), `rot` R - I, `residual` the tet's
// energy over a; lanes with k = 0 or J >= tau keep both exactly.
template <int N>
TETRIG_INLINE void inversionGuard(const Pack<N> (&h)[9], const Matrix<N>& rot, Matrix<N>& rm, Pack<N> det,
                                  Pack<N> k, float tau, Pack<N>& residual) {
  using V = Pack<N>;
  V alpha = k * ((tau - det) * (1.0f / tau));
  const PackMask<N> off = notAbove(alpha, 0.0f);  // J >= tau, k = 0; NaN too
  alpha = select(off, splat<N>(0.0f), alpha);
  alpha = select(alpha >= k, k, alpha);
  V e[9];
  V ee = splat<N>(0.0f);
  for (int i = 0; i < 9; ++i) {
    e[i] = select(off, splat<N>(0.0f), rot.m[i] - h[i]);  // R - F (0 where off: no 0 * inf)
    ee += e[i] * e[i];
  }
  // The push alpha (R - F) is at most c = kInversionGuardPushCap (Frobenius): a tet far from any
  // rotation (a frame's first iteration after a jump) must not be kicked. Beyond the cap the extra
  // energy grows linearly (Huber): alpha x^2 up to x = c / alpha, then 2 c x - c^2 / alpha.
  constexpr float c = kInversionGuardPushCap;
  const V push2 = alpha * alpha * ee;
  const PackMask<N> below = notAbove(push2, c * c);
  const V x = squareRoot(ee);
  const V extra = select(below, alpha * ee, c * (2.0f * x - c / alpha));
  alpha = select(below, alpha, c / x);
  for (int i = 0; i < 9; ++i) rm.m[i] = rm.m[i] + alpha * e[i];
  residual = residual + extra;
}

// Lane l of a block -> bit l, by a vector AND and a tree of ORs (a per-lane loop compiles to
// scalar code).
TETRIG_INLINE unsigned laneBits(FMask m) {
  constexpr FMask kLaneBit = {1 << 0, 1 << 1, 1 << 2,  1 << 3,  1 << 4,  1 << 5,  1 << 6,  1 << 7,
                              1 << 8, 1 << 9, 1 << 10, 1 << 11, 1 << 12, 1 << 13, 1 << 14, 1 << 15};
  const FMask b16 = m & kLaneBit;
  using I8 = int __attribute__((vector_size(8 * sizeof(int))));
  using I4 = int __attribute__((vector_size(4 * sizeof(int))));
  const I8 b8 = __builtin_shufflevector(b16, b16, 0, 1, 2, 3, 4, 5, 6, 7) |
                __builtin_shufflevector(b16, b16, 8, 9, 10, 11, 12, 13, 14, 15);
  const I4 b4 = __builtin_shufflevector(b8, b8, 0, 1, 2, 3) | __builtin_shufflevector(b8, b8, 4, 5, 6, 7);
  return static_cast<unsigned>(b4[0] | b4[1] | b4[2] | b4[3]);
}

// The pass over N consecutive blocks. `energy` accumulates in double (two halves): a float sum
// over thousands of tets would lose the small terms.
template <int N, bool kRelax, bool kVolume>
TETRIG_INLINE void passBlocks(TetBlock* blocks, const double* u, float* delta, int steps, float relax,
                              const float* volume_weight, const float* guard, float guard_threshold,
                              Lanes (&energy)[2], std::uint16_t* exact_lanes, std::int64_t& flagged, float* det_out) {
  using V = Pack<N>;
  using M = PackMask<N>;
  V h[9];  // H = E'_u E^-1; F = I + H   (eq. 2.6)
  displacementGradient<N>(blocks, u, h);
  V f[9];
  for (int i = 0; i < 9; ++i) f[i] = (i % 4 == 0) ? h[i] + 1.0f : h[i];
  const V det = f[0] * (f[4] * f[8] - f[5] * f[7]) - f[1] * (f[3] * f[8] - f[5] * f[6]) +
                f[2] * (f[3] * f[7] - f[4] * f[6]);
  if (det_out != nullptr) {  // the implicit guard's input (inversion_guard.cpp)
    for (int n = 0; n < N; ++n) storeF(det_out + n * W, det.v[n]);
  }
  // Horn's symmetric N(F): q^T N q = |q|^2 tr(R(q)^T F) for any quaternion q (polar.hpp).
  const V n00 = f[0] + f[4] + f[8], n11 = f[0] - f[4] - f[8];
  const V n22 = f[4] - f[0] - f[8], n33 = f[8] - f[0] - f[4];
  const V n01 = f[7] - f[5], n02 = f[2] - f[6], n03 = f[3] - f[1];
  const V n12 = f[1] + f[3], n13 = f[2] + f[6], n23 = f[5] + f[7];

  // Warm-started refinement of q towards argmax tr(R^T F) (Mueller et al. 2016). With g = N q,
  // the gradient of tr(R^T F) over rotation vectors is omega = (q_w g_v - g_w q_v + q_v x g_v) / |q|^2
  // (for unit q, sum_c r_c x f_c). The step rotates q by the half-angle vector
  // damping * omega / (|tr| + eps), i.e. q <- (1, damping * omega / (|tr| + eps)) q; multiplied
  // through by |q|^2 this is q <- (dw, damping |q|^2 omega) q / dw with dw = |q^T N q| + eps |q|^2,
  // whose division runs beside the step instead of before it. |q| then grows only by
  // sqrt(1 + |step|^2) per step (dividing by |q|^2 instead, it grew by |tr| ~ 3 ||F|| per step and
  // float overflowed after ~40 steps even at rest). q is normalised once, at the end. A step is kept only
  // if tr(R^T F) does not drop by more than float rounding; a rejected step halves that lane's
  // damping. The rounding allowance matters: the trace is flat at its maximum (an angle error d
  // changes it by ~d^2), so an exact comparison in float would reject the last steps as noise
  // and stall at d ~ sqrt(float eps) ~ 3e-4. The steps themselves (omega) are accurate to ~1e-7.
  V qw = loadField<N>(blocks, TETRIG_FIELD(rotation, 0));
  V qx = loadField<N>(blocks, TETRIG_FIELD(rotation, 1));
  V qy = loadField<N>(blocks, TETRIG_FIELD(rotation, 2));
  V qz = loadField<N>(blocks, TETRIG_FIELD(rotation, 3));
  const V q0w = qw, q0x = qx, q0y = qy, q0z = qz;  // the rotation this pass started from (over-relaxation)
  V norm2 = qw * qw + qx * qx + qy * qy + qz * qz;  // 1 up to rounding
  V gw = n00 * qw + n01 * qx + n02 * qy + n03 * qz;
  V gx = n01 * qw + n11 * qx + n12 * qy + n13 * qz;
  V gy = n02 * qw + n12 * qx + n22 * qy + n23 * qz;
  V gz = n03 * qw + n13 * qx + n23 * qy + n33 * qz;
  V quad = qw * gw + qx * gx + qy * gy + qz * gz;  // |q|^2 tr(R^T F)
  V damping = splat<N>(0.5f);  // 0.5: (1, omega / 2) is the half-angle form of a rotation by |omega|
  // Rounding of |q|^2 tr(R^T F) is at most a few float eps times |N| |q|^2, |N| <= 2 ||F||
  // <= 1 + ||F||^2; 1e-6 is ~16 eps.
  V ff = f[0] * f[0];
  for (int i = 1; i < 9; ++i) ff += f[i] * f[i];
  const V allowance = 1e-6f * (1.0f + ff);
  for (int s = 0; s < steps; ++s) {
    const V ox = damping * (qw * gx - gw * qx + qy * gz - qz * gy);
    const V oy = damping * (qw * gy - gw * qy + qz * gx - qx * gz);
    const V oz = damping * (qw * gz - gw * qz + qx * gy - qy * gx);
    const V dw = absolute(quad) + 1e-9f * norm2;
    const V inv_dw = 1.0f / dw;
    const V w1 = (dw * qw - ox * qx - oy * qy - oz * qz) * inv_dw;  // (dw, o) * q / dw
    const V x1 = (dw * qx + ox * qw + oy * qz - oz * qy) * inv_dw;
    const V y1 = (dw * qy + oy * qw + oz * qx - ox * qz) * inv_dw;
    const V z1 = (dw * qz + oz * qw + ox * qy - oy * qx) * inv_dw;
    const V gw1 = n00 * w1 + n01 * x1 + n02 * y1 + n03 * z1;
    const V gx1 = n01 * w1 + n11 * x1 + n12 * y1 + n13 * z1;
    const V gy1 = n02 * w1 + n12 * x1 + n22 * y1 + n23 * z1;
    const V gz1 = n03 * w1 + n13 * x1 + n23 * y1 + n33 * z1;
    const V quad1 = w1 * gw1 + x1 * gx1 + y1 * gy1 + z1 * gz1;
    const V norm21 = w1 * w1 + x1 * x1 + y1 * y1 + z1 * z1;
    // tr1 >= tr - allowance, without dividing; false on NaN.
    const M accept = quad1 * norm2 >= (quad - allowance * norm2) * norm21;
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
    damping = select(accept, damping, 0.5f * damping);
  }
  const V inv_norm = 1.0f / squareRoot(norm2);
  qw *= inv_norm;
  qx *= inv_norm;
  qy *= inv_norm;
  qz *= inv_norm;
  // Inverted and degenerate tets (det F <= 1e-12) need the exact rotation: the local iteration can
  // stall there. So do lanes whose float arithmetic left the range (F beyond ~1e12, where the
  // products of the step overflow): their q is not a unit quaternion (or NaN); it is reset to the
  // identity here so nothing non-finite reaches delta. Both are rare: only flagged here, and fixed
  // after the pass (fixExactRotations, in double), so this loop holds no call and keeps its values
  // in registers. (Padding lanes have F = I, det 1: never flagged.)
  const M out_of_range = notBelow(absolute(qw * qw + qx * qx + qy * qy + qz * qz - 1.0f), 1e-3f);
  const M needs_exact = notAbove(det, 1e-12f) | out_of_range;  // NaN too
  if constexpr (kRelax) {
    // Over-relaxation (rotation_relaxation.hpp): q <- D^relax q with D = q q0^-1, the change this pass made,
    // taken in the hemisphere of the identity; D^relax scales D's half-angle tangent by relax.
    V dw = qw * q0w + qx * q0x + qy * q0y + qz * q0z;
    const V sign = select(dw >= splat<N>(0.0f), splat<N>(1.0f), splat<N>(-1.0f));
    dw = dw * sign;
    const V k = relax * sign;
    const V dx = k * (-qw * q0x + qx * q0w - qy * q0z + qz * q0y);
    const V dy = k * (-qw * q0y + qx * q0z + qy * q0w - qz * q0x);
    const V dz = k * (-qw * q0z - qx * q0y + qy * q0x + qz * q0w);
    const V rw = dw * qw - dx * qx - dy * qy - dz * qz;
    const V rx = dw * qx + dx * qw + dy * qz - dz * qy;
    const V ry = dw * qy - dx * qz + dy * qw + dz * qx;
    const V rz = dw * qz + dx * qy - dy * qx + dz * qw;
    const V inv_r = 1.0f / squareRoot(rw * rw + rx * rx + ry * ry + rz * rz);
    qw = rw * inv_r;
    qx = rx * inv_r;
    qy = ry * inv_r;
    qz = rz * inv_r;
  }
  qw = select(out_of_range, splat<N>(1.0f), qw);
  qx = select(out_of_range, splat<N>(0.0f), qx);
  qy = select(out_of_range, splat<N>(0.0f), qy);
  qz = select(out_of_range, splat<N>(0.0f), qz);
  storeField<N>(blocks, TETRIG_FIELD(rotation, 0), qw);
  storeField<N>(blocks, TETRIG_FIELD(rotation, 1), qx);
  storeField<N>(blocks, TETRIG_FIELD(rotation, 2), qy);
  storeField<N>(blocks, TETRIG_FIELD(rotation, 3), qz);
  const Matrix<N> rm = rotationMinusIdentity<N>(qw, qx, qy, qz);

  for (int n = 0; n < N; ++n) {
    const unsigned bits = laneBits(needs_exact.v[n]);
    exact_lanes[n] = static_cast<std::uint16_t>(bits);
    flagged |= bits;
  }
  // Energy a ||H - (R - I)||^2: no cancellation near rest, where both terms are small. Flagged
  // lanes add theirs in fixExactRotations.
  V residual = (h[0] - rm.m[0]) * (h[0] - rm.m[0]);
  for (int i = 1; i < 9; ++i) residual += (h[i] - rm.m[i]) * (h[i] - rm.m[i]);
  Matrix<N> target = rm;  // M - I: R - I, or blended with the volume target
  if constexpr (kVolume) {
    Pack<N> w;
    for (int n = 0; n < N; ++n) w.v[n] = loadF(volume_weight + n * W);
    w = select(needs_exact, splat<N>(0.0f), w);  // flagged lanes: the exact rotation alone
    volumeBlend<N>(h, target, w, residual);
  }
  if (guard != nullptr) {
    Pack<N> k;
    for (int n = 0; n < N; ++n) k.v[n] = loadF(guard + n * W);
    k = select(needs_exact, splat<N>(0.0f), k);  // flagged lanes: fixExactRotations adds theirs
    inversionGuard<N>(h, rm, target, det, k, guard_threshold, residual);
  }
  const V tet_energy = select(needs_exact, splat<N>(0.0f), loadField<N>(blocks, TETRIG_FIELD(weight, 0)) * residual);
  for (int n = 0; n < N; ++n) {
    energy[0] += lowHalf(tet_energy.v[n]);
    energy[1] += highHalf(tet_energy.v[n]);
  }
  if (delta != nullptr) scatterBlocks<N>(blocks, target, delta);
}


// The exact rotation for every tet the pass flagged (det F <= 1e-12, or out of float range) after
// the pass gave it the refined one: rotation replaced, delta corrected by
// a (R_exact - R_refined) grad phi_k, the tet's energy added. Scalar, in double; runs only when
// the pass flagged a tet.
__attribute__((noinline, cold)) void fixExactRotations(TetBlock* blocks, std::int32_t block_count, const double* u,
                                                        float* delta, const std::uint16_t* exact_lanes,
                                                        const float* guard, float guard_threshold,
                                                        RotationPassStats& stats) {
  for (std::int32_t b = 0; b < block_count; ++b) {
    if (exact_lanes[b] == 0) continue;
    TetBlock& block = blocks[b];
    for (int l = 0; l < W; ++l) {
      if (((exact_lanes[b] >> l) & 1) == 0) continue;
      Eigen::Matrix3d edges, inv;
      const double* p3 = u + block.corner_offset[3][l];
      for (int k = 0; k < 3; ++k) {
        const double* pk = u + block.corner_offset[k][l];
        for (int c = 0; c < 3; ++c) edges(c, k) = pk[c] - p3[c];
      }
      for (int i = 0; i < 9; ++i) inv(i / 3, i % 3) = block.edge_inverse[i][l];
      const Eigen::Matrix3d f = Eigen::Matrix3d::Identity() + edges * inv;
      const Eigen::Quaterniond refined(block.rotation[0][l], block.rotation[1][l], block.rotation[2][l],
                                       block.rotation[3][l]);
      const Eigen::Quaterniond exact = closestRotation(f);
      block.rotation[0][l] = static_cast<float>(exact.w());
      block.rotation[1][l] = static_cast<float>(exact.x());
      block.rotation[2][l] = static_cast<float>(exact.y());
      block.rotation[3][l] = static_cast<float>(exact.z());
      // The stored (rounded) rotation is the one later passes see: correct with that one.
      const Eigen::Quaterniond stored(block.rotation[0][l], block.rotation[1][l], block.rotation[2][l],
                                      block.rotation[3][l]);
      const Eigen::Matrix3d r_refined = refined.normalized().toRotationMatrix();
      const Eigen::Matrix3d r_stored = stored.normalized().toRotationMatrix();
      const double a = block.weight[l];
      const double off = (r_stored - f).norm();
      const InversionGuardTerm g =
          guard != nullptr ? inversionGuardTerm(guard[static_cast<std::size_t>(b) * W + static_cast<std::size_t>(l)],
                                                guard_threshold, f.determinant(), off)
                           : InversionGuardTerm{};
      stats.energy += a * (off * off + g.extra);
      ++stats.exact_fallbacks;
      if (delta == nullptr) continue;
      const Eigen::Matrix3d change = r_stored - r_refined + g.alpha * (r_stored - f);
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector3d d = a * change * inv.row(k).transpose();
        float* out = delta + block.corner_offset[k][l];
        for (int c = 0; c < 3; ++c) out[c] += static_cast<float>(d[c]);
        sum += d;
      }
      float* out = delta + block.corner_offset[3][l];
      for (int c = 0; c < 3; ++c) out[c] -= static_cast<float>(sum[c]);
    }
  }
}

// passBlocks, with the volume term only when some lane of these N blocks has a weight: a rig's
// volume regions leave most blocks without, and those take the plain pass (the same result as
// w = 0, for less work).
template <int N, bool kRelax, bool kVolume>
TETRIG_INLINE void passBlocksWeighted(TetBlock* blocks, const double* u, float* delta, int steps, float relax,
                                      const float* volume_weight, const float* guard, float guard_threshold, Lanes (&energy)[2],
                                      std::uint16_t* exact_lanes, std::int64_t& flagged, float* det_out) {
  bool any = false;
  if constexpr (kVolume) {
    for (int i = 0; i < N * W; ++i) any |= volume_weight[i] != 0.0f;
  }
  if (any) {
    passBlocks<N, kRelax, true>(blocks, u, delta, steps, relax, volume_weight, guard, guard_threshold, energy, exact_lanes, flagged,
                                det_out);
  } else {
    passBlocks<N, kRelax, false>(blocks, u, delta, steps, relax, nullptr, guard, guard_threshold, energy, exact_lanes, flagged,
                                 det_out);
  }
}

// The pass over all blocks (kRelax: with over-relaxation; kVolume: with the volume term, on the
// blocks that have a weight).
template <bool kRelax, bool kVolume>
TETRIG_INLINE void passAll(TetBlock* blocks, std::int32_t block_count, const double* u, float* delta, int steps, float relax,
                           const float* volume_weight, const float* guard, float guard_threshold,
                           std::uint16_t* exact_lanes, RotationPassStats& stats, float* det_out) {
  Lanes energy[2] = {};
  std::int64_t flagged = 0;
  std::int32_t b = 0;
  auto weights = [&](std::int32_t block) { return kVolume ? volume_weight + static_cast<std::size_t>(block) * W : nullptr; };
  auto guards = [&](std::int32_t block) { return guard != nullptr ? guard + static_cast<std::size_t>(block) * W : nullptr; };
  auto dets = [&](std::int32_t block) { return det_out != nullptr ? det_out + static_cast<std::size_t>(block) * W : nullptr; };
  // Blocks beyond the L2 cache stream from memory: there, ask for the block after next now, so
  // its lines arrive while this one computes (on meshes that fit in L2 the prefetches only cost).
  if (static_cast<std::size_t>(block_count) * sizeof(TetBlock) > (512u << 10)) {
    for (; b + 4 <= block_count; b += 2) {
      const char* next = reinterpret_cast<const char*>(blocks + b + 2);
#pragma GCC unroll 64
      for (std::size_t line = 0; line < 2 * sizeof(TetBlock); line += 64) __builtin_prefetch(next + line);
      passBlocksWeighted<2, kRelax, kVolume>(blocks + b, u, delta, steps, relax, weights(b), guards(b), guard_threshold, energy,
                                             exact_lanes + b, flagged, dets(b));
    }
  }
  for (; b + 2 <= block_count; b += 2)
    passBlocksWeighted<2, kRelax, kVolume>(blocks + b, u, delta, steps, relax, weights(b), guards(b), guard_threshold, energy,
                                           exact_lanes + b, flagged, dets(b));
  for (; b < block_count; ++b)
    passBlocksWeighted<1, kRelax, kVolume>(blocks + b, u, delta, steps, relax, weights(b), guards(b), guard_threshold, energy,
                                           exact_lanes + b, flagged, dets(b));
  double total = 0.0;
  for (int l = 0; l < kHalf; ++l) total += energy[0][l] + energy[1][l];
  stats.energy = total;
  if (flagged != 0) fixExactRotations(blocks, block_count, u, delta, exact_lanes, guard, guard_threshold, stats);
}


}  // namespace

TETRIG_MULTIVERSION
RotationPassStats rotationPass(TetBlock* blocks, std::int32_t block_count, const double* u, float* delta,
                               int steps, std::uint16_t* exact_lanes, float relax, const float* volume_weight,
                               const float* guard, float guard_threshold, float* det_out) {
  RotationPassStats stats;
  const bool relaxed = relax != 0.0f;
  const float* vw = volume_weight;
  const float* g = guard;
  const float gt = guard_threshold;
  if (volume_weight != nullptr) {
    if (relaxed) passAll<true, true>(blocks, block_count, u, delta, steps, relax, vw, g, gt, exact_lanes, stats, det_out);
    else passAll<false, true>(blocks, block_count, u, delta, steps, relax, vw, g, gt, exact_lanes, stats, det_out);
  } else {
    if (relaxed) passAll<true, false>(blocks, block_count, u, delta, steps, relax, nullptr, g, gt, exact_lanes, stats, det_out);
    else passAll<false, false>(blocks, block_count, u, delta, steps, relax, nullptr, g, gt, exact_lanes, stats, det_out);
  }
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
void differentialPass(const TetBlock* blocks, std::int32_t block_count, float* delta, const double* u,
                      const float* volume_weight, const float* guard, float guard_threshold) {
  for (std::int32_t b = 0; b < block_count; ++b) {
    const TetBlock& block = blocks[b];
    Matrix<1> rm = rotationMinusIdentity<1>(loadField<1>(&block, TETRIG_FIELD(rotation, 0)),
                                            loadField<1>(&block, TETRIG_FIELD(rotation, 1)),
                                            loadField<1>(&block, TETRIG_FIELD(rotation, 2)),
                                            loadField<1>(&block, TETRIG_FIELD(rotation, 3)));
    Matrix<1> target = rm;
    if (volume_weight != nullptr || guard != nullptr) {
      Pack<1> h[9];
      displacementGradient<1>(&block, u, h);
      Pack<1> residual = splat<1>(0.0f);  // unused: no energy here
      if (volume_weight != nullptr) {
        Pack<1> w;
        w.v[0] = loadF(volume_weight + static_cast<std::size_t>(b) * W);
        volumeBlend<1>(h, target, w, residual);
      }
      if (guard != nullptr) {
        // Inverted tets too: the stored rotation is the exact one there (no fallback in this pass).
        Pack<1> f[9];
        for (int i = 0; i < 9; ++i) f[i] = (i % 4 == 0) ? h[i] + 1.0f : h[i];
        const Pack<1> det = f[0] * (f[4] * f[8] - f[5] * f[7]) - f[1] * (f[3] * f[8] - f[5] * f[6]) +
                            f[2] * (f[3] * f[7] - f[4] * f[6]);
        Pack<1> k;
        k.v[0] = loadF(guard + static_cast<std::size_t>(b) * W);
        inversionGuard<1>(h, rm, target, det, k, guard_threshold, residual);
      }
    }
    scatterBlocks<1>(&block, target, delta);
  }
}

}  // namespace tetrig
