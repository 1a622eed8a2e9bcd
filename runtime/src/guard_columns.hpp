// One tet's 3x3 matrices as three columns of (x, y, z, 0) 4-lane vectors, the layout of the
// per-vertex displacements: the inversion guard's passes (inversion_guard.cpp) and the untangling
// (untangle.cpp) read F = I + H, R - I and G^T X in this form. Every product is one FMA of a column
// with a broadcast entry, and nothing goes through memory in between (Eigen's Matrix3d went
// through the stack there and reloaded 16 bytes across two 8-byte stores: a stalled store forward).
// Private to runtime/src; a file including it is compiled with -Wno-psabi (runtime/CMakeLists.txt).
#pragma once

#include "tetrig/deformer_impl.hpp"
#include "vector_lanes.hpp"

namespace tetrig::guard_columns {

using lanes::Vec4;
using lanes::load4;
using lanes::store4;

struct Columns {
  Vec4 c[3];
};

// The columns of H = [v_0 - v_3, v_1 - v_3, v_2 - v_3] E^-1 of the displacements v (solver order,
// stride 4; double, or float widened), pad lanes 0. F = I + H (the rest F is I).
template <typename T>
TETRIG_INLINE Columns gradientColumns(const GuardedTet& t, const T* v) {
  const Vec4 p3 = lanes::load4AsDouble(v + t.corner[3]);
  Vec4 e[3];
  for (size_t k = 0; k < 3; ++k) {
    e[k] = lanes::load4AsDouble(v + t.corner[k]) - p3;
    e[k][3] = 0.0;
  }
  Columns h;
  for (int j = 0; j < 3; ++j) h.c[j] = e[0] * t.einv(0, j) + e[1] * t.einv(1, j) + e[2] * t.einv(2, j);
  return h;
}

// The columns of R - I for slot s's stored rotation (the float quaternion q, normalized in double:
// R - I = s [[-(y^2+z^2), xy-wz, xz+wy], [xy+wz, -(x^2+z^2), yz-wx], [xz-wy, yz+wx, -(x^2+y^2)]],
// s = 2 / |q|^2).
TETRIG_INLINE Columns rotationMinusIdentity(const TetBlock* blocks, std::int32_t slot) {
  const TetBlock& block = blocks[slot / kTetBlockWidth];
  const int l = slot % kTetBlockWidth;
  const double w = block.rotation[0][l], x = block.rotation[1][l], y = block.rotation[2][l], z = block.rotation[3][l];
  const double s = 2.0 / (w * w + x * x + y * y + z * z);
  const double xx = x * x, yy = y * y, zz = z * z, xy = x * y, xz = x * z, yz = y * z, wx = w * x, wy = w * y, wz = w * z;
  Columns r;
  r.c[0] = Vec4{-(yy + zz), xy + wz, xz - wy, 0.0} * s;
  r.c[1] = Vec4{xy - wz, -(xx + zz), yz + wx, 0.0} * s;
  r.c[2] = Vec4{xz + wy, yz - wx, -(xx + yy), 0.0} * s;
  return r;
}

// det (I + H) = f_0 . (f_1 x f_2) for the columns f_j = e_j + h_j.
TETRIG_INLINE double determinantOfIdentityPlus(const Columns& h) {
  Vec4 f[3] = {h.c[0], h.c[1], h.c[2]};
  for (int j = 0; j < 3; ++j) f[j][j] += 1.0;
  return f[0][0] * (f[1][1] * f[2][2] - f[1][2] * f[2][1]) - f[0][1] * (f[1][0] * f[2][2] - f[1][2] * f[2][0]) +
         f[0][2] * (f[1][0] * f[2][1] - f[1][1] * f[2][0]);
}

// g = dF / dx of the tet's corner k (0..3): row k of E^-1 for k < 3, minus the sum of the rows for
// corner 3 (as a plain array: it multiplies columns entry by entry).
TETRIG_INLINE std::array<double, 3> cornerGradient(const GuardedTet& t, int k) {
  if (k < 3) return {t.einv(k, 0), t.einv(k, 1), t.einv(k, 2)};
  return {-(t.einv(0, 0) + t.einv(1, 0) + t.einv(2, 0)), -(t.einv(0, 1) + t.einv(1, 1) + t.einv(2, 1)),
          -(t.einv(0, 2) + t.einv(1, 2) + t.einv(2, 2))};
}

// out += G^T X for X given by its columns: corner k (0..2) takes column k of X E^-T, corner 3 minus
// their sum.
TETRIG_INLINE void scatterColumns(const GuardedTet& t, const Columns& x, double* out) {
  Vec4 sum{};
  for (size_t k = 0; k < 3; ++k) {
    const Vec4 m = x.c[0] * t.einv(static_cast<Eigen::Index>(k), 0) + x.c[1] * t.einv(static_cast<Eigen::Index>(k), 1) +
                   x.c[2] * t.einv(static_cast<Eigen::Index>(k), 2);
    double* ok = out + t.corner[k];
    store4(ok, load4(ok) + m);
    sum += m;
  }
  double* o3 = out + t.corner[3];
  store4(o3, load4(o3) - sum);
}

}  // namespace tetrig::guard_columns
