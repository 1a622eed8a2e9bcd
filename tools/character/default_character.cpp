// The default character's rig: build inputs, cache key and cached build (default_character.hpp).
#include "default_character.hpp"

#include "make_character.hpp"
#include "tetrig/drivers/character_performance.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/write_file_atomic.hpp"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <iterator>

namespace tetrig::character {

namespace {

constexpr const char* kCacheVersion = "character-rig-3";

std::string readWhole(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    throw rigbuild::RigBuildError(path.string() + ": cannot read the default character (make it with `tetrig make-character --out " +
                                  path.parent_path().string() + "`)");
  }
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

}  // namespace

rigbuild::BuildRigInputs defaultCharacterRigInputs(const std::filesystem::path& assets_dir) {
  rigbuild::BuildRigInputs in;
  in.mesh = assets_dir / kCharacterObjName;
  in.description.name = "tetrig default character";
  // The description's defaults are the character's axes: mesh_unit "m", mesh_up "y",
  // markers.device_up "z", markers.alignment "auto" (tested in tests/tools/test_character.cpp).
  rigbuild::MarkerPositions markers;
  markers.what = "the default character's T-pose markers";
  for (const drivers::CharacterMarker& m : drivers::characterMarkers()) {
    markers.labels.emplace_back(m.label);
    markers.device_mm.emplace_back(m.tpose[0], m.tpose[1], m.tpose[2]);
  }
  in.marker_positions = std::move(markers);
  // The markers sit kCharacterMarkerClearanceMm outside the skin: the alignment fits them there
  // (fitted onto the skin itself, the performance would come out 0.9 % small).
  in.description.markers.marker_offset = drivers::kCharacterMarkerClearanceMm * 0.001;  // the OBJ's metres
  in.coarse_tet_vertices = rigbuild::kDefaultCoarseTetVertices;  // as build-rig builds a marker-driven rig
  return in;
}

DefaultCharacter prepareDefaultCharacter(const std::filesystem::path& assets_dir, const std::filesystem::path& cache_dir,
                                         rigbuild::Progress* progress, rigbuild::BuildRigReport* report) {
  const rigbuild::BuildRigInputs in = defaultCharacterRigInputs(assets_dir);
  std::string key = kCacheVersion;
  for (const std::string& part : {readWhole(in.mesh), characterMarkersCsv(), std::to_string(in.description.tet_vertices)}) {
    key.push_back('|');
    key.append(part);
  }
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016zx", std::hash<std::string>{}(key));
  DefaultCharacter out;
  out.performance_frames = static_cast<std::uint64_t>(std::llround(drivers::characterPerformanceSeconds() * 120.0));
  out.rig_path = cache_dir / ("character-" + std::string(hex) + ".rig");
  if (std::filesystem::exists(out.rig_path)) {
    out.reused = true;
    return out;
  }
  const Rig rig = rigbuild::buildRig(in, report, progress);
  std::error_code ec;
  std::filesystem::create_directories(cache_dir, ec);
  if (ec) throw rigbuild::RigBuildError(cache_dir.string() + ": cannot create the rig cache folder: " + ec.message());
  rigbuild::writeFileAtomically(out.rig_path, serializeRig(rig));
  return out;
}

}  // namespace tetrig::character
