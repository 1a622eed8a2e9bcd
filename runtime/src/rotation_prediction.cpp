// Temporal prediction of the warm start (rotation_prediction.hpp has the equations), 16 tets per
// vector; a damped prediction (alpha other than 0 or 1) scales each lane's angle with atan2/sin.
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

}  // namespace

TETRIG_MULTIVERSION
void predictFrameRotations(TetBlock* blocks, std::int32_t block_count, float* previous, const float* guide, float alpha,
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
    if (alpha == 0.0f) {  // no velocity: R' = G R, or R itself
      store(rotation, base);
      continue;
    }
    // D = R P^-1 (P^-1 = conj P), the velocity with the un-guided R, in the hemisphere of the
    // identity, its angle capped.
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
    if (alpha != 1.0f) {
      // D^alpha: alpha times D's half angle, lane by lane (atan2 and sin have no vector form here;
      // only damped predictions for measurements take this path).
      float w[W], x[W], y[W], z[W];
      storeF(w, d.w);
      storeF(x, d.x);
      storeF(y, d.y);
      storeF(z, d.z);
      for (int l = 0; l < W; ++l) {
        const float s = std::sqrt(x[l] * x[l] + y[l] * y[l] + z[l] * z[l]);
        if (s <= 1e-12f) continue;
        const float half = alpha * std::atan2(s, w[l]);
        const float f = std::sin(half) / s;
        w[l] = std::cos(half);
        x[l] *= f;
        y[l] *= f;
        z[l] *= f;
      }
      d = {loadF(w), loadF(x), loadF(y), loadF(z)};
    }
    store(rotation, normalised(product(d, base)));  // R' = D (G R)
  }
}

}  // namespace tetrig
