// Chains the rig builder's geometry steps (see rig_geometry.hpp).
#include "tetrig/rigbuild/rig_geometry.hpp"

#include <chrono>
#include <cstdio>

namespace tetrig::rigbuild {
namespace {

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

std::string format(const char* fmt, double a, double b = 0, double c = 0, double d = 0) {
  char buffer[256];
  std::snprintf(buffer, sizeof(buffer), fmt, a, b, c, d);
  return buffer;
}

}  // namespace

RigGeometry buildRigGeometry(const std::filesystem::path& surface, const RigGeometryOptions& options,
                             const std::function<void(const std::string&)>& progress) {
  auto say = [&progress](const std::string& line) {
    if (progress) progress(line);
  };
  RigGeometry g;
  auto start = std::chrono::steady_clock::now();
  g.fine = importSurface(surface, options.import, &g.import_stats);
  g.seconds.import = secondsSince(start);
  say(format("imported %.0f vertices, %.0f triangles (%.2f s)", g.fine.vertexCount(), g.fine.triangleCount(),
             g.seconds.import));

  start = std::chrono::steady_clock::now();
  g.surface_report = validateSurface(g.fine, options.validate);
  g.seconds.validate = secondsSince(start);
  requireUsableSurface(g.surface_report, surface.string());
  say("surface: " + g.surface_report.summary());

  start = std::chrono::steady_clock::now();
  g.coarse = buildCoarseTetMesh(g.fine, options.decimate, options.tetrahedralize, options.retries, options.intersections);
  g.seconds.coarse = secondsSince(start);
  say(format("tet mesh: %.0f vertices, %.0f tets, %.0f intersecting faces repaired (%.2f s)",
             g.coarse.tets.mesh.vertexCount(), g.coarse.tets.mesh.tetCount(), g.coarse.repair.initial_faces,
             g.seconds.coarse));

  start = std::chrono::steady_clock::now();
  g.b = poseTransferWeights(g.fine.vertices, g.coarse.tets.mesh, options.pose_transfer, &g.b_stats);
  g.seconds.weights = secondsSince(start);
  g.rest_error = restReconstructionError(g.b, g.fine.vertices, g.coarse.tets.mesh.vertices);
  say(format("pose transfer: %.1f non-zeros per vertex, rest error %.2g of the diagonal (%.2f s)",
             g.b_stats.mean_nonzeros_per_row, g.rest_error, g.seconds.weights));
  return g;
}

}  // namespace tetrig::rigbuild
