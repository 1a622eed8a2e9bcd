// The default character's skin by OpenVDB (make_character.hpp): level set sampling,
// signedFloodFill, volumeToMesh; canonical OBJ and the marker table.
#include "make_character.hpp"

#include "tetrig/drivers/character_performance.hpp"
#include "tetrig/rigbuild/decimate_surface.hpp"
#include "tetrig/rigbuild/validate_surface.hpp"
#include "tetrig/rigbuild/write_file_atomic.hpp"

#include <openvdb/openvdb.h>
#include <openvdb/tools/SignedFloodFill.h>
#include <openvdb/tools/VolumeToMesh.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numeric>
#include <vector>

namespace tetrig::character {

namespace {

using rigbuild::RigBuildError;
using rigbuild::SurfaceMesh;

// A coordinate as the OBJ prints it, read back: the mesh in memory equals the file.
double printed(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return std::strtod(buf, nullptr);
}

// Vertices sorted by (x, y, z), each triangle rotated to start at its lowest index (orientation
// kept), triangles sorted.
void canonicalOrder(SurfaceMesh& mesh) {
  const std::int32_t nv = mesh.vertexCount();
  std::vector<std::int32_t> order(static_cast<std::size_t>(nv));
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](std::int32_t a, std::int32_t b) {
    for (int k = 0; k < 3; ++k) {
      if (mesh.vertices(a, k) != mesh.vertices(b, k)) return mesh.vertices(a, k) < mesh.vertices(b, k);
    }
    return a < b;
  });
  std::vector<std::int32_t> new_index(static_cast<std::size_t>(nv));
  Vertices sorted(nv, 3);
  for (std::int32_t i = 0; i < nv; ++i) {
    new_index[static_cast<std::size_t>(order[static_cast<std::size_t>(i)])] = i;
    sorted.row(i) = mesh.vertices.row(order[static_cast<std::size_t>(i)]);
  }
  std::vector<std::array<std::int32_t, 3>> tris(static_cast<std::size_t>(mesh.triangleCount()));
  for (std::int32_t f = 0; f < mesh.triangleCount(); ++f) {
    std::array<std::int32_t, 3> t{};
    for (int k = 0; k < 3; ++k) t[static_cast<std::size_t>(k)] = new_index[static_cast<std::size_t>(mesh.triangles(f, k))];
    std::rotate(t.begin(), std::min_element(t.begin(), t.end()), t.end());
    tris[static_cast<std::size_t>(f)] = t;
  }
  std::sort(tris.begin(), tris.end());
  mesh.vertices = std::move(sorted);
  for (std::size_t f = 0; f < tris.size(); ++f) {
    for (int k = 0; k < 3; ++k) mesh.triangles(static_cast<Eigen::Index>(f), k) = tris[f][static_cast<std::size_t>(k)];
  }
}

}  // namespace

SurfaceMesh makeCharacterSkin(double voxel_mm, std::int32_t target_vertices, CharacterSkinStats* stats) {
  const auto t0 = std::chrono::steady_clock::now();
  if (!(voxel_mm >= 2.0 && voxel_mm <= 50.0)) throw RigBuildError("character skin: the voxel size must be within 2..50 mm");
  openvdb::initialize();
  // One thread: the same operations in the same order on every run.
  const tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);

  // Bounding box of the capsules, grown by the band, in voxel indices.
  const double band = kBandVoxels * voxel_mm;
  std::array<double, 3> lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (const drivers::CharacterCapsule& c : drivers::characterSkinCapsules()) {
    for (std::size_t k = 0; k < 3; ++k) {
      lo[k] = std::min({lo[k], c.a[k] - c.a_radius, c.b[k] - c.b_radius});
      hi[k] = std::max({hi[k], c.a[k] + c.a_radius, c.b[k] + c.b_radius});
    }
  }
  std::array<int, 3> ilo{}, ihi{};
  for (std::size_t k = 0; k < 3; ++k) {
    ilo[k] = static_cast<int>(std::floor((lo[k] - 2 * band) / voxel_mm));
    ihi[k] = static_cast<int>(std::ceil((hi[k] + 2 * band) / voxel_mm));
  }

  const auto background = static_cast<float>(band);
  openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(background);
  grid->setTransform(openvdb::math::Transform::createLinearTransform(voxel_mm));
  grid->setGridClass(openvdb::GRID_LEVEL_SET);
  openvdb::FloatGrid::Accessor acc = grid->getAccessor();
  for (int i = ilo[0]; i <= ihi[0]; ++i) {
    for (int j = ilo[1]; j <= ihi[1]; ++j) {
      for (int k = ilo[2]; k <= ihi[2]; ++k) {
        const double d = drivers::characterSkinField({i * voxel_mm, j * voxel_mm, k * voxel_mm});
        if (std::abs(d) < band) acc.setValue(openvdb::Coord(i, j, k), static_cast<float>(d));
      }
    }
  }
  openvdb::tools::signedFloodFill(grid->tree());

  std::vector<openvdb::Vec3s> points;
  std::vector<openvdb::Vec3I> triangles;
  std::vector<openvdb::Vec4I> quads;
  openvdb::tools::volumeToMesh(*grid, points, triangles, quads, /*isovalue=*/0.0, /*adaptivity=*/0.0);
  if (points.empty()) throw RigBuildError("character skin: the level set gave no surface");

  // Device mm (Z up, facing -Y) -> OBJ metres (Y up, facing +Z), rounded as printed.
  SurfaceMesh mesh;
  mesh.vertices.resize(static_cast<Eigen::Index>(points.size()), 3);
  for (std::size_t v = 0; v < points.size(); ++v) {
    const auto r = static_cast<Eigen::Index>(v);
    const Eigen::Vector3d obj = characterObjFromDevice(Eigen::Vector3d(points[v][0], points[v][1], points[v][2]));
    for (int k = 0; k < 3; ++k) mesh.vertices(r, k) = printed(obj[k]);
  }
  // The level set's faces wind inward: reversed here. Quads split along the shorter diagonal.
  mesh.triangles.resize(static_cast<Eigen::Index>(triangles.size() + 2 * quads.size()), 3);
  Eigen::Index f = 0;
  for (const openvdb::Vec3I& t : triangles) mesh.triangles.row(f++) << static_cast<int>(t[0]), static_cast<int>(t[2]), static_cast<int>(t[1]);
  for (const openvdb::Vec4I& q : quads) {
    const int a = static_cast<int>(q[0]), b = static_cast<int>(q[1]), c = static_cast<int>(q[2]), d = static_cast<int>(q[3]);
    const double ac = (mesh.vertices.row(a) - mesh.vertices.row(c)).squaredNorm();
    const double bd = (mesh.vertices.row(b) - mesh.vertices.row(d)).squaredNorm();
    if (ac <= bd) {
      mesh.triangles.row(f++) << a, d, c;
      mesh.triangles.row(f++) << a, c, b;
    } else {
      mesh.triangles.row(f++) << b, a, d;
      mesh.triangles.row(f++) << b, d, c;
    }
  }

  rigbuild::SurfaceReport report = rigbuild::validateSurface(mesh);
  rigbuild::requireUsableSurface(report, "character skin");
  // The even triangulation of the iso-surface has about area / voxel^2 vertices; decimated to the
  // budget with the rig builder's guarded decimation (vertices kept, never moved: still as printed).
  if (mesh.vertexCount() > target_vertices) {
    rigbuild::DecimateOptions dopt;
    dopt.target_vertices = target_vertices;
    mesh = rigbuild::decimateSurface(mesh, dopt).coarse;
    report = rigbuild::validateSurface(mesh);
    rigbuild::requireUsableSurface(report, "character skin (decimated)");
  }
  if (report.flipped_inside_out || report.reoriented_faces != 0 || report.components != 1 || report.boundary_edges != 0 ||
      report.non_manifold_edges != 0 || report.non_manifold_vertices != 0) {
    throw RigBuildError("character skin: the meshed level set is not one closed, outward, manifold surface (" + report.summary() + ")");
  }
  canonicalOrder(mesh);
  if (stats != nullptr) {
    stats->vertices = mesh.vertexCount();
    stats->triangles = mesh.triangleCount();
    stats->genus = report.genus;
    stats->height_m = mesh.vertices.col(1).maxCoeff() - mesh.vertices.col(1).minCoeff();
    stats->volume_m3 = rigbuild::signedVolume(mesh);
    stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  return mesh;
}

std::string characterObjText(const SurfaceMesh& mesh) {
  std::string out =
      "# tetrig default character (tetrig make-character; docs/character.md): metres, Y up, facing +Z, T-pose\n";
  out += "# " + std::to_string(mesh.vertexCount()) + " vertices, " + std::to_string(mesh.triangleCount()) + " triangles\n";
  char buf[96];
  for (std::int32_t v = 0; v < mesh.vertexCount(); ++v) {
    std::snprintf(buf, sizeof buf, "v %.6g %.6g %.6g\n", mesh.vertices(v, 0), mesh.vertices(v, 1), mesh.vertices(v, 2));
    out += buf;
  }
  for (std::int32_t t = 0; t < mesh.triangleCount(); ++t) {
    std::snprintf(buf, sizeof buf, "f %d %d %d\n", mesh.triangles(t, 0) + 1, mesh.triangles(t, 1) + 1, mesh.triangles(t, 2) + 1);
    out += buf;
  }
  return out;
}

std::string characterMarkersCsv() {
  std::string out = "label,bone,x_mm,y_mm,z_mm\n";
  const auto bones = drivers::characterBones();
  char buf[160];
  for (const drivers::CharacterMarker& m : drivers::characterMarkers()) {
    std::snprintf(buf, sizeof buf, "%.*s,%.*s,%.3f,%.3f,%.3f\n", static_cast<int>(m.label.size()), m.label.data(),
                  static_cast<int>(bones[static_cast<std::size_t>(m.bone)].name.size()), bones[static_cast<std::size_t>(m.bone)].name.data(),
                  m.tpose[0], m.tpose[1], m.tpose[2]);
    out += buf;
  }
  return out;
}

CharacterSkinStats writeCharacterAssets(const std::filesystem::path& dir) {
  CharacterSkinStats stats;
  const SurfaceMesh mesh = makeCharacterSkin(kSkinVoxelMm, kSkinVertices, &stats);
  const std::string obj = characterObjText(mesh);
  const std::string csv = characterMarkersCsv();
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw RigBuildError(dir.string() + ": cannot create the folder: " + ec.message());
  auto bytes = [](const std::string& s) { return std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(s.data()), s.size()); };
  rigbuild::writeFileAtomically(dir / kCharacterObjName, bytes(obj));
  rigbuild::writeFileAtomically(dir / kCharacterMarkersName, bytes(csv));
  return stats;
}

}  // namespace tetrig::character
