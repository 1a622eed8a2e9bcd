// Decimation, tetrahedralization and pose-transfer weights of the rig builder, on generated
// shapes and on the real meshes of ../shared/data (NOTES.md section 1).
#include "tetrig/rigbuild/decimate_surface.hpp"
#include "tetrig/rigbuild/import_surface.hpp"
#include "tetrig/rigbuild/pose_transfer_weights.hpp"
#include "tetrig/rigbuild/rig_geometry.hpp"
#include "tetrig/rigbuild/tetrahedralize_surface.hpp"
#include "tetrig/rigbuild/validate_surface.hpp"
#include "temp_dir.hpp"
#include "test_data.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

namespace tetrig::rigbuild {
namespace {

#define EXPECT_CONTAINS(haystack, needle) \
  EXPECT_NE(std::string(haystack).find(needle), std::string::npos) << "text: " << (haystack)

// UV sphere: closed, genus 0, outward.
SurfaceMesh sphere(int rings, int segments, double radius = 1.0) {
  SurfaceMesh m;
  const int n = 2 + (rings - 1) * segments;
  m.vertices.resize(n, 3);
  m.vertices.row(0) << 0, 0, radius;
  m.vertices.row(n - 1) << 0, 0, -radius;
  for (int r = 1; r < rings; ++r) {
    const double theta = M_PI * r / rings;
    for (int s = 0; s < segments; ++s) {
      const double phi = 2 * M_PI * s / segments;
      m.vertices.row(1 + (r - 1) * segments + s) << radius * std::sin(theta) * std::cos(phi),
          radius * std::sin(theta) * std::sin(phi), radius * std::cos(theta);
    }
  }
  std::vector<std::array<int, 3>> tris;
  auto at = [segments](int r, int s) { return 1 + (r - 1) * segments + (s % segments); };
  for (int s = 0; s < segments; ++s) tris.push_back({0, at(1, s), at(1, s + 1)});
  for (int r = 1; r < rings - 1; ++r) {
    for (int s = 0; s < segments; ++s) {
      tris.push_back({at(r, s), at(r + 1, s), at(r + 1, s + 1)});
      tris.push_back({at(r, s), at(r + 1, s + 1), at(r, s + 1)});
    }
  }
  for (int s = 0; s < segments; ++s) tris.push_back({n - 1, at(rings - 1, s + 1), at(rings - 1, s)});
  m.triangles.resize(static_cast<Eigen::Index>(tris.size()), 3);
  for (size_t f = 0; f < tris.size(); ++f) m.triangles.row(static_cast<Eigen::Index>(f)) << tris[f][0], tris[f][1], tris[f][2];
  return m;
}

TEST(DecimateSurface, SphereToBudgetStaysClosedAndUsesFineVertices) {
  SurfaceMesh fine = sphere(40, 60);
  ASSERT_TRUE(validateSurface(fine).ok());
  DecimateOptions options;
  options.target_vertices = 300;
  const DecimationResult d = decimateSurface(fine, options);
  EXPECT_NEAR(d.coarse.vertexCount(), 300, 300 * 0.1);
  EXPECT_TRUE(surfaceTopology(d.coarse).closedManifold());
  EXPECT_EQ(d.coarse.triangleCount(), 2 * d.coarse.vertexCount() - 4);  // Euler: genus 0
  ASSERT_EQ(static_cast<std::int32_t>(d.coarse_to_fine.size()), d.coarse.vertexCount());
  for (std::int32_t c = 0; c < d.coarse.vertexCount(); ++c) {
    EXPECT_EQ(d.coarse.vertices.row(c), fine.vertices.row(d.coarse_to_fine[static_cast<size_t>(c)]));
  }
  EXPECT_GT(signedVolume(d.coarse), 0.0);
  // A sphere keeps most of its volume (4/3 pi) at 300 vertices.
  EXPECT_GT(signedVolume(d.coarse), 0.9 * 4.0 / 3.0 * M_PI);
}

TEST(DecimateSurface, RefusesOpenInput) {
  SurfaceMesh open = sphere(10, 12);
  open.triangles.conservativeResize(open.triangleCount() - 1, 3);
  DecimateOptions options;
  options.target_vertices = 50;
  try {
    (void)decimateSurface(open, options);
    FAIL() << "no exception";
  } catch (const RigBuildError& e) {
    EXPECT_CONTAINS(e.what(), "3 boundary");
    EXPECT_CONTAINS(e.what(), "run validateSurface first");
  }
}

TEST(TetrahedralizeSurface, SphereHasOnlyPositiveTetsAndKeepsTheSurface) {
  const SurfaceMesh s = sphere(8, 12);
  const TetrahedralizeResult t = tetrahedralizeSurface(s);
  const TetMeshReport report = checkTetMesh(t.mesh);
  EXPECT_TRUE(report.ok()) << report.summary();
  // "pQY" adds no points ON the surface; it may add a few inside to recover faces of this very
  // degenerate (co-spherical, planar-quad) input. They are mapped to no coarse vertex.
  for (std::int32_t v = s.vertexCount(); v < t.mesh.vertexCount(); ++v) {
    EXPECT_EQ(t.tet_to_coarse[static_cast<size_t>(v)], -1);
    EXPECT_LT(t.mesh.vertices.row(v).norm(), 1.0 - 1e-9);  // strictly inside the unit sphere
  }
  ASSERT_GE(t.mesh.vertexCount(), s.vertexCount());
  for (std::int32_t v = 0; v < s.vertexCount(); ++v) {
    EXPECT_EQ(t.tet_to_coarse[static_cast<size_t>(v)], v);
    EXPECT_EQ(t.mesh.vertices.row(v), s.vertices.row(v));
  }
  // The tets fill exactly the volume the surface encloses.
  double volume = 0.0;
  for (std::int32_t k = 0; k < t.mesh.tetCount(); ++k) volume += tetrig::signedVolume(t.mesh, k);
  EXPECT_NEAR(volume, signedVolume(s), 1e-9);
}

TEST(TetrahedralizeSurface, SelfIntersectingSurfaceIsExplained) {
  // Two spheres overlapping in one vertex list: the surfaces cross each other.
  SurfaceMesh a = sphere(8, 12);
  SurfaceMesh b = sphere(8, 12);
  b.vertices.col(0).array() += 0.5;
  SurfaceMesh both;
  both.vertices.resize(a.vertexCount() + b.vertexCount(), 3);
  both.vertices << a.vertices, b.vertices;
  both.triangles.resize(a.triangleCount() + b.triangleCount(), 3);
  both.triangles << a.triangles, (b.triangles.array() + a.vertexCount()).matrix();
  try {
    (void)tetrahedralizeSurface(both);
    FAIL() << "no exception";
  } catch (const RigBuildError& e) {
    EXPECT_CONTAINS(e.what(), "TetGen");
    EXPECT_CONTAINS(e.what(), "self-intersection");
  }
}

// ---- pose-transfer weights ----

TEST(PoseTransferWeights, SingleTetGivesExactBarycentricCoordinates) {
  TetMesh tet;
  tet.vertices.resize(4, 3);
  tet.vertices << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
  tet.tets.resize(1, 4);
  tet.tets << 0, 1, 2, 3;
  Vertices fine(2, 3);
  fine << 0.1, 0.2, 0.3, 2.0, -1.0, 0.5;  // inside, and outside (extrapolated)
  const auto b = poseTransferWeights(fine, tet);
  const Eigen::MatrixXd dense = b;
  // p = l0 p0 + l1 p1 + l2 p2 + l3 p3 with p0 = 0 and p1..p3 the unit axes: l1..l3 = x, y, z.
  EXPECT_NEAR(dense(0, 0), 0.4, 1e-14);
  EXPECT_NEAR(dense(0, 1), 0.1, 1e-14);
  EXPECT_NEAR(dense(0, 2), 0.2, 1e-14);
  EXPECT_NEAR(dense(0, 3), 0.3, 1e-14);
  EXPECT_NEAR(dense(1, 0), -0.5, 1e-14);
  EXPECT_NEAR(dense(1, 1), 2.0, 1e-14);
  EXPECT_NEAR(dense(1, 2), -1.0, 1e-14);
  EXPECT_NEAR(dense(1, 3), 0.5, 1e-14);
}

TEST(PoseTransferWeights, FallbacksWhenNoBoundaryFaceIsInRange) {
  TetMesh tet;
  tet.vertices.resize(4, 3);
  tet.vertices << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
  tet.tets.resize(1, 4);
  tet.tets << 0, 1, 2, 3;
  Vertices fine(3, 3);
  fine << 0.1, 0.1, 0.1, 5, 5, 5, 0, 0, 0;
  PoseTransferOptions options;
  options.radius_fraction = 1e-6;  // nothing in range (face centres are far from these points)
  PoseTransferStats stats;
  const auto b = poseTransferWeights(fine, tet, options, &stats);
  EXPECT_EQ(stats.fallback_containing, 2);  // (0.1, 0.1, 0.1) and the corner (0, 0, 0)
  EXPECT_EQ(stats.fallback_nearest, 1);     // (5, 5, 5)
  EXPECT_LT(restReconstructionError(b, fine, tet.vertices), 1e-12);
}

// Runs the whole offline chain on a real mesh and checks the properties the runtime relies on.
void checkRig(const std::string& relative, std::int32_t target, bool with_caps) {
  TETRIG_REQUIRE_DATA(path, relative);
  SurfaceMesh fine = importSurface(path);
  const SurfaceReport report = validateSurface(fine);
  ASSERT_TRUE(report.ok()) << report.summary();

  DecimateOptions d;
  d.target_vertices = target;
  const CoarseRig rig = buildCoarseTetMesh(fine, d);
  const TetMesh& tets = rig.tets.mesh;
  const std::int32_t coarse_v = rig.decimation.coarse.vertexCount();
  // The budget is the whole tet mesh: the decimated surface plus TetGen's interior points.
  EXPECT_NEAR(tets.vertexCount(), target, 0.12 * target);
  EXPECT_EQ(tets.vertexCount(), coarse_v + rig.tets.interior_vertices);
  const TetMeshReport check = checkTetMesh(tets);
  EXPECT_TRUE(check.ok()) << check.summary();
  EXPECT_EQ(check.inverted_tets, 0);
  // Every surface tet vertex is a fine vertex at the same place, unless the self-intersection
  // repair moved it (then by at most the reported displacement, which stays small).
  std::vector<char> moved(rig.tet_to_fine.size(), 0);
  for (const std::int32_t v : rig.repair.moved) moved[static_cast<size_t>(v)] = 1;
  const double diagonal = boundingBoxDiagonal(fine.vertices);
  EXPECT_LT(rig.repair.max_displacement, 0.05 * diagonal);  // measured: <= 3.3 % (dragon scales)
  for (size_t v = 0; v < rig.tet_to_fine.size(); ++v) {
    if (rig.tet_to_fine[v] < 0) continue;
    const double distance = (tets.vertices.row(static_cast<Eigen::Index>(v)) - fine.vertices.row(rig.tet_to_fine[v])).norm();
    if (moved[v]) {
      ASSERT_LE(distance, rig.repair.max_displacement + 1e-15);
    } else {
      ASSERT_EQ(distance, 0.0);
    }
  }
  // The tets fill the coarse surface's volume.
  double volume = 0.0;
  for (std::int32_t t = 0; t < tets.tetCount(); ++t) volume += tetrig::signedVolume(tets, t);
  EXPECT_NEAR(volume, signedVolume(rig.decimation.coarse), 1e-9 * std::abs(volume) + 1e-12);

  PoseTransferStats stats;
  const auto b = poseTransferWeights(fine.vertices, tets, {}, &stats);
  ASSERT_EQ(b.rows(), fine.vertexCount());
  ASSERT_EQ(b.cols(), tets.vertexCount());
  const Eigen::VectorXd row_sums = b * Eigen::VectorXd::Ones(b.cols());
  EXPECT_LT((row_sums.array() - 1.0).abs().maxCoeff(), 1e-9);
  EXPECT_LT(restReconstructionError(b, fine.vertices, tets.vertices), 1e-5);
  // Rows sum to 1 and reproduce positions, hence any affine map of the tets moves the fine mesh
  // by the same map.
  Eigen::Matrix3d a = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix() * 1.3;
  const Eigen::RowVector3d shift(0.3, -2.0, 1.0);
  const Vertices moved_tets = (tets.vertices * a.transpose()).rowwise() + shift;
  const Vertices moved_fine = (fine.vertices * a.transpose()).rowwise() + shift;
  EXPECT_LT(restReconstructionError(b, moved_fine, moved_tets), 1e-5);
  EXPECT_GE(stats.mean_nonzeros_per_row, 4.0);
  std::printf("[rig] %s: fine %d V; coarse %d V (target %d, %zu retries, %d folded faces removed, %d intersecting "
              "faces repaired in %d rounds moving %d V by <= %.3g of the diagonal); %d tet V (%d interior), %d tets; "
              "B nnz/row mean %.1f max %d, tets/row %.1f, fallbacks %d+%d, max |coef| %.3g, rest error %.3g\n",
              relative.c_str(), fine.vertexCount(), coarse_v, target, rig.failed_attempts.size(),
              rig.decimation.removed_folded_faces, rig.repair.initial_faces, rig.repair.rounds, rig.repair.moved_vertices,
              rig.repair.max_displacement / diagonal, tets.vertexCount(),
              rig.tets.interior_vertices, tets.tetCount(), stats.mean_nonzeros_per_row, stats.max_nonzeros_per_row,
              stats.mean_tets_per_row, stats.fallback_containing, stats.fallback_nearest, stats.max_abs_coefficient,
              restReconstructionError(b, fine.vertices, tets.vertices));

  if (!with_caps) return;
  // A non-affine pose of the tets (twist about the y axis growing with y) to compare capped and
  // uncapped B away from the rest pose (printed, not asserted: there is no reference value).
  Vertices twisted = tets.vertices;
  const double y_min = tets.vertices.col(1).minCoeff();
  const double y_range = tets.vertices.col(1).maxCoeff() - y_min;
  for (Eigen::Index v = 0; v < twisted.rows(); ++v) {
    const double angle = 1.0 * (tets.vertices(v, 1) - y_min) / y_range;
    const double x = tets.vertices(v, 0);
    const double z = tets.vertices(v, 2);
    twisted(v, 0) = std::cos(angle) * x - std::sin(angle) * z;
    twisted(v, 2) = std::sin(angle) * x + std::cos(angle) * z;
  }
  const Eigen::MatrixXd posed = b * twisted;
  for (const WeightCap mode : {WeightCap::kDropFarTets, WeightCap::kDropSmallEntries}) {
    PoseTransferOptions capped;
    capped.max_nonzeros_per_row = 16;
    capped.cap_mode = mode;
    PoseTransferStats cs;
    const auto bc = poseTransferWeights(fine.vertices, tets, capped, &cs);
    EXPECT_LE(cs.max_nonzeros_per_row, 16);
    const Eigen::VectorXd sums = bc * Eigen::VectorXd::Ones(bc.cols());
    EXPECT_LT((sums.array() - 1.0).abs().maxCoeff(), 1e-9);
    const double err = restReconstructionError(bc, fine.vertices, tets.vertices);
    if (mode == WeightCap::kDropFarTets) {
      EXPECT_LT(err, 1e-5);  // whole tets: still exact
    }
    const Eigen::MatrixXd posed_capped = bc * twisted;
    const double pose_difference = (posed_capped - posed).rowwise().norm().maxCoeff() / diagonal;
    std::printf("[rig] %s cap 16 (%s): rest error %.3g of the diagonal, nnz/row %.1f, twisted pose differs from "
                "uncapped B by max %.3g of the diagonal\n", relative.c_str(),
                mode == WeightCap::kDropFarTets ? "drop far tets" : "drop small entries", err,
                cs.mean_nonzeros_per_row, pose_difference);
  }
}

TEST(RigGeometry, KnightInOneCallWithProgress) {
  TETRIG_REQUIRE_DATA(path, "meshes/libigl-tutorial-data/decimated-knight.off");
  RigGeometryOptions options;
  options.decimate.target_vertices = 300;
  int lines = 0;
  const RigGeometry g = buildRigGeometry(path, options, [&lines](const std::string&) { ++lines; });
  EXPECT_EQ(lines, 4);
  EXPECT_EQ(g.fine.vertexCount(), 502);
  EXPECT_TRUE(checkTetMesh(g.coarse.tets.mesh).ok());
  EXPECT_EQ(g.b.rows(), 502);
  EXPECT_EQ(g.b.cols(), g.coarse.tets.mesh.vertexCount());
  EXPECT_LT(g.rest_error, 1e-5);
  // An open surface is refused with the file name and what to do.
  SurfaceMesh open = importSurface(path);
  open.triangles.conservativeResize(open.triangleCount() - 1, 3);
  const tetrig::test::TempDir dir("tetrig-pipeline");  // a fresh private directory (tests/support/temp_dir.hpp)
  const std::filesystem::path open_path = dir / "tetrig_open_knight.off";
  {
    std::ofstream out(open_path);
    out << "OFF\n" << open.vertexCount() << ' ' << open.triangleCount() << " 0\n";
    for (std::int32_t v = 0; v < open.vertexCount(); ++v) out << open.vertices.row(v) << '\n';
    for (std::int32_t f = 0; f < open.triangleCount(); ++f) out << "3 " << open.triangles.row(f) << '\n';
  }
  try {
    (void)buildRigGeometry(open_path, options);
    ADD_FAILURE() << "no exception";
  } catch (const RigBuildError& e) {
    EXPECT_CONTAINS(e.what(), "tetrig_open_knight.off: surface refused");
    EXPECT_CONTAINS(e.what(), "3 boundary edges");
  }
}

TEST(RigPipeline, DecimatedKnight) { checkRig("meshes/libigl-tutorial-data/decimated-knight.off", 300, true); }
TEST(RigPipeline, HumanMan) { checkRig("meshes/odedstein-meshes/human_man.obj", 2500, false); }
TEST(RigPipeline, Dragon) { checkRig("meshes/correspondence/dragon.obj", 2500, false); }
TEST(RigPipeline, Cactus) { checkRig("meshes/deformation-survey/cactus.off", 2000, false); }
TEST(RigPipeline, Cylinder) { checkRig("meshes/deformation-survey/cylinder.off", 2000, false); }
TEST(RigPipeline, Armadillo43k) { checkRig("meshes/libigl-tutorial-data/armadillo.obj", 2500, true); }

}  // namespace
}  // namespace tetrig::rigbuild
