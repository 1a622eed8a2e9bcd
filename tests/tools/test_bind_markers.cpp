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
}

}  // namespace
}  // namespace tetrig::rigbuild
