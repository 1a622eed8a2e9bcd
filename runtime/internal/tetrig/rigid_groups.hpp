// Rigid groups (Stoll et al. 2007, section 2.3.2, "Rigid section handling"): every tet of a group
// takes the group's average rotation, the proper rotation closest to sum_j a_j R_j (weights a_j =
// stiffness * volume). Groups may be disconnected. No allocation.
#pragma once

#include "tetrig/rotation_kernel.hpp"

#include <cstdint>
#include <span>

namespace tetrig {

// Groups as CSR: group g owns tet slots group_slot[group_start[g] .. group_start[g + 1]).
void applyRigidGroups(std::span<const std::int32_t> group_start, std::span<const std::int32_t> group_slot,
                      TetBlock* blocks);

}  // namespace tetrig
