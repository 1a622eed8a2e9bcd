// The frame-start rotation prediction (rotation_prediction.hpp has the equations).
#include "tetrig/rotation_prediction.hpp"

#include <cmath>
#include <cstddef>

namespace tetrig {

namespace {

struct Quat {
  float w, x, y, z;
};

// a * b
inline Quat mul(const Quat& a, const Quat& b) {
  return {a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z, a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
          a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x, a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w};
}

// (q p^-1)^alpha for unit q, p, in the hemisphere of the identity.
inline Quat temporalIncrement(const Quat& q, const Quat& p, float alpha, float max_sin_half) {
  Quat d = mul(q, Quat{p.w, -p.x, -p.y, -p.z});
  if (d.w < 0.0f) d = {-d.w, -d.x, -d.y, -d.z};
  const float s2 = d.x * d.x + d.y * d.y + d.z * d.z;
  if (s2 > max_sin_half * max_sin_half) {
    // Faster than any body part turns between two frames (a tet whose rotation jumped, e.g. while
    // inverted): carry it by the cap instead.
    const float k = max_sin_half / std::sqrt(s2);
    d = {std::sqrt(1.0f - max_sin_half * max_sin_half), d.x * k, d.y * k, d.z * k};
  }
  if (alpha == 1.0f) return d;
  const float s = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
  if (s <= 1e-12f) return {1.0f, 0.0f, 0.0f, 0.0f};
  const float half = alpha * std::atan2(s, d.w);
  const float k = std::sin(half) / s;
  return {std::cos(half), d.x * k, d.y * k, d.z * k};
}

}  // namespace

void predictFrameRotations(TetBlock* blocks, std::int32_t block_count, const RotationPredictionInput& in) {
  const std::int32_t per_slot = in.guides_per_slot;
  for (std::int32_t b = 0; b < block_count; ++b) {
    TetBlock& block = blocks[b];
    float* p = in.previous != nullptr ? in.previous + static_cast<std::size_t>(b) * 4 * kTetBlockWidth : nullptr;
    for (int l = 0; l < kTetBlockWidth; ++l) {
      const Quat r{block.rotation[0][l], block.rotation[1][l], block.rotation[2][l], block.rotation[3][l]};
      Quat d{1.0f, 0.0f, 0.0f, 0.0f};
      if (p != nullptr) {
        d = temporalIncrement(r, Quat{p[l], p[kTetBlockWidth + l], p[2 * kTetBlockWidth + l], p[3 * kTetBlockWidth + l]},
                              in.alpha, in.max_sin_half);
        p[l] = r.w;
        p[kTetBlockWidth + l] = r.x;
        p[2 * kTetBlockWidth + l] = r.y;
        p[3 * kTetBlockWidth + l] = r.z;
      }
      if (per_slot > 0) {
        const std::size_t slot = static_cast<std::size_t>(b) * kTetBlockWidth + static_cast<std::size_t>(l);
        Quat sum{0.0f, 0.0f, 0.0f, 0.0f};
        float covered = 0.0f;
        for (std::int32_t j = 0; j < per_slot; ++j) {
          const std::size_t e = slot * static_cast<std::size_t>(per_slot) + static_cast<std::size_t>(j);
          const std::int32_t g = in.guide_index[e];
          if (in.guide_active[g] == 0) continue;
          const float w = in.guide_weight[e];
          const float* inc = in.guide_increment + 4 * static_cast<std::size_t>(g);
          sum.w += w * inc[0];
          sum.x += w * inc[1];
          sum.y += w * inc[2];
          sum.z += w * inc[3];
          covered += w;
        }
        const float rest = 1.0f - covered;
        if (in.compose_with_temporal) {
          d = mul(Quat{sum.w + rest, sum.x, sum.y, sum.z}, d);
        } else {
          d = {sum.w + rest * d.w, sum.x + rest * d.x, sum.y + rest * d.y, sum.z + rest * d.z};
        }
      }
      Quat q = mul(d, r);
      const float inv = 1.0f / std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
      block.rotation[0][l] = q.w * inv;
      block.rotation[1][l] = q.x * inv;
      block.rotation[2][l] = q.y * inv;
      block.rotation[3][l] = q.z * inv;
    }
  }
}

}  // namespace tetrig
