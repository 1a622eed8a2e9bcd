// The default rig of `tetrig demo`: the generated character (assets/character/character.obj, made
// by `tetrig make-character`) bound to its own T-pose markers (drivers/character_performance.hpp,
// given to the rig builder as BuildRigInputs::marker_positions), driven by the
// "synthetic:character" source (its scripted performance with noise and dropouts).
//
// The rig is built once and cached (like the demo's real-data rigs): the cache file's name is a
// hash of the OBJ's bytes, the marker positions and the build settings, so regenerated assets
// give a new rig. Offline: allocates, throws rigbuild::RigBuildError with one line.
#pragma once

#include "tetrig/rigbuild/build_rig.hpp"
#include "tetrig/rigbuild/progress.hpp"

#include <cstdint>
#include <filesystem>
#include <string>

namespace tetrig::character {

inline constexpr const char* kCharacterSourceSpec = "synthetic:character";

// The rig builder's inputs for the default character whose assets are in `assets_dir` (the folder
// holding character.obj): OBJ in metres, Y up; markers in device mm, Z up; automatic alignment
// with every plausibility check on.
rigbuild::BuildRigInputs defaultCharacterRigInputs(const std::filesystem::path& assets_dir);

struct DefaultCharacter {
  std::filesystem::path rig_path;    // the cached rig file
  bool reused = false;               // true: the cache already held it
  std::string source_spec = kCharacterSourceSpec;
  std::uint64_t performance_frames;  // one pass of the performance at 120 Hz
};

// Returns the default rig from `cache_dir`, building and caching it (atomically) first when
// absent. `report` (optional) receives the build report when a rig is built.
DefaultCharacter prepareDefaultCharacter(const std::filesystem::path& assets_dir, const std::filesystem::path& cache_dir,
                                         rigbuild::Progress* progress = nullptr, rigbuild::BuildRigReport* report = nullptr);

}  // namespace tetrig::character
