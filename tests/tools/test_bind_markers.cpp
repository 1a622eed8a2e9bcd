// Markers bound by invisible tets (tools/rigbuild/bind_markers.cpp): the nearest faces, or a tripod
// spread over the marker's footprint (MarkerBindOptions::face_spread).
#include "scenes.hpp"
#include "tetrig/rigbuild/bind_markers.hpp"
#include "tetrig/rigbuild/rig_description.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include <algorithm>
#include <exception>
#include <limits>
#include <string>
#include <vector>

namespace tetrig::rigbuild {
namespace {

// The invisible tets' corners of marker m (its tet vertex is the last corner).
std::vector<Eigen::Vector4i> invisibleTets(const MarkerBindResult& bound, std::int32_t body_tets, std::int32_t marker_vertex) {
  std::vector<Eigen::Vector4i> tets;
  for (Eigen::Index t = body_tets; t < bound.mesh.tets.rows(); ++t)
    if (bound.mesh.tets(t, 3) == marker_vertex) tets.push_back(bound.mesh.tets.row(t).transpose());
  return tets;
}

double signedVolume(const TetMesh& mesh, const Eigen::Vector4i& t) {
  const Eigen::Vector3d a = mesh.vertices.row(t[0]), b = mesh.vertices.row(t[1]), c = mesh.vertices.row(t[2]),
                        d = mesh.vertices.row(t[3]);
  return (b - a).cross(c - a).dot(d - a) / 6.0;
}

// The smallest distance between the centroids of a marker's bound faces.
double closestFaceCentroids(const TetMesh& mesh, const std::vector<Eigen::Vector4i>& tets) {
  double closest = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < tets.size(); ++i)
    for (std::size_t j = i + 1; j < tets.size(); ++j) {
      Eigen::Vector3d gi = Eigen::Vector3d::Zero(), gj = Eigen::Vector3d::Zero();
      for (int c = 0; c < 3; ++c) {
        gi += mesh.vertices.row(tets[i][c]).transpose() / 3.0;
        gj += mesh.vertices.row(tets[j][c]).transpose() / 3.0;
      }
      closest = std::min(closest, (gi - gj).norm());
    }
  return closest;
}

// A marker 4 cells above the middle of a 12 x 12 x 2 slab (cells of 1): the nearest three faces
// sit within one cell of each other (the tets are needles); spread over a footprint of its height
// they stand at least 2 cells apart, inside the footprint, and every tet stays positive. A marker
// near the skin (0.3 cells) keeps three faces with the spread on.
TEST(BindMarkers, FaceSpreadGivesATripodInsteadOfNeedles) {
  const TetMesh slab = scenes::makeBar(12, 12, 2);
  const auto body_tets = static_cast<std::int32_t>(slab.tetCount());
  const std::vector<Eigen::Vector3d> markers{{6.2, 5.9, 6.0}, {3.3, 8.4, 2.3}};
  const std::vector<std::string> labels{"HIGH", "LOW"};
  MarkerBindOptions nearest;
  MarkerBindOptions spread;
  spread.face_spread = 1.0;
  const MarkerBindResult a = bindMarkers(slab, markers, labels, nearest);
  const MarkerBindResult b = bindMarkers(slab, markers, labels, spread);
  ASSERT_EQ(a.bindings.size(), 2u);
  ASSERT_EQ(b.bindings.size(), 2u);
  for (int m = 0; m < 2; ++m) {
    EXPECT_EQ(a.bindings[static_cast<std::size_t>(m)].bound_faces, 3) << labels[static_cast<std::size_t>(m)];
    EXPECT_EQ(b.bindings[static_cast<std::size_t>(m)].bound_faces, 3) << labels[static_cast<std::size_t>(m)];
    for (const MarkerBindResult* r : {&a, &b})
      for (const Eigen::Vector4i& t : invisibleTets(*r, body_tets, r->bindings[static_cast<std::size_t>(m)].tet_vertex))
        EXPECT_GT(signedVolume(r->mesh, t), 1e-3) << labels[static_cast<std::size_t>(m)];
  }
  const std::int32_t high = a.bindings[0].tet_vertex;
  const auto needles = invisibleTets(a, body_tets, high);
  const auto tripod = invisibleTets(b, body_tets, high);
  ASSERT_EQ(needles.size(), 3u);
  ASSERT_EQ(tripod.size(), 3u);
  EXPECT_LT(closestFaceCentroids(a.mesh, needles), 1.0);
  EXPECT_GT(closestFaceCentroids(b.mesh, tripod), 2.0);
  const Eigen::Vector3d foot(6.2, 5.9, 2.0);  // the marker's closest point on the slab's top
  for (const Eigen::Vector4i& t : tripod) {
    Eigen::Vector3d g = Eigen::Vector3d::Zero();
    for (int c = 0; c < 3; ++c) g += b.mesh.vertices.row(t[c]).transpose() / 3.0;
    EXPECT_LE((g - foot).norm(), 4.0 + 1e-9);  // face_spread 1 x the height
    EXPECT_NEAR(g.z(), 2.0, 1e-12);            // on the top face, where the marker looks
  }
  // The body is untouched and the marker vertices come after it.
  EXPECT_EQ(b.mesh.vertices.topRows(slab.vertexCount()), slab.vertices);
  EXPECT_EQ(b.mesh.tets.topRows(body_tets), slab.tets);
}

// A fan (MarkerBindOptions::fan_spread): the marker 4 cells above the slab joins a ring of surface
// vertices spread over its footprint, with every tet positive and well shaped (no needle: the
// marker stands at least half a base edge over each base). With fan_weight 1 the fan's weight
// (scale * volume) equals that of the three nearest faces' needles; with fan_weight 0 the fan keeps its
// own volume (scale 1). A marker below the skin keeps the faces binding.
TEST(BindMarkers, FanSpreadsAMarkerOverItsFootprint) {
  const TetMesh slab = scenes::makeBar(12, 12, 2);
  const auto body_tets = static_cast<std::int32_t>(slab.tetCount());
  const std::vector<Eigen::Vector3d> markers{{6.2, 5.9, 6.0}, {3.3, 8.4, 1.5}};
  const std::vector<std::string> labels{"HIGH", "INSIDE"};
  MarkerBindOptions fan;
  fan.fan_spread = 1.0;
  const MarkerBindResult needles = bindMarkers(slab, markers, labels, MarkerBindOptions{});
  const MarkerBindResult b = bindMarkers(slab, markers, labels, fan);
  ASSERT_EQ(b.bindings.size(), 2u);
  ASSERT_EQ(b.invisible_scale.size(), static_cast<std::size_t>(b.invisible_tets));
  const std::int32_t high = b.bindings[0].tet_vertex;
  const auto tets = invisibleTets(b, body_tets, high);
  ASSERT_GE(tets.size(), 4u);
  EXPECT_EQ(b.bindings[0].bound_faces, static_cast<std::int32_t>(tets.size()));
  const Eigen::Vector3d foot(6.2, 5.9, 2.0);
  double reach = 0.0, fan_weight = 0.0;
  for (const Eigen::Vector4i& t : tets) {
    EXPECT_GT(signedVolume(b.mesh, t), 0.5);
    for (int c = 0; c < 3; ++c) {
      const Eigen::Vector3d q = b.mesh.vertices.row(t[c]);
      EXPECT_NEAR(q.z(), 2.0, 1e-12);  // on the top face, where the marker looks
      EXPECT_LE((q - foot).norm(), 4.0 + 1e-9);
      reach = std::max(reach, (q - foot).norm());
    }
  }
  EXPECT_GT(reach, 3.0);  // spread to the footprint's edge, not the nearest cell
  double needle_weight = 0.0;
  for (const Eigen::Vector4i& t : invisibleTets(needles, body_tets, needles.bindings[0].tet_vertex))
    needle_weight += signedVolume(needles.mesh, t);
  for (Eigen::Index t = body_tets; t < b.mesh.tets.rows(); ++t)
    if (b.mesh.tets(t, 3) == high)
      fan_weight += b.invisible_scale[static_cast<std::size_t>(t - body_tets)] * signedVolume(b.mesh, b.mesh.tets.row(t).transpose());
  EXPECT_NEAR(fan_weight, needle_weight, 1e-9 * needle_weight);
  EXPECT_LT(b.invisible_scale[static_cast<std::size_t>(tets.size()) - 1], 0.5);  // the fan is far bigger than the needles
  // The marker inside the slab: the reversed nearest faces, scale 1.
  EXPECT_TRUE(b.bindings[1].below_skin);
  EXPECT_EQ(b.bindings[1].bound_faces, 3);
  for (std::size_t i = tets.size(); i < b.invisible_scale.size(); ++i) EXPECT_EQ(b.invisible_scale[i], 1.0);
  fan.fan_weight = 0.0;
  const MarkerBindResult own = bindMarkers(slab, markers, labels, fan);
  for (const double s : own.invisible_scale) EXPECT_EQ(s, 1.0);
}

// The rig description's markers.face_spread: read, range-checked with its path.
TEST(BindMarkers, TheDescriptionReadsAndChecksFaceSpread) {
  EXPECT_EQ(parseRigDescription(R"({"markers": {"face_spread": 1.5}})", "r.json").markers.face_spread, 1.5);
  EXPECT_EQ(parseRigDescription("{}", "r.json").markers.face_spread, 0.0);
  for (const char* bad : {"-0.5", "101", "\"wide\""}) {
    try {
      (void)parseRigDescription(std::string(R"({"markers": {"face_spread": )") + bad + "}}", "r.json");
      ADD_FAILURE() << bad << " accepted";
    } catch (const std::exception& e) {
      EXPECT_NE(std::string(e.what()).find("markers.face_spread"), std::string::npos) << e.what();
    }
  }
  const RigDescription fan = parseRigDescription(R"({"markers": {"fan_spread": 1, "fan_spokes": 8, "fan_weight": 0}})", "r.json");
  EXPECT_EQ(fan.markers.fan_spread, 1.0);
  EXPECT_EQ(fan.markers.fan_spokes, 8);
  EXPECT_EQ(fan.markers.fan_weight, 0.0);
  for (const char* bad : {R"("fan_spread": -1)", R"("fan_spokes": 2)", R"("fan_weight": -1)"}) {
    try {
      (void)parseRigDescription(std::string(R"({"markers": {)") + bad + "}}", "r.json");
      ADD_FAILURE() << bad << " accepted";
    } catch (const std::exception& e) {
      EXPECT_NE(std::string(e.what()).find("markers.fan_"), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace tetrig::rigbuild
