// Temporal prediction of the warm start (rotation_prediction.hpp has the equations).
//
// alpha = 0 or 1 (the live rig's settings) runs 16 tets per vector (a TetBlock's lanes); any other
// alpha (damped prediction, for measurements) runs the scalar loop with its atan2/sin.
#include "tetrig/rotation_prediction.hpp"

#include "multiversion.hpp"
#include "vector_lanes.hpp"

#include <cmath>
#include <cstddef>

namespace tetrig {

namespace {

using lanes::FLanes;
using lanes::FMask;
using lanes::loadF;
using lanes::storeF;
constexpr int W = kTetBlockWidth;

TETRIG_INLINE FLanes squareRoot(FLanes a) {
  float l[W];
  storeF(l, a);
  for (float& x : l) x = __builtin_sqrtf(x);  // -fno-math-errno: one vector sqrt
  return loadF(l);
}

// One block's 4 quaternion components.
struct Quat {
  FLanes w, x, y, z;
};
TETRIG_INLINE Quat load(const float* q) { return {loadF(q), loadF(q + W), loadF(q + 2 * W), loadF(q + 3 * W)}; }
TETRIG_INLINE void store(float* q, const Quat& v) {
  storeF(q, v.w);
  storeF(q + W, v.x);
  storeF(q + 2 * W, v.y);
  storeF(q + 3 * W, v.z);
}
TETRIG_INLINE Quat product(const Quat& a, const Quat& b) {  // a b
  return {a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z, a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
          a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x, a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w};
}
TETRIG_INLINE Quat normalised(const Quat& q) {
  const FLanes inv = 1.0f / squareRoot(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
  return {q.w * inv, q.x * inv, q.y * inv, q.z * inv};
}

// alpha = 1 (velocity) or 0 (guide only), 16 tets at a time.
TETRIG_MULTIVERSION
void predictLanes(TetBlock* blocks, std::int32_t block_count, float* previous, const float* guide, bool velocity,
                  float max_sin_half) {
  const float cap2 = max_sin_half * max_sin_half;
  const float cap_w = std::sqrt(1.0f - cap2);
  for (std::int32_t b = 0; b < block_count; ++b) {
    float* rotation = &blocks[b].rotation[0][0];
    float* p = previous + static_cast<std::size_t>(b) * 4 * W;
    const Quat r = load(rotation);
    const Quat before = load(p);  // P
    // The base the velocity is applied to, and the new P: G R, or R without a guide.
    const Quat base = guide != nullptr ? normalised(product(load(guide + static_cast<std::size_t>(b) * 4 * W), r)) : r;
    store(p, base);
    if (!velocity) {
      store(rotation, base);
      continue;
    }
    // D = R P^-1 (P^-1 = conj P), in the hemisphere of the identity, its angle capped.
    Quat d{r.w * before.w + r.x * before.x + r.y * before.y + r.z * before.z,
           -r.w * before.x + r.x * before.w - r.y * before.z + r.z * before.y,
           -r.w * before.y + r.x * before.z + r.y * before.w - r.z * before.x,
           -r.w * before.z - r.x * before.y + r.y * before.x + r.z * before.w};
    const FLanes sign = d.w < 0.0f ? FLanes{} - 1.0f : FLanes{} + 1.0f;
    d = {d.w * sign, d.x * sign, d.y * sign, d.z * sign};
    const FLanes s2 = d.x * d.x + d.y * d.y + d.z * d.z;  // sin^2 of half D's angle
    const FMask over = s2 > cap2;
    const FLanes k = over ? max_sin_half / squareRoot(over ? s2 : FLanes{} + 1.0f) : FLanes{} + 1.0f;
    d = {over ? FLanes{} + cap_w : d.w, d.x * k, d.y * k, d.z * k};
    store(rotation, normalised(product(d, base)));
  }
}

}  // namespace

void predictFrameRotations(TetBlock* blocks, std::int32_t block_count, float* previous, const float* guide, float alpha,
                           float max_sin_half) {
  if (alpha == 0.0f || alpha == 1.0f) {
    predictLanes(blocks, block_count, previous, guide, alpha == 1.0f, max_sin_half);
    return;
  }
  const float cap2 = max_sin_half * max_sin_half;
  const float cap_w = std::sqrt(1.0f - cap2);
  for (std::int32_t b = 0; b < block_count; ++b) {
    TetBlock& block = blocks[b];
    float* p = previous + static_cast<std::size_t>(b) * 4 * kTetBlockWidth;
    const float* g = guide != nullptr ? guide + static_cast<std::size_t>(b) * 4 * kTetBlockWidth : nullptr;
    for (int l = 0; l < kTetBlockWidth; ++l) {
      float rw = block.rotation[0][l], rx = block.rotation[1][l], ry = block.rotation[2][l], rz = block.rotation[3][l];
      const float pw = p[l], px = p[kTetBlockWidth + l], py = p[2 * kTetBlockWidth + l], pz = p[3 * kTetBlockWidth + l];
      if (g != nullptr) {
        // P <- G R, normalised: the guided start, against which the next frame takes its velocity.
        const float gw = g[l], gx = g[kTetBlockWidth + l], gy = g[2 * kTetBlockWidth + l], gz = g[3 * kTetBlockWidth + l];
        const float ow = gw * rw - gx * rx - gy * ry - gz * rz;
        const float ox = gw * rx + gx * rw + gy * rz - gz * ry;
        const float oy = gw * ry - gx * rz + gy * rw + gz * rx;
        const float oz = gw * rz + gx * ry - gy * rx + gz * rw;
        const float inv_g = 1.0f / std::sqrt(ow * ow + ox * ox + oy * oy + oz * oz);
        p[l] = ow * inv_g;
        p[kTetBlockWidth + l] = ox * inv_g;
        p[2 * kTetBlockWidth + l] = oy * inv_g;
        p[3 * kTetBlockWidth + l] = oz * inv_g;
      } else {
        p[l] = rw;
        p[kTetBlockWidth + l] = rx;
        p[2 * kTetBlockWidth + l] = ry;
        p[3 * kTetBlockWidth + l] = rz;
      }
      if (alpha == 0.0f) {
        // No velocity: R' = G R (= the new P), or R itself without a guide.
        block.rotation[0][l] = p[l];
        block.rotation[1][l] = p[kTetBlockWidth + l];
        block.rotation[2][l] = p[2 * kTetBlockWidth + l];
        block.rotation[3][l] = p[3 * kTetBlockWidth + l];
        continue;
      }
      // D = R P^-1, the velocity, with the un-guided R (unit quaternions: P^-1 = conj P), in the
      // hemisphere of the identity.
      float dw = rw * pw + rx * px + ry * py + rz * pz;
      float dx = -rw * px + rx * pw - ry * pz + rz * py;
      float dy = -rw * py + rx * pz + ry * pw - rz * px;
      float dz = -rw * pz - rx * py + ry * px + rz * pw;
      if (dw < 0.0f) {
        dw = -dw;
        dx = -dx;
        dy = -dy;
        dz = -dz;
      }
      const float s2 = dx * dx + dy * dy + dz * dz;  // sin^2 of half D's angle
      if (s2 > cap2) {
        const float k = max_sin_half / std::sqrt(s2);
        dw = cap_w;
        dx *= k;
        dy *= k;
        dz *= k;
      }
      if (alpha != 1.0f) {
        const float s = std::sqrt(dx * dx + dy * dy + dz * dz);
        if (s > 1e-12f) {
          const float half = alpha * std::atan2(s, dw);
          const float k = std::sin(half) / s;
          dw = std::cos(half);
          dx *= k;
          dy *= k;
          dz *= k;
        }
      }
      if (g != nullptr) {
        // Continue from the guided rotation: R' = W (G R).
        rw = p[l];
        rx = p[kTetBlockWidth + l];
        ry = p[2 * kTetBlockWidth + l];
        rz = p[3 * kTetBlockWidth + l];
      }
      // R' = D R, normalised.
      const float qw = dw * rw - dx * rx - dy * ry - dz * rz;
      const float qx = dw * rx + dx * rw + dy * rz - dz * ry;
      const float qy = dw * ry - dx * rz + dy * rw + dz * rx;
      const float qz = dw * rz + dx * ry - dy * rx + dz * rw;
      const float inv = 1.0f / std::sqrt(qw * qw + qx * qx + qy * qy + qz * qz);
      block.rotation[0][l] = qw * inv;
      block.rotation[1][l] = qx * inv;
      block.rotation[2][l] = qy * inv;
      block.rotation[3][l] = qz * inv;
    }
  }
}

}  // namespace tetrig
