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
// Per tet, in float, on the blocks' quaternions; `previous` holds R_{n-1} in the blocks' layout
// ([block][component][lane], 4 * kTetBlockWidth floats per block) and receives R_n.
// No allocation, lock or exception; one thread.
#pragma once

#include "tetrig/rotation_kernel.hpp"

#include <cstdint>

namespace tetrig {

void predictFrameRotations(TetBlock* blocks, std::int32_t block_count, float* previous, float alpha, float max_sin_half);

}  // namespace tetrig
