// The coarse level: a much smaller tet mesh of the same shape, solved every frame before the fine
// iterations, whose rotation change guides the fine tets' start (issue #12, docs/fidelity.md
// "Coarse level").
//
// A few fine iterations per frame remove the short-range part of the rotation field's error fast
// and the long-range part (a limb turning as a whole, the body lagging its markers) slowly: a slow
// mode contracts by rho per iteration with rho close to 1, and what is left accumulates from frame
// to frame. The same long-range modes converge in a few iterations on a mesh with a tenth of the
// tets (they are short-range there). So each frame:
//   1. the coarse deformer steps `iterations` times on the same frame's handle targets (warm-started
//      from its last frame, like the fine one);
//   2. every coarse tet's rotation change over the frame, Q_c = R_c,n R_c,n-1^-1, is handed to the
//      fine tets it covers (the coarse tet whose rest centroid is nearest to the fine tet's) as the
//      fine deformer's frame guide: the fine frame starts from R_f' = Q_c(f) R_f (with the fine
//      temporal prediction, if on, taken beyond the guide: tetrig/rotation_prediction.hpp);
//   3. the fine iterations then only correct the detail.
// The converged pose is the fine rig's own: the guide changes where a frame starts, not where it
// converges.
//
// Load time: the constructor allocates and factorises the coarse mesh (throws what Deformer throws,
// std::invalid_argument for bad options). guide() and reset() allocate nothing, lock nothing, throw
// nothing. One thread.
#pragma once

#include "tetrig/deformer.hpp"
#include "tetrig/solver_settings.hpp"
#include "tetrig/tet_mesh.hpp"

#include <cstdint>
#include <span>
#include <vector>

namespace tetrig {

struct CoarseLevelOptions {
  // Coarse iterations per frame (at least 1): the live default, SolverSettings::coarse_iterations.
  int iterations = SolverSettings{}.coarse_iterations;
};

class CoarseLevel {
 public:
  // fine_mesh: the fine deformer's tet mesh (rest); fine: the deformer it guides (of fine_mesh, with
  // DeformerOptions::frame_guide on: its guide's sources become the coarse tets,
  // Deformer::setFrameGuideSources); coarse_mesh and coarse_setup: the coarse level's (rest in the
  // same units and place as the fine mesh). The coarse level keeps `fine` (it must outlive the coarse
  // level), so a coarse level is neither copied nor moved.
  CoarseLevel(const TetMesh& fine_mesh, Deformer& fine, const TetMesh& coarse_mesh, const DeformerSetup& coarse_setup,
              const CoarseLevelOptions& options = {});
  CoarseLevel(const CoarseLevel&) = delete;
  CoarseLevel& operator=(const CoarseLevel&) = delete;

  // One frame: the coarse step on `coarse_targets` (the coarse setup's handles), then the frame guide
  // of the fine deformer given at construction. Returns the coarse step's stats, with total_ns the
  // whole call's time (the step and the guide). No allocation.
  StepStats guide(const HandleTargets& coarse_targets) noexcept;

  // Back to rest (rotations I, no change remembered). No allocation.
  void reset() noexcept;

  const Deformer& deformer() const noexcept { return coarse_; }
  // The coarse tet that guides each fine tet (nearest rest centroid).
  std::span<const std::int32_t> coarseTetOfFineTet() const noexcept { return coarse_of_fine_; }
  const CoarseLevelOptions& options() const noexcept { return options_; }

 private:
  CoarseLevelOptions options_;
  Deformer& fine_;
  Deformer coarse_;
  std::vector<std::int32_t> coarse_of_fine_;
  std::vector<float> previous_;  // R_c,n-1 per coarse tet (w x y z)
  std::vector<float> now_;       // R_c,n per coarse tet (w x y z), read out of the coarse deformer
  std::vector<float> change_;    // Q_c per coarse tet (w x y z): the fine deformer's guide table
};

}  // namespace tetrig
