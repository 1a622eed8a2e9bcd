// Temporal prediction of the warm start (rotation_prediction.hpp has the equations).
#include "tetrig/rotation_prediction.hpp"

#include <cmath>
#include <cstddef>

namespace tetrig {

void predictFrameRotations(TetBlock* blocks, std::int32_t block_count, float* previous, float alpha, float max_sin_half) {
  const float cap2 = max_sin_half * max_sin_half;
  const float cap_w = std::sqrt(1.0f - cap2);
  for (std::int32_t b = 0; b < block_count; ++b) {
    TetBlock& block = blocks[b];
    float* p = previous + static_cast<std::size_t>(b) * 4 * kTetBlockWidth;
    for (int l = 0; l < kTetBlockWidth; ++l) {
      const float rw = block.rotation[0][l], rx = block.rotation[1][l], ry = block.rotation[2][l], rz = block.rotation[3][l];
      const float pw = p[l], px = p[kTetBlockWidth + l], py = p[2 * kTetBlockWidth + l], pz = p[3 * kTetBlockWidth + l];
      p[l] = rw;
      p[kTetBlockWidth + l] = rx;
      p[2 * kTetBlockWidth + l] = ry;
      p[3 * kTetBlockWidth + l] = rz;
      // D = R P^-1 (unit quaternions: P^-1 = conj P), in the hemisphere of the identity.
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
