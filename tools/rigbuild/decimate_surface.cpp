// Quadric-error surface decimation (Garland and Heckbert, "Surface Simplification Using Quadric
// Error Metrics", SIGGRAPH 1997) through meshoptimizer's meshopt_simplify, driven to a vertex
// budget: meshopt_simplify takes a triangle target, which for a closed surface of Euler
// characteristic chi is F = 2 (V - chi); the target is corrected from the count actually reached.
#include "tetrig/rigbuild/decimate_surface.hpp"

#include "tetrig/rigbuild/validate_surface.hpp"

#include <meshoptimizer.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>

namespace tetrig::rigbuild {
namespace {

struct Attempt {
  std::vector<unsigned> indices;
  std::int32_t vertices = 0;
  float error = 0.0f;
};

std::int32_t countUsed(const std::vector<unsigned>& indices, std::vector<char>& scratch) {
  std::fill(scratch.begin(), scratch.end(), 0);
  std::int32_t n = 0;
  for (const unsigned i : indices) {
    if (!scratch[i]) {
      scratch[i] = 1;
      ++n;
    }
  }
  return n;
}

}  // namespace

DecimationResult decimateSurface(const SurfaceMesh& fine, const DecimateOptions& options) {
  if (options.target_vertices < 4) {
    throw RigBuildError("decimation target of " + std::to_string(options.target_vertices) +
                        " vertices is too small: a closed surface needs at least 4");
  }
  DecimationResult result;
  if (fine.vertexCount() <= options.target_vertices) {
    result.coarse = fine;
    result.coarse_to_fine.resize(static_cast<size_t>(fine.vertexCount()));
    for (std::int32_t v = 0; v < fine.vertexCount(); ++v) result.coarse_to_fine[static_cast<size_t>(v)] = v;
    return result;
  }
  const SurfaceTopology topo = surfaceTopology(fine);
  if (!topo.closedManifold()) {
    throw RigBuildError("decimation needs a closed, manifold, consistently oriented surface (" +
                        std::to_string(topo.boundary_edges) + " boundary, " + std::to_string(topo.non_manifold_edges) +
                        " non-manifold, " + std::to_string(topo.inconsistent_edges) +
                        " inconsistent edges): run validateSurface first");
  }
  const std::int64_t chi = static_cast<std::int64_t>(fine.vertexCount()) - topo.edges + fine.triangleCount();

  const auto nv = static_cast<size_t>(fine.vertexCount());
  std::vector<float> positions(nv * 3);
  for (size_t v = 0; v < nv; ++v) {
    for (int c = 0; c < 3; ++c) positions[v * 3 + static_cast<size_t>(c)] = static_cast<float>(fine.vertices(static_cast<Eigen::Index>(v), c));
  }
  std::vector<unsigned> indices(static_cast<size_t>(fine.triangleCount()) * 3);
  for (std::int32_t f = 0; f < fine.triangleCount(); ++f) {
    for (int k = 0; k < 3; ++k) indices[static_cast<size_t>(f) * 3 + static_cast<size_t>(k)] = static_cast<unsigned>(fine.triangles(f, k));
  }

  std::vector<char> scratch(nv);
  const double target = options.target_vertices;
  double triangle_target = std::max<double>(4.0, 2.0 * (target - static_cast<double>(chi)));
  Attempt best;
  double best_miss = std::numeric_limits<double>::infinity();
  std::vector<unsigned> out(indices.size());
  const unsigned flags = options.lock_border ? unsigned{meshopt_SimplifyLockBorder} : 0u;
  for (int attempt = 0; attempt < std::max(1, options.max_attempts); ++attempt) {
    ++result.attempts;
    const auto target_indices = static_cast<size_t>(std::llround(triangle_target)) * 3;
    float error = 0.0f;
    const size_t n = meshopt_simplify(out.data(), indices.data(), indices.size(), positions.data(), nv,
                                      sizeof(float) * 3, target_indices, std::numeric_limits<float>::max(), flags, &error);
    Attempt a;
    a.indices.assign(out.begin(), out.begin() + static_cast<std::ptrdiff_t>(n));
    a.vertices = countUsed(a.indices, scratch);
    a.error = error;
    const std::int32_t reached = a.vertices;
    const double miss = std::abs(reached - target) / target;
    if (miss < best_miss) {
      best_miss = miss;
      best = std::move(a);
    }
    if (best_miss <= options.tolerance || best.vertices == 0) break;
    // Correct the triangle target by the ratio actually reached.
    triangle_target = std::max(4.0, triangle_target * target / std::max(1.0, static_cast<double>(reached)));
  }

  // Compact the kept vertices (in fine order) and rewrite the triangles.
  std::vector<std::int32_t> new_index(nv, -1);
  for (const unsigned i : best.indices) new_index[i] = 0;
  std::int32_t kept = 0;
  for (size_t v = 0; v < nv; ++v) {
    if (new_index[v] == 0) {
      new_index[v] = kept++;
      result.coarse_to_fine.push_back(static_cast<std::int32_t>(v));
    }
  }
  result.coarse.vertices.resize(kept, 3);
  for (std::int32_t c = 0; c < kept; ++c) result.coarse.vertices.row(c) = fine.vertices.row(result.coarse_to_fine[static_cast<size_t>(c)]);
  const auto nf = static_cast<Eigen::Index>(best.indices.size() / 3);
  result.coarse.triangles.resize(nf, 3);
  for (Eigen::Index f = 0; f < nf; ++f) {
    for (int k = 0; k < 3; ++k) result.coarse.triangles(f, k) = new_index[best.indices[static_cast<size_t>(f) * 3 + static_cast<size_t>(k)]];
  }
  result.relative_error = best.error;

  // meshopt_simplify can fold two triangles onto each other: the same three corners in both
  // orientations, a zero-volume "pillow" whose edges then have four faces. Removing both faces
  // of such a pair restores two faces per edge; vertices left unused are dropped.
  {
    std::vector<std::pair<std::array<std::int32_t, 3>, std::int32_t>> keyed;
    for (Eigen::Index f = 0; f < nf; ++f) {
      std::array<std::int32_t, 3> k{result.coarse.triangles(f, 0), result.coarse.triangles(f, 1), result.coarse.triangles(f, 2)};
      std::sort(k.begin(), k.end());
      keyed.push_back({k, static_cast<std::int32_t>(f)});
    }
    std::sort(keyed.begin(), keyed.end());
    std::vector<char> drop(static_cast<size_t>(nf), 0);
    for (size_t i = 0; i < keyed.size();) {
      size_t j = i;
      while (j < keyed.size() && keyed[j].first == keyed[i].first) ++j;
      if (j - i == 2) {
        drop[static_cast<size_t>(keyed[i].second)] = 1;
        drop[static_cast<size_t>(keyed[i + 1].second)] = 1;
        result.removed_folded_faces += 2;
      }
      i = j;
    }
    if (result.removed_folded_faces > 0) {
      Triangles kept_faces(nf - result.removed_folded_faces, 3);
      Eigen::Index out_f = 0;
      std::vector<std::int32_t> used(static_cast<size_t>(kept), -1);
      for (Eigen::Index f = 0; f < nf; ++f) {
        if (drop[static_cast<size_t>(f)]) continue;
        kept_faces.row(out_f++) = result.coarse.triangles.row(f);
        for (int k = 0; k < 3; ++k) used[static_cast<size_t>(result.coarse.triangles(f, k))] = 0;
      }
      std::int32_t n_used = 0;
      std::vector<std::int32_t> coarse_to_fine;
      for (std::int32_t c = 0; c < kept; ++c) {
        if (used[static_cast<size_t>(c)] == 0) {
          used[static_cast<size_t>(c)] = n_used++;
          coarse_to_fine.push_back(result.coarse_to_fine[static_cast<size_t>(c)]);
        }
      }
      Vertices verts(n_used, 3);
      for (std::int32_t c = 0; c < n_used; ++c) verts.row(c) = fine.vertices.row(coarse_to_fine[static_cast<size_t>(c)]);
      for (Eigen::Index f = 0; f < kept_faces.rows(); ++f) {
        for (int k = 0; k < 3; ++k) kept_faces(f, k) = used[static_cast<size_t>(kept_faces(f, k))];
      }
      result.coarse.vertices = std::move(verts);
      result.coarse.triangles = std::move(kept_faces);
      result.coarse_to_fine = std::move(coarse_to_fine);
    }
  }

  // The decimated surface must still be one closed, manifold, consistently oriented solid.
  SurfaceMesh check = result.coarse;
  ValidateOptions strict;
  strict.weld_tolerance = 0.0;
  const SurfaceReport report = validateSurface(check, strict);
  if (!report.ok() || report.reoriented_faces != 0 || report.flipped_inside_out || report.removed_degenerate_faces != 0 ||
      report.removed_duplicate_faces != 0 || report.welded_vertices != 0) {
    throw RigBuildError("decimation to " + std::to_string(options.target_vertices) + " vertices broke the surface (" +
                        report.summary() + (report.ok() ? "" : ": " + report.refusals.front()) +
                        "): try a different vertex target");
  }
  return result;
}

}  // namespace tetrig::rigbuild
