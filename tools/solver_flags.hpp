// The solver flags `tetrig run`, `tetrig export` and `tetrig_fidelity` share, checked and set on the
// live rig's options in one place so that all accept and mean the same thing.
#pragma once

#include "tetrig/live_rig.hpp"

#include <stdexcept>

namespace tetrig::tools {

// --relax OMEGA (LiveRigOptions::rotation_relaxation, [1, 2)), --inversion-guard K
// (LiveRigOptions::inversion_guard: [0, 1] for the explicit guard, up to kImplicitGuardMaxK for the
// implicit one), --inversion-guard-solves S (LiveRigOptions::inversion_guard_solves, [0, 64]; > 0:
// the implicit guard) and --inversion-guard-threshold T (LiveRigOptions::inversion_guard_threshold,
// [0.01, 1]: the volume ratio below which the guard holds a tet). Throws std::invalid_argument naming
// the flag.
inline void setRelaxAndGuard(double relax, double inversion_guard, int inversion_guard_solves, double inversion_guard_threshold,
                             LiveRigOptions& options) {
  if (!(relax >= 1.0 && relax < 2.0)) throw std::invalid_argument("--relax must be in [1, 2)");
  if (!(inversion_guard_threshold >= 0.01 && inversion_guard_threshold <= 1.0))
    throw std::invalid_argument("--inversion-guard-threshold must be in [0.01, 1]");
  if (inversion_guard_solves < 0 || inversion_guard_solves > 64) throw std::invalid_argument("--inversion-guard-solves must be in [0, 64]");
  if (inversion_guard_solves > 0) {
    if (!(inversion_guard >= 0.0 && inversion_guard <= kImplicitGuardMaxK))
      throw std::invalid_argument("--inversion-guard must be in [0, 1000] with --inversion-guard-solves");
  } else if (!(inversion_guard >= 0.0 && inversion_guard <= 1.0)) {
    throw std::invalid_argument("--inversion-guard must be in [0, 1] (above 1 only with --inversion-guard-solves: the explicit guard is "
                                "unstable there)");
  }
  options.rotation_relaxation = relax;
  options.inversion_guard = inversion_guard;
  options.inversion_guard_solves = inversion_guard_solves;
  options.inversion_guard_threshold = inversion_guard_threshold;
}

}  // namespace tetrig::tools
