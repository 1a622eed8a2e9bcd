// Where a frame's iterations start: every tet's rotation carried forward by a prediction of this
// frame's rotation, before the frame's first solve (issue #12, docs/fidelity.md).
//
// A frame step ends with rotations R_n, the state the next frame starts from. The plain warm start
// begins the next frame at R_n. When the converged rotations move from frame to frame, a few
// iterations per frame never catch up: a slow mode of the iteration (contraction rho per iteration)
// lags about v / (1 - rho^k) behind a per-frame motion v at k iterations per frame, worst far from
// the markers. Starting from a prediction R' = D R_n of this frame's pose leaves the iterations
// only the prediction's error. Two predictions of D, per tet t:
//   temporal (the tet's own last rotation):   D_state = (R_n R_{n-1}^T)^alpha
//       (constant angular velocity; D^alpha: alpha times D's angle about its axis; alpha < 1 damps).
//       The steady lag then comes from the change of velocity, not the velocity.
//   from the markers (this frame's own motion): D_guides = sum_g w_tg I_g
//       I_g = Q_g(n) Q_g(n-1)^T, the rotation increment of guide g, a marker cluster's best-fit
//       rotation (the live rig computes Q_g by Kabsch from the measured markers), spread over the
//       tets by harmonic weights w_tg (a few per tet, precomputed; sum_g w_tg <= 1).
//   together:   D = normalize(sum_{g active} w_tg I_g + (1 - sum_{g active} w_tg) D_state)
//       (quaternions in the hemisphere of the identity; increments are small, so the linear blend
//       is close to the geodesic one). A guide is active in a frame when its markers were measured
//       in this frame and the last (otherwise its increment is unknown and its weight goes to
//       the temporal prediction).
// Per tet, in float, on the blocks' quaternions. `previous` holds R_{n-1} in the blocks' layout
// ([block][component][lane]) and receives R_n. No allocation, lock or exception; one thread.
#pragma once

#include "tetrig/rotation_kernel.hpp"

#include <cstdint>

namespace tetrig {

struct RotationPredictionInput {
  float* previous = nullptr;      // block_count * 4 * kTetBlockWidth floats: R_{n-1} in, R_n out; null: D_state = I
  float alpha = 1.0f;             // temporal damping in [0, 1]
  float max_sin_half = 1.0f;      // D_state's angle capped at 2 asin(max_sin_half) (1: no cap)
  // Guides: `guides_per_slot` entries per slot (slot-major), weight 0 on unused entries.
  std::int32_t guides_per_slot = 0;
  const std::int32_t* guide_index = nullptr;  // slot * guides_per_slot + j -> guide
  const float* guide_weight = nullptr;        // same layout
  const float* guide_increment = nullptr;     // 4 floats (w, x, y, z) per guide, hemisphere of the identity
  const std::uint8_t* guide_active = nullptr; // 1 per guide: its increment is known this frame
  // false: D = blend of the guide increments, the rest of the weight to D_state (above);
  // true: the guides' increments are changes of their per-frame rotation (I_g(n) I_g(n-1)^T, an
  // angular acceleration) and correct the temporal prediction: D = normalize(sum_g w_tg A_g +
  // (1 - sum_g w_tg) I) D_state.
  bool compose_with_temporal = false;
};

// R <- D R for every slot of `blocks` (D as above), and previous <- R (before the update).
void predictFrameRotations(TetBlock* blocks, std::int32_t block_count, const RotationPredictionInput& in);

}  // namespace tetrig
