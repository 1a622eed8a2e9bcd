// The solver flags `tetrig run`, `tetrig export`, `tetrig demo` and `tetrig_fidelity` share: one
// place that declares them on a command (addSolverFlags), checks them (checkSolverSettings) and
// writes them into a report (solverJson), so that every tool accepts and means the same flags and
// starts from the same defaults (SolverSettings{}, the accurate settings).
#pragma once

#include "tetrig/deformer.hpp"
#include "tetrig/solver_settings.hpp"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <stdexcept>
#include <string>

namespace tetrig::tools {

// Checks the settings the flags set; throws std::invalid_argument naming the flag:
// --relax OMEGA in [1, 2), --inversion-guard K in [0, 1] for the explicit guard and up to
// kImplicitGuardMaxK for the implicit one, --inversion-guard-solves S in [0, 64] (> 0: the implicit
// guard), --inversion-guard-threshold T in [0.01, 1] (the volume ratio below which the guard holds a
// tet), --after-publish-iterations in [0, 100], --coarse-iterations >= 1.
inline void checkSolverSettings(const SolverSettings& s) {
  if (!(s.rotation_relaxation >= 1.0 && s.rotation_relaxation < 2.0)) throw std::invalid_argument("--relax must be in [1, 2)");
  if (!(s.inversion_guard_threshold >= 0.01 && s.inversion_guard_threshold <= 1.0))
    throw std::invalid_argument("--inversion-guard-threshold must be in [0.01, 1]");
  if (s.inversion_guard_solves < 0 || s.inversion_guard_solves > 64) throw std::invalid_argument("--inversion-guard-solves must be in [0, 64]");
  if (s.inversion_guard_solves > 0) {
    if (!(s.inversion_guard >= 0.0 && s.inversion_guard <= kImplicitGuardMaxK))
      throw std::invalid_argument("--inversion-guard must be in [0, 1000] with --inversion-guard-solves");
  } else if (!(s.inversion_guard >= 0.0 && s.inversion_guard <= 1.0)) {
    throw std::invalid_argument("--inversion-guard must be in [0, 1] (above 1 only with --inversion-guard-solves: the explicit guard is "
                                "unstable there)");
  }
  if (s.after_publish_iterations < 0 || s.after_publish_iterations > 100)
    throw std::invalid_argument("--after-publish-iterations must be in [0, 100]");
  if (s.coarse_iterations < 1) throw std::invalid_argument("--coarse-iterations must be at least 1");
}

// Declares the shared solver flags on `cmd`, writing into `s` (whose values are the shown defaults):
//   --predict / --no-predict              temporal prediction of each frame's start (rotation_extrapolation 1 / 0)
//   --keep-volume / --no-keep-volume      keep the fine mesh's enclosed volume at rest (volume_constraint)
//   --no-coarse                           ignore the rig's own coarse level
//   --relax, --inversion-guard, --inversion-guard-solves, --inversion-guard-threshold,
//   --after-publish-iterations
// A flag given twice takes its last value. `group` names the flags' help section ("" for none).
// Range errors come from CLI11 at parse time;
// call checkSolverSettings after parsing for the checks across flags.
inline void addSolverFlags(CLI::App& cmd, SolverSettings& s, const std::string& group = "") {
  auto grouped = [&group](auto* option) {
    if (!group.empty()) option->group(group);
    option->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);  // given twice: the last one counts
    return option;
  };
  CLI::Option* predict = grouped(cmd.add_flag_callback(
      "--predict", [&s] { s.rotation_extrapolation = 1.0; },
      "Start each frame where the motion is heading: the skin lands nearer its final shape in the frame's iterations (default on)"));
  CLI::Option* no_predict = grouped(cmd.add_flag_callback(
      "--no-predict", [&s] { s.rotation_extrapolation = 0.0; }, "Start each frame from the last pose (no temporal prediction)"));
  predict->excludes(no_predict);
  CLI::Option* keep_volume = grouped(cmd.add_flag_callback(
      "--keep-volume", [&s] { s.volume_constraint = true; },
      "Keep the body's volume constant (default on): bent joints do not lose volume; about a quarter more work per frame, "
      "done after each publish; skipped with a note when the rig's fine mesh is not closed"));
  CLI::Option* no_keep_volume = grouped(cmd.add_flag_callback(
      "--no-keep-volume", [&s] { s.volume_constraint = false; }, "Let bent joints lose volume (no volume constraint)"));
  keep_volume->excludes(no_keep_volume);
  grouped(cmd.add_flag_callback(
      "--no-coarse", [&s] { s.use_coarse_level = false; }, "Do not use the rig's own coarse level (built with --coarse-tet-vertices)"));
  grouped(cmd.add_option("--relax", s.rotation_relaxation,
                         "How far each iteration steps toward the final shape: 1 cautious; the default 1.8 lands nearest in a few "
                         "iterations (docs/fidelity.md)")
              ->capture_default_str()
              ->check(CLI::Range(1.0, 1.999)));
  grouped(cmd.add_option("--inversion-guard", s.inversion_guard,
                         "Resist the body turning inside out where the markers bend it far: squashed parts get up to 1 + K times "
                         "stiffer (0 off; at most 1 without --inversion-guard-solves)")
              ->capture_default_str()
              ->check(CLI::Range(0.0, 1000.0)));
  grouped(cmd.add_option("--inversion-guard-solves", s.inversion_guard_solves,
                         "The implicit inversion guard: conjugate-gradient steps per iteration, each one more solve (0: the "
                         "explicit guard)")
              ->capture_default_str()
              ->check(CLI::Range(0, 64)));
  grouped(cmd.add_option("--inversion-guard-threshold", s.inversion_guard_threshold,
                         "How squashed a part of the body must be before the guard acts, as a fraction of its volume")
              ->capture_default_str()
              ->check(CLI::Range(0.01, 1.0)));
  grouped(cmd.add_option("--after-publish-iterations", s.after_publish_iterations,
                         "Iterations on each frame after it is published, within its budget: the next frame starts nearer its "
                         "final shape")
              ->capture_default_str()
              ->check(CLI::Range(0, 100)));
}

// The settings as a report's "solver" object (tetrig run --stats-json, tetrig export --report,
// tetrig_fidelity --json): one key per SolverSettings field, plus "predict" (rotation_extrapolation > 0).
inline nlohmann::json solverJson(const SolverSettings& s) {
  return {{"predict", s.rotation_extrapolation > 0.0},
          {"rotation_extrapolation", s.rotation_extrapolation},
          {"rotation_extrapolation_max_deg", s.rotation_extrapolation_max_deg},
          {"relax", s.rotation_relaxation},
          {"volume_weight", s.volume_weight},
          {"inversion_guard", s.inversion_guard},
          {"inversion_guard_threshold", s.inversion_guard_threshold},
          {"inversion_guard_solves", s.inversion_guard_solves},
          {"untangle", s.untangle},
          {"keep_volume", s.volume_constraint},
          {"volume_constraint_refresh_frames", s.volume_constraint_refresh_frames},
          {"after_publish_iterations", s.after_publish_iterations},
          {"coarse_iterations", s.coarse_iterations},
          {"use_coarse_level", s.use_coarse_level}};
}

}  // namespace tetrig::tools
