// The tracking measure (tools/rigbuild/tracking_measure.cpp) on the small block rig: each marker's
// skin point is the nearest point of the fine surface at rest, carried by the pose; the measure is
// the change of the marker-to-skin distance, in the device's millimetres, over measured markers only.
#include "small_rig.hpp"
#include "tetrig/rigbuild/closest_point.hpp"
#include "tetrig/rigbuild/tracking_measure.hpp"

#include <gtest/gtest.h>

#include <numeric>

namespace tetrig {
namespace {

using rigbuild::TrackingMeasure;

std::vector<float> restFine(const Rig& rig) {
  std::vector<float> x(static_cast<std::size_t>(rig.fine_vertices.rows()) * 3);
  for (Eigen::Index v = 0; v < rig.fine_vertices.rows(); ++v)
    for (int c = 0; c < 3; ++c) x[static_cast<std::size_t>(v) * 3 + static_cast<std::size_t>(c)] = static_cast<float>(rig.fine_vertices(v, c));
  return x;
}

std::vector<Eigen::Vector3d> restMarkers(const Rig& rig) {
  std::vector<Eigen::Vector3d> m;
  for (const RigMarker& r : rig.markers) m.push_back(rig.tet_mesh.vertices.row(r.tet_vertex).transpose());
  return m;
}

TEST(TrackingMeasure, PercentilesAreNearestRank) {
  std::vector<double> v(100);
  std::iota(v.begin(), v.end(), 1.0);
  std::reverse(v.begin(), v.end());
  const rigbuild::Percentiles p = rigbuild::percentilesOf(v);
  EXPECT_EQ(p.median, 50.0);
  EXPECT_EQ(p.p90, 90.0);
  EXPECT_EQ(p.p99, 99.0);
  EXPECT_EQ(p.max, 100.0);
  EXPECT_EQ(p.count, 100u);
  EXPECT_EQ(rigbuild::percentilesOf({}).count, 0u);
}

TEST(TrackingMeasure, SkinPointsAreTheNearestSurfacePointsAtRest) {
  const test::TempDir dir;
  const Rig rig = test::buildSmallRig(dir);
  ASSERT_GE(rig.markers.size(), 3u);
  const TrackingMeasure t(rig);
  ASSERT_EQ(t.skinPoints().size(), rig.markers.size());
  EXPECT_DOUBLE_EQ(t.mmPerRigUnit(), 1000.0);  // the small rig is in metres
  const rigbuild::SurfaceQuery surface(rig.fine_vertices, rig.fine_triangles);
  for (std::size_t m = 0; m < rig.markers.size(); ++m) {
    const rigbuild::SkinPoint& s = t.skinPoints()[m];
    EXPECT_NEAR(s.a + s.b + s.c, 1.0, 1e-12);
    EXPECT_GE(std::min({s.a, s.b, s.c}), -1e-9);
    const Eigen::Vector3d rest = rig.tet_mesh.vertices.row(rig.markers[m].tet_vertex).transpose();
    EXPECT_NEAR(s.rest_distance, surface.closest(rest).distance, 1e-9);
    EXPECT_GT(s.rest_distance, 0.0);  // the clip's markers sit outside the faces
  }
}

TEST(TrackingMeasure, ZeroWhenTheSkinCarriesTheMarkersAndTheDistanceChangeOtherwise) {
  const test::TempDir dir;
  const Rig rig = test::buildSmallRig(dir);
  const std::size_t n = rig.markers.size();
  TrackingMeasure t(rig);
  // Rest: the markers at their rest positions on the rest mesh.
  std::vector<float> x = restFine(rig);
  std::vector<Eigen::Vector3d> markers = restMarkers(rig);
  std::vector<std::uint8_t> measured(n, 1);
  t.addFrame(x, markers, measured);
  EXPECT_LT(t.all().max, 1e-3);  // float positions: well under a micrometre
  // The same rigid motion of mesh and markers (a rotation about y and a shift): still zero.
  const Eigen::Matrix3d r = Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const Eigen::Vector3d shift(0.5, -0.2, 0.1);
  for (std::size_t i = 0; i < x.size(); i += 3) {
    const Eigen::Vector3d p = r * Eigen::Vector3d(x[i], x[i + 1], x[i + 2]) + shift;
    for (int c = 0; c < 3; ++c) x[i + static_cast<std::size_t>(c)] = static_cast<float>(p[c]);
  }
  for (Eigen::Vector3d& m : markers) m = r * m + shift;
  t.addFrame(x, markers, measured);
  EXPECT_LT(t.all().max, 1e-3);
  // Marker 0 moved 5 mm away from its skin point (along the line to it): 5 mm for that marker.
  // Marker 1 moved 40 mm but not measured: not counted.
  TrackingMeasure moved(rig);
  const std::vector<float> rest = restFine(rig);
  std::vector<Eigen::Vector3d> m2 = restMarkers(rig);
  const rigbuild::SkinPoint& s0 = moved.skinPoints()[0];
  Eigen::Vector3d skin = Eigen::Vector3d::Zero();
  const double w[3] = {s0.a, s0.b, s0.c};
  for (int k = 0; k < 3; ++k) skin += w[k] * rig.fine_vertices.row(rig.fine_triangles(s0.triangle, k)).transpose();
  m2[0] += 0.005 * (m2[0] - skin).normalized();
  m2[1] += Eigen::Vector3d(0.04, 0.0, 0.0);
  std::vector<std::uint8_t> some(n, 1);
  some[1] = 0;
  moved.addFrame(rest, m2, some);
  EXPECT_NEAR(moved.marker(0).max, 5.0, 1e-3);
  EXPECT_EQ(moved.marker(1).count, 0u);
  EXPECT_EQ(moved.all().count, n - 1);
  EXPECT_NEAR(moved.all().max, 5.0, 1e-3);
  // The skin moving instead of the marker counts the same: the whole mesh 3 mm along x, markers
  // still: the distance of every marker changes, by at most 3 mm.
  TrackingMeasure skin_moved(rig);
  std::vector<float> shifted = restFine(rig);
  for (std::size_t i = 0; i < shifted.size(); i += 3) shifted[i] += 0.003f;
  skin_moved.addFrame(shifted, restMarkers(rig), measured);
  EXPECT_GT(skin_moved.all().max, 1.0);
  EXPECT_LE(skin_moved.all().max, 3.0 + 1e-3);
}

}  // namespace
}  // namespace tetrig
