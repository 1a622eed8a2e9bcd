// Harmonic interpolation of relative handle rotations (Stoll et al. 2007, section 2.3.2, after
// Zayer et al. 2005, "Harmonic guidance for surface deformation").
//
// At load, each oriented handle h gets a harmonic scalar field w_h over the tets (the dual graph:
// tets sharing a face are neighbours, uniform weights): w_h = 1 on h's tets, 0 on the other
// oriented handles' tets and on tets touching a non-oriented constraint, harmonic elsewhere.
// Harmonic interpolation of per-handle quaternions q_h is then sum_h w_h q_h (+ the remainder of
// the identity), so per frame it costs O(#handles * #T) and no solve.
// The quaternions interpolated are RELATIVE rotations: each handle's rotation increment since the
// last interpolation. They are small even when the accumulated twist passes 180 degrees, which
// is where absolute quaternion interpolation breaks (paper, fig. 2.2: a 360-degree twist).
#pragma once

#include "tetrig/rotation_kernel.hpp"
#include "tetrig/tet_mesh.hpp"

#include <Eigen/Geometry>

#include <cstdint>
#include <span>
#include <vector>

namespace tetrig {

// Returns #handles * #T weights, handle-major, mesh tet order. Load-time: allocates, factors the
// dual-graph Laplacian once (SimplicialLDLT).
std::vector<double> harmonicTetWeights(const TetMesh& mesh, std::span<const std::vector<std::int32_t>> handle_tets,
                                       std::span<const std::int32_t> zero_tets);

// q_s <- normalize(sum_h w_hs inc_h + (1 - sum_h w_hs) * identity) * q_s for every tet slot s of
// `blocks` (weights in slot order, handle-major, `slot_count` per handle). Increments must be in
// the hemisphere of the identity (w >= 0). `slot_count` is a multiple of kTetBlockWidth (whole
// blocks). No allocation.
void applyRotationIncrements(std::span<const double> weights, std::span<const Eigen::Quaterniond> increments,
                             TetBlock* blocks, std::int32_t slot_count);

}  // namespace tetrig
