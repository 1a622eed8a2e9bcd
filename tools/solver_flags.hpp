// The solver flags `tetrig run` and `tetrig export` share, checked and set on the live rig's options
// in one place so that both commands accept and mean the same thing.
#pragma once

#include "tetrig/live_rig.hpp"

#include <stdexcept>

namespace tetrig::tools {

// --relax OMEGA (LiveRigOptions::rotation_relaxation, [1, 2)) and --inversion-guard K
// (LiveRigOptions::inversion_guard, [0, 1]). Throws std::invalid_argument naming the flag.
inline void setRelaxAndGuard(double relax, double inversion_guard, LiveRigOptions& options) {
  if (!(relax >= 1.0 && relax < 2.0)) throw std::invalid_argument("--relax must be in [1, 2)");
  if (!(inversion_guard >= 0.0 && inversion_guard <= 1.0)) throw std::invalid_argument("--inversion-guard must be in [0, 1]");
  options.rotation_relaxation = relax;
  options.inversion_guard = inversion_guard;
}

}  // namespace tetrig::tools
