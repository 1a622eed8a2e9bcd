// Temporal prediction of the warm start: where a frame's iterations begin (issue #12,
// docs/fidelity.md "Temporal prediction").
//
// A frame step ends with rotations R_n, the state the next frame starts from. The plain warm start
// begins the next frame at R_n. When the converged rotations move from frame to frame, a few
// iterations per frame never catch up: a slow mode of the iteration (contraction c = rho^k per
// frame at k iterations) settles v c / (1 - c) behind a steady per-frame motion v, worst far from
// the markers. Starting instead from every tet's rotation carried on by its own last rotation,
//     D  = (R_n R_{n-1}^T)^alpha      (D^alpha: alpha times D's angle about D's axis)
//     R' = D R_n,
// leaves the iterations only the change of velocity: the steady lag becomes a c / (1 - c) for a
// per-frame change of motion a (measured on HDM05 at 3 iterations: body RMS error to the converged
// pose, median 41 -> 6 mm). alpha < 1 damps the prediction. D's angle is capped at `max_angle`
// (given as sin(max_angle / 2)): a tet whose rotation jumped (e.g. through an inverted state) is
// not carried on by the jump.
// With a frame guide G (a per-tet rotation increment for this frame from outside, e.g. the coarse
// level's rotation change, tetrig/coarse_level.hpp), the velocity is taken beyond the guide the last
// frame had and the guide is composed in:
//     W  = (R_n P^-1)^alpha (capped as D above),   R' = W G R_n,   P <- G R_n,
// where P is what `previous` holds: G_{n-1} R_{n-1} (R_{n-1} when the last frame had no guide).
// Without a guide, G = I and this is the prediction above; alpha = 0 leaves R' = G R_n.
// Per tet, in float, on the blocks' quaternions; `previous` holds P in the blocks' layout
// ([block][component][lane], 4 * kTetBlockWidth floats per block) and receives the new P; `guide`
// (nullptr: none) holds G in the same layout. No allocation, lock or exception; one thread.
#pragma once

#include "tetrig/rotation_kernel.hpp"

#include <cstdint>

namespace tetrig {

void predictFrameRotations(TetBlock* blocks, std::int32_t block_count, float* previous, const float* guide, float alpha,
                           float max_sin_half);

}  // namespace tetrig
