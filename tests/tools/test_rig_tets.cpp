// Tets fit for deformation (tools/rigbuild: decimate_surface, tet_quality, tetrahedralize_surface):
// the tet quality measures on tets whose values are known, the decimation's edge-length and
// aspect-ratio guards on a long cylinder (the shape quadric decimation ruins), the progressive
// decimator, the tet-vertex budget shared between the surface and TetGen's interior points, and
// surface selections reaching the interior points (extendSelectionInward). Generated shapes only.
#include "tetrig/rigbuild/decimate_surface.hpp"
#include "tetrig/rigbuild/tet_quality.hpp"
#include "tetrig/rigbuild/tetrahedralize_surface.hpp"
#include "tetrig/rigbuild/validate_surface.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <set>
#include <string>
#include <vector>

namespace tetrig::rigbuild {
namespace {

#define EXPECT_CONTAINS(haystack, needle) \
  EXPECT_NE(std::string(haystack).find(needle), std::string::npos) << "text: " << (haystack)

TetMesh singleTet(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c, const Eigen::Vector3d& d) {
  TetMesh m;
  m.vertices.resize(4, 3);
  m.vertices << a.transpose(), b.transpose(), c.transpose(), d.transpose();
  m.tets.resize(1, 4);
  m.tets << 0, 1, 2, 3;
  return m;
}

TEST(TetQuality, KnownTets) {
  // Regular tet (alternate corners of a cube): radius ratio 1, every dihedral angle acos(1/3).
  const TetMesh regular = singleTet({1, 1, 1}, {1, -1, -1}, {-1, 1, -1}, {-1, -1, 1});
  EXPECT_NEAR(tetRadiusRatio(regular, 0), 1.0, 1e-12);
  const TetQuality rq = tetQuality(regular);
  EXPECT_EQ(rq.tets, 1);
  EXPECT_NEAR(rq.min_dihedral_degrees, std::acos(1.0 / 3.0) * 180.0 / M_PI, 1e-9);
  EXPECT_NEAR(rq.max_dihedral_degrees, std::acos(1.0 / 3.0) * 180.0 / M_PI, 1e-9);
  // Corner tet (0, e1, e2, e3): three right dihedral angles on the axes, three of acos(1/sqrt 3)
  // at the slanted face; r = 1 / (3 + sqrt 3), R = sqrt 3 / 2.
  const TetMesh corner = singleTet({0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1});
  const TetQuality cq = tetQuality(corner);
  EXPECT_NEAR(cq.min_dihedral_degrees, std::acos(1.0 / std::sqrt(3.0)) * 180.0 / M_PI, 1e-9);
  EXPECT_NEAR(cq.max_dihedral_degrees, 90.0, 1e-9);
  EXPECT_NEAR(tetRadiusRatio(corner, 0), 3.0 * (1.0 / (3.0 + std::sqrt(3.0))) / (std::sqrt(3.0) / 2.0), 1e-12);
  // The orientation does not matter (the measures are of the shape).
  const TetMesh flipped = singleTet({0, 0, 0}, {0, 1, 0}, {1, 0, 0}, {0, 0, 1});
  EXPECT_NEAR(tetRadiusRatio(flipped, 0), tetRadiusRatio(corner, 0), 1e-12);
  EXPECT_NEAR(tetQuality(flipped).min_dihedral_degrees, cq.min_dihedral_degrees, 1e-9);
  // A sliver (four corners of a square, one lifted by 1e-3) and a needle (apex far away): near 0.
  const TetMesh sliver = singleTet({0, 0, 0}, {1, 0, 0}, {1, 1, 1e-3}, {0, 1, 0});
  EXPECT_LT(tetRadiusRatio(sliver, 0), 0.01);
  EXPECT_LT(tetQuality(sliver).min_dihedral_degrees, 1.0);
  EXPECT_GT(tetQuality(sliver).max_dihedral_degrees, 179.0);
  const TetMesh needle = singleTet({0, 0, 0}, {0.1, 0, 0}, {0, 0.1, 0}, {0, 0, 50});
  EXPECT_LT(tetRadiusRatio(needle, 0), 0.02);
  // Degenerate (coplanar): 0, never NaN.
  const TetMesh flat = singleTet({0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0});
  EXPECT_EQ(tetRadiusRatio(flat, 0), 0.0);
  // A range leaves the other tets out; the median of [1, sliver] picks one of them.
  TetMesh two = regular;
  two.vertices.conservativeResize(8, 3);
  two.vertices.bottomRows(4) = sliver.vertices;
  two.tets.resize(2, 4);
  two.tets << 0, 1, 2, 3, 4, 5, 6, 7;
  const TetQuality both = tetQuality(two);
  EXPECT_EQ(both.tets, 2);
  EXPECT_EQ(both.below_0_1, 1);
  EXPECT_LT(both.min_radius_ratio, 0.01);
  const TetQuality first = tetQuality(two, 0, 1);
  EXPECT_EQ(first.tets, 1);
  EXPECT_EQ(first.below_0_1, 0);
  EXPECT_NEAR(first.min_radius_ratio, 1.0, 1e-12);
  EXPECT_CONTAINS(both.summary(), "1 of 2 below 0.1");
}

// A capped cylinder of radius 1 along z, `segments` around, `rings` rings over [0, length]; the
// caps are fans around a centre vertex. Outward, closed, genus 0. Thin triangles along z when
// rings are sparse, like the survey's cylinder.off (240 x 20).
SurfaceMesh cylinder(int segments, int rings, double length) {
  SurfaceMesh m;
  const int n = segments * rings + 2;
  m.vertices.resize(n, 3);
  for (int r = 0; r < rings; ++r) {
    for (int s = 0; s < segments; ++s) {
      const double a = 2.0 * M_PI * s / segments;
      m.vertices.row(r * segments + s) << std::cos(a), std::sin(a), length * r / (rings - 1);
    }
  }
  const int bottom = n - 2, top = n - 1;
  m.vertices.row(bottom) << 0, 0, 0;
  m.vertices.row(top) << 0, 0, length;
  std::vector<std::array<int, 3>> tris;
  auto at = [segments](int r, int s) { return r * segments + (s % segments); };
  for (int r = 0; r + 1 < rings; ++r) {
    for (int s = 0; s < segments; ++s) {
      tris.push_back({at(r, s), at(r, s + 1), at(r + 1, s + 1)});
      tris.push_back({at(r, s), at(r + 1, s + 1), at(r + 1, s)});
    }
  }
  for (int s = 0; s < segments; ++s) {
    tris.push_back({bottom, at(0, s + 1), at(0, s)});
    tris.push_back({top, at(rings - 1, s), at(rings - 1, s + 1)});
  }
  m.triangles.resize(static_cast<Eigen::Index>(tris.size()), 3);
  for (size_t f = 0; f < tris.size(); ++f) m.triangles.row(static_cast<Eigen::Index>(f)) << tris[f][0], tris[f][1], tris[f][2];
  return m;
}

TEST(DecimateSurface, EdgeBoundKeepsALongCylinderFromCollapsingIntoNeedles) {
  const SurfaceMesh fine = cylinder(96, 49, 12.0);
  SurfaceMesh copy = fine;
  const SurfaceReport check = validateSurface(copy);
  ASSERT_TRUE(check.ok()) << check.summary();
  ASSERT_GT(signedVolume(fine), 0.0);

  DecimateOptions guarded;
  guarded.target_vertices = 300;
  const DecimationResult d = decimateSurface(fine, guarded);
  EXPECT_EQ(d.coarse.vertexCount(), 300);
  EXPECT_TRUE(surfaceTopology(d.coarse).closedManifold());
  EXPECT_EQ(d.coarse.triangleCount(), 2 * d.coarse.vertexCount() - 4);
  ASSERT_EQ(static_cast<std::int32_t>(d.coarse_to_fine.size()), d.coarse.vertexCount());
  for (std::int32_t c = 0; c < d.coarse.vertexCount(); ++c) {
    EXPECT_EQ(d.coarse.vertices.row(c), fine.vertices.row(d.coarse_to_fine[static_cast<size_t>(c)]));
  }
  EXPECT_TRUE(std::is_sorted(d.coarse_to_fine.begin(), d.coarse_to_fine.end()));  // fine order kept
  // h = sqrt(2 A / (sqrt 3 V)) for the cylinder's area A = 2 pi r l + 2 pi r^2 (up to the
  // polygon's approximation), and no edge longer than the bound finally used.
  const double area = 2.0 * M_PI * 12.0 + 2.0 * M_PI;
  EXPECT_NEAR(d.even_edge_length, std::sqrt(2.0 * area / (std::sqrt(3.0) * 300)), 0.01 * d.even_edge_length);
  EXPECT_NEAR(d.edge_bound, guarded.max_edge_factor * d.even_edge_length * std::pow(1.25, d.relaxations), 1e-12);
  EXPECT_LE(d.longest_edge, d.edge_bound + 1e-12);
  EXPECT_LT(d.longest_edge, 0.12 * 12.0);

  // The same decimation without the guards (no edge bound, any aspect): pure quadric error keeps
  // a few rings, so its triangles run along most of the length (the defect the guards fix).
  DecimateOptions unguarded = guarded;
  unguarded.max_edge_factor = 1e9;
  unguarded.max_aspect = 1e9;
  const DecimationResult u = decimateSurface(fine, unguarded);
  EXPECT_EQ(u.coarse.vertexCount(), 300);
  EXPECT_GT(u.longest_edge, 0.5 * 12.0);
  EXPECT_GT(u.worst_aspect, 10.0 * d.worst_aspect);

  // Tetrahedralized (TetGen, quality bound): the guarded surface gives tets of a usable shape.
  const TetrahedralizeResult t = tetrahedralizeSurface(d.coarse);
  const TetQuality q = tetQuality(t.mesh);
  EXPECT_GT(q.median_radius_ratio, 0.5) << q.summary();
  EXPECT_GT(q.min_radius_ratio, 0.005) << q.summary();
  EXPECT_GT(t.interior_vertices, 0);
  std::printf("[ measured ] cylinder 96 x 49 -> 300: guarded longest edge %.3g (bound %.3g, %d relaxations), worst aspect %.3g; "
              "unguarded longest edge %.3g, worst aspect %.3g; tets: %s\n",
              d.longest_edge, d.edge_bound, d.relaxations, d.worst_aspect, u.longest_edge, u.worst_aspect, q.summary().c_str());
}

TEST(DecimateSurface, ProgressiveDecimatorContinuesAndNeverGrows) {
  const SurfaceMesh fine = cylinder(48, 25, 6.0);
  SurfaceDecimator decimator(fine, {});
  const DecimationResult a = decimator.decimateTo(400);
  const DecimationResult b = decimator.decimateTo(250);
  EXPECT_EQ(a.coarse.vertexCount(), 400);
  EXPECT_EQ(b.coarse.vertexCount(), 250);
  EXPECT_TRUE(surfaceTopology(b.coarse).closedManifold());
  // Continued from the first result: every vertex kept at 250 was kept at 400.
  const std::set<std::int32_t> kept_a(a.coarse_to_fine.begin(), a.coarse_to_fine.end());
  for (const std::int32_t v : b.coarse_to_fine) EXPECT_TRUE(kept_a.count(v)) << "fine vertex " << v;
  // The edge bound follows the target.
  EXPECT_GT(b.even_edge_length, a.even_edge_length);
  try {
    (void)decimator.decimateTo(300);
    FAIL() << "no exception";
  } catch (const RigBuildError& e) {
    EXPECT_CONTAINS(e.what(), "cannot grow back from 250 to 300");
  }
  // A surface already within the target comes back unchanged.
  SurfaceDecimator small(fine, {});
  const DecimationResult same = small.decimateTo(fine.vertexCount());
  EXPECT_EQ(same.coarse.vertices, fine.vertices);
  EXPECT_EQ(same.coarse.triangles, fine.triangles);
  DecimateOptions bad;
  bad.max_aspect = 0.5;
  EXPECT_THROW(SurfaceDecimator(fine, bad), RigBuildError);
}

TEST(BuildCoarseTetMesh, BudgetCountsTetGensInteriorPoints) {
  const SurfaceMesh fine = cylinder(96, 49, 12.0);
  DecimateOptions d;
  d.target_vertices = 500;
  const CoarseRig rig = buildCoarseTetMesh(fine, d);
  const std::int32_t total = rig.tets.mesh.vertexCount();
  EXPECT_LE(total, 515);  // within 3 % above the budget
  EXPECT_GE(total, 450);
  EXPECT_GT(rig.tets.interior_vertices, 0);
  EXPECT_EQ(total, rig.decimation.coarse.vertexCount() + rig.tets.interior_vertices);
  EXPECT_LT(rig.decimation.coarse.vertexCount(), 500);  // the surface got less than the whole budget
  EXPECT_GT(rig.budget_rounds, 1);
  EXPECT_EQ(rig.used_target, 500);
  EXPECT_TRUE(checkTetMesh(rig.tets.mesh).ok());
  // Surface tet vertices are fine vertices at the same place; interior ones map to none.
  for (size_t v = 0; v < rig.tet_to_fine.size(); ++v) {
    const std::int32_t f = rig.tet_to_fine[v];
    if (static_cast<std::int32_t>(v) < rig.decimation.coarse.vertexCount()) {
      ASSERT_GE(f, 0);
      EXPECT_EQ(rig.tets.mesh.vertices.row(static_cast<Eigen::Index>(v)), fine.vertices.row(f));
    } else {
      EXPECT_EQ(f, -1);
    }
  }
  // Without a quality bound ("pQY": the surface alone, as before) the same budget gives tets
  // spanning the whole cylinder: measured median radius ratio below 0.2.
  TetrahedralizeOptions surface_only;
  surface_only.switches = "pQY";
  const CoarseRig old = buildCoarseTetMesh(fine, d, surface_only);
  const TetQuality q = tetQuality(rig.tets.mesh), q_old = tetQuality(old.tets.mesh);
  EXPECT_GT(q.median_radius_ratio, 2.0 * q_old.median_radius_ratio) << q.summary() << " | " << q_old.summary();
  std::printf("[ measured ] budget 500: %d tet vertices (%d surface + %d interior, %d rounds), %s; surface only: %s\n", total,
              rig.decimation.coarse.vertexCount(), rig.tets.interior_vertices, rig.budget_rounds, q.summary().c_str(),
              q_old.summary().c_str());
}

// A unit cube's 8 corners (surface) and its centre (interior), 12 tets from the centre to the
// 12 boundary triangles.
TetMesh cubeWithCentre() {
  TetMesh m;
  m.vertices.resize(9, 3);
  for (int i = 0; i < 8; ++i) m.vertices.row(i) << (i & 1), (i >> 1) & 1, (i >> 2) & 1;
  m.vertices.row(8) << 0.5, 0.5, 0.5;
  const int faces[12][3] = {{0, 2, 3}, {0, 3, 1}, {4, 5, 7}, {4, 7, 6}, {0, 1, 5}, {0, 5, 4},
                            {2, 6, 7}, {2, 7, 3}, {0, 4, 6}, {0, 6, 2}, {1, 3, 7}, {1, 7, 5}};
  m.tets.resize(12, 4);
  for (int f = 0; f < 12; ++f) m.tets.row(f) << faces[f][0], faces[f][1], faces[f][2], 8;
  return m;
}

TEST(ExtendSelectionInward, InteriorPointsJoinTheVolumeTheSurfaceSelects) {
  const TetMesh cube = cubeWithCentre();
  std::vector<std::uint8_t> is_surface(9, 1);
  is_surface[8] = 0;
  auto run = [&](std::vector<int> selected) {
    std::vector<std::uint8_t> mask(9, 0);
    for (const int v : selected) mask[static_cast<size_t>(v)] = 1;
    extendSelectionInward(cube, is_surface, mask);
    return mask;
  };
  // Every surface vertex selected: the centre's neighbours are all selected (rule a).
  EXPECT_EQ(run({0, 1, 2, 3, 4, 5, 6, 7})[8], 1);
  // The top face (z = 1: vertices 4..7): the centre stands under its triangles (rule b).
  const std::vector<std::uint8_t> top = run({4, 5, 6, 7});
  EXPECT_EQ(top[8], 1);
  for (int v = 0; v < 4; ++v) EXPECT_EQ(top[static_cast<size_t>(v)], 0) << v;  // surface vertices never change
  // One edge of the cube (two vertices): no triangle of three selected corners, unselected
  // neighbours: the centre stays out.
  EXPECT_EQ(run({4, 5})[8], 0);
  // Three vertices that are not one of the 12 triangles (4, 5 and 2): still out.
  EXPECT_EQ(run({4, 5, 2})[8], 0);
  // Nothing selected: nothing joins.
  EXPECT_EQ(run({})[8], 0);
  std::vector<std::uint8_t> wrong(3, 0);
  EXPECT_THROW(extendSelectionInward(cube, is_surface, wrong), RigBuildError);
}

TEST(ExtendSelectionInward, ChainsOfInteriorPointsJoinOnlyWhenEnclosed) {
  // The cylinder's tet mesh at a small budget: select the surface vertices with z >= 8 (the top
  // third and its cap). Interior points join by rule (a) or (b) only: each joined one is either
  // the apex of a tet on three selected surface vertices, or has only selected neighbours.
  const SurfaceMesh fine = cylinder(48, 25, 12.0);
  DecimateOptions d;
  d.target_vertices = 400;
  const CoarseRig rig = buildCoarseTetMesh(fine, d);
  const TetMesh& m = rig.tets.mesh;
  std::vector<std::uint8_t> is_surface(static_cast<size_t>(m.vertexCount()), 0), mask(is_surface.size(), 0);
  for (std::int32_t v = 0; v < m.vertexCount(); ++v) {
    is_surface[static_cast<size_t>(v)] = rig.tet_to_fine[static_cast<size_t>(v)] >= 0 ? 1 : 0;
    if (is_surface[static_cast<size_t>(v)] && m.vertices(v, 2) >= 8.0) mask[static_cast<size_t>(v)] = 1;
  }
  const std::vector<std::uint8_t> before = mask;
  extendSelectionInward(m, is_surface, mask);
  std::vector<std::set<std::int32_t>> neighbours(static_cast<size_t>(m.vertexCount()));
  std::vector<char> apex(static_cast<size_t>(m.vertexCount()), 0);
  for (std::int32_t t = 0; t < m.tetCount(); ++t) {
    int selected_surface = 0;
    std::int32_t inner = -1;
    for (int i = 0; i < 4; ++i) {
      const std::int32_t v = m.tets(t, i);
      if (is_surface[static_cast<size_t>(v)]) {
        selected_surface += before[static_cast<size_t>(v)];
      } else {
        inner = v;
      }
      for (int j = 0; j < 4; ++j) {
        if (i != j) neighbours[static_cast<size_t>(v)].insert(m.tets(t, j));
      }
    }
    if (selected_surface == 3 && inner >= 0) apex[static_cast<size_t>(inner)] = 1;
  }
  int joined = 0, interior = 0;
  for (std::int32_t v = 0; v < m.vertexCount(); ++v) {
    if (is_surface[static_cast<size_t>(v)]) {
      EXPECT_EQ(mask[static_cast<size_t>(v)], before[static_cast<size_t>(v)]);
      continue;
    }
    ++interior;
    if (apex[static_cast<size_t>(v)]) {
      EXPECT_EQ(mask[static_cast<size_t>(v)], 1) << "apex " << v;
    }
    if (!mask[static_cast<size_t>(v)]) continue;
    ++joined;
    bool enclosed = true;
    for (const std::int32_t w : neighbours[static_cast<size_t>(v)]) enclosed = enclosed && mask[static_cast<size_t>(w)];
    EXPECT_TRUE(apex[static_cast<size_t>(v)] || enclosed) << "interior vertex " << v << " at z " << m.vertices(v, 2);
    EXPECT_GT(m.vertices(v, 2), 6.0) << "interior vertex " << v << " joined far below the selection";
  }
  EXPECT_GT(joined, 0);
  EXPECT_LT(joined, interior);
}

}  // namespace
}  // namespace tetrig::rigbuild
