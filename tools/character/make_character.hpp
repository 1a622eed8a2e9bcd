// `tetrig make-character`: the default character's assets (docs/character.md).
//
// The skin is the zero set of characterSkinField() (drivers/character_performance.hpp: a smooth
// union of tapered capsules along the T-pose skeleton). It is sampled on a voxel grid into an
// OpenVDB narrow-band level set (values within kBandVoxels voxels of the surface), the inside is
// signed by signedFloodFill, and volumeToMesh extracts the iso-surface (its faces wind inward for
// a level set: they are flipped; its quads are split along their shorter diagonal), which the rig
// builder's guarded quadric decimation (decimate_surface.hpp) brings to kSkinVertices. The surface
// is converted to the OBJ convention (metres, Y up: x_obj = x / 1000, y_obj = z / 1000,
// z_obj = -y / 1000, so the character faces +Z) and checked with the rig builder's surface
// validation (closed, manifold, oriented outward, one component).
//
// Reproducible: the level set is filled in a fixed order from a pure function, OpenVDB runs on
// one thread here, and the output is put in a canonical order (vertices sorted by their printed
// coordinates, each triangle rotated to start at its lowest index, triangles sorted), so a rerun
// writes the same bytes.
//
// Offline: allocates, throws rigbuild::RigBuildError (or std::runtime_error) with one line.
#pragma once

#include "tetrig/rigbuild/surface_mesh.hpp"

#include <Eigen/Dense>

#include <cstdint>
#include <filesystem>
#include <string>

namespace tetrig::character {

inline constexpr double kSkinVoxelMm = 10.0;        // grid spacing of the level set
inline constexpr std::int32_t kSkinVertices = 3000;  // vertex budget of the decimated skin

// The assets' axes: a point in the device's millimetres (Z up, facing -Y) in the OBJ's metres
// (Y up, facing +Z), and back.
inline Eigen::Vector3d characterObjFromDevice(const Eigen::Vector3d& device_mm) {
  return Eigen::Vector3d(device_mm.x(), device_mm.z(), -device_mm.y()) / 1000.0;
}
inline Eigen::Vector3d characterDeviceFromObj(const Eigen::Vector3d& obj_m) {
  return Eigen::Vector3d(obj_m.x(), -obj_m.z(), obj_m.y()) * 1000.0;
}
inline constexpr int kBandVoxels = 3;         // narrow band half-width

struct CharacterSkinStats {
  std::int32_t vertices = 0, triangles = 0;
  std::int32_t genus = -1;
  double height_m = 0;      // along the OBJ's Y
  double volume_m3 = 0;
  double seconds = 0;
};

// The skin in OBJ axes and metres (see above), validated closed and manifold.
rigbuild::SurfaceMesh makeCharacterSkin(double voxel_mm = kSkinVoxelMm, std::int32_t target_vertices = kSkinVertices,
                                        CharacterSkinStats* stats = nullptr);

// The OBJ text of `mesh` (a header comment, "v x y z" with %.6g, "f a b c" 1-based).
std::string characterObjText(const rigbuild::SurfaceMesh& mesh);

// The T-pose markers as CSV: "label,bone,x_mm,y_mm,z_mm" (device axes, %.3f), one line each.
std::string characterMarkersCsv();

// File names inside the assets folder.
inline constexpr const char* kCharacterObjName = "character.obj";
inline constexpr const char* kCharacterMarkersName = "markers.csv";

// Writes character.obj and markers.csv into `dir` (created if needed), each atomically; returns
// what was made. Prints nothing.
CharacterSkinStats writeCharacterAssets(const std::filesystem::path& dir);

}  // namespace tetrig::character
