// The solver settings of the live frame path, one struct every tool shares (LiveRigOptions::solver;
// `tetrig run`, `tetrig export`, `tetrig demo` and `tetrig_fidelity` hold one and set it from the
// same flags, tools/solver_flags.hpp).
//
// The defaults are the accurate settings (measured best on HDM05, docs/fidelity.md): every frame
// starts from its temporal prediction, each iteration's rotation update is over-relaxed, squashed
// body tets are held by the implicit inversion guard, the fine mesh's enclosed volume is kept at
// rest (when the fine mesh is closed: LiveRig::volumeNotKept()) and the rig's own coarse level
// steps first. SolverSettings::plain() is the fast setup without prediction, guard or volume
// constraint, for benchmarks and comparisons.
#pragma once

namespace tetrig {

struct SolverSettings {
  // Temporal prediction of the warm start (DeformerOptions::rotation_extrapolation, alpha in [0, 1]):
  // each frame starts from every tet's rotation carried on by alpha times its last frame's rotation.
  double rotation_extrapolation = 1.0;
  double rotation_extrapolation_max_deg = 5.0;  // cap of a tet's predicted rotation per frame
  double rotation_relaxation = 1.8;             // omega in [1, 2): over-relaxation of each rotation update
  double volume_weight = 0.0;                   // the volume term's w (docs/deformation.md), rig and coarse level
  double inversion_guard = 4.0;                 // k: extra stiffness of squashed body tets, rig and coarse level
  double inversion_guard_threshold = 0.6;       // tau: the volume ratio below which the guard holds a tet
  int inversion_guard_solves = 1;               // > 0: the implicit guard (conjugate-gradient steps per iteration)
  bool untangle = true;                         // with the implicit guard: relax the corners of nearly inverted
                                                // body tets in each published pose (DeformerOptions::untangle)
  // Keep the fine mesh's enclosed volume at rest (FineVolumeConstraint, a Lagrange multiplier on the
  // fine rig, linearized at each frame's published pose by LiveRig::prepareNextFrame). Needs a closed
  // fine mesh: on an open one the live rig skips it (LiveRig::volumeNotKept()).
  bool volume_constraint = true;
  int volume_constraint_refresh_frames = 1;  // frames between two linearizations of the volume's gradient
  // Iterations on each frame's own targets after its pose is published (LiveRig::prepareNextFrame,
  // within the frame's deadline). 0: none.
  int after_publish_iterations = 0;
  int coarse_iterations = 2;     // the coarse level's iterations per frame (2 as near as 5: docs/fidelity.md)
  bool use_coarse_level = true;  // use the rig's own coarse level (Rig::coarse) when it has one

  // The fast settings: no temporal prediction, no inversion guard, no volume constraint.
  static SolverSettings plain() noexcept {
    SolverSettings s;
    s.rotation_extrapolation = 0.0;
    s.rotation_relaxation = 1.8;
    s.inversion_guard = 0.0;
    s.inversion_guard_solves = 0;
    s.inversion_guard_threshold = 0.5;  // (untangle stays: without the implicit guard it does nothing)
    s.volume_constraint = false;
    return s;
  }

  bool operator==(const SolverSettings&) const = default;
};

}  // namespace tetrig
