// The live rig (runtime/include/tetrig/live_rig.hpp) and the occlusion prediction
// (marker_prediction.hpp) on a small rig made here: a 2x2x8 bar, its boundary as the fine mesh
// (B = identity rows), twelve markers outside its sides joined to their three nearest boundary
// faces by invisible tets (stiffness 0.1) and driven as vertex handles, device millimetres mapped
// to rig units by a similarity (rotation, 1e-3 scale, shift).
#include "counting_allocator.hpp"
#include "scenes.hpp"
#include "tetrig/live_rig.hpp"
#include "tetrig/marker_prediction.hpp"
#include "tetrig/pose_transfer_blocked.hpp"
#include "tetrig/pose_transfer_padded.hpp"
#include "tetrig/volume_constraint.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <map>
#include <string>
#include <vector>

namespace tetrig {
namespace {

constexpr std::int64_t kPeriodNs = 8'333'333;  // 120 Hz
constexpr int kMarkers = 12;

struct Face {
  std::array<std::int32_t, 3> v{};  // outward (counter-clockwise seen from outside)
};

// The boundary faces of a tet mesh (tetrig::boundaryFaces: outward), as arrays.
std::vector<Face> boundaryFacesOf(const TetMesh& mesh) {
  const Triangles faces = boundaryFaces(mesh);
  std::vector<Face> out(static_cast<std::size_t>(faces.rows()));
  for (Eigen::Index f = 0; f < faces.rows(); ++f)
    for (int k = 0; k < 3; ++k) out[static_cast<std::size_t>(f)].v[static_cast<std::size_t>(k)] = faces(f, k);
  return out;
}

// Rest positions of the twelve markers: four around each of z = 0.5, 4, 7.5, 0.3 off the sides.
std::vector<Eigen::Vector3d> barMarkerPositions() {
  std::vector<Eigen::Vector3d> m;
  for (const double z : {0.5, 4.0, 7.5}) {
    m.emplace_back(-0.3, 1.0, z);
    m.emplace_back(2.3, 1.0, z);
    m.emplace_back(1.0, -0.3, z);
    m.emplace_back(1.0, 2.3, z);
  }
  return m;
}

// The bar rig. `extra_degenerate_triangle` adds three fine vertices at one tet vertex joined by one
// (zero-area) triangle of their own.
Rig makeBarRig(bool extra_degenerate_triangle = false, bool far_region = false) {
  const TetMesh body = scenes::makeBar(2, 2, 8);
  const std::vector<Face> faces = boundaryFacesOf(body);
  const std::vector<Eigen::Vector3d> markers = barMarkerPositions();
  Rig rig;
  rig.name = "bar 2x2x8";
  rig.body_vertex_count = body.vertexCount();
  rig.body_tet_count = body.tetCount();
  const std::int32_t nv = body.vertexCount() + static_cast<std::int32_t>(markers.size());
  rig.tet_mesh.vertices.resize(nv, 3);
  rig.tet_mesh.vertices.topRows(body.vertexCount()) = body.vertices;
  std::vector<std::array<std::int32_t, 4>> invisible;
  for (std::size_t k = 0; k < markers.size(); ++k) {
    const auto mv = static_cast<std::int32_t>(body.vertexCount() + static_cast<std::int32_t>(k));
    rig.tet_mesh.vertices.row(mv) = markers[k].transpose();
    // The three boundary faces with the nearest centres that the marker is not coplanar with.
    std::vector<std::pair<double, std::size_t>> order;
    for (std::size_t f = 0; f < faces.size(); ++f) {
      Eigen::Vector3d centre = Eigen::Vector3d::Zero();
      for (const std::int32_t v : faces[f].v) centre += body.vertices.row(v).transpose() / 3.0;
      order.emplace_back((centre - markers[k]).norm(), f);
    }
    std::sort(order.begin(), order.end());
    int bound = 0;
    for (const auto& [d, f] : order) {
      std::array<std::int32_t, 4> tet{faces[f].v[0], faces[f].v[1], faces[f].v[2], mv};
      const Eigen::Vector3d a = rig.tet_mesh.vertices.row(tet[0]).transpose(), b = rig.tet_mesh.vertices.row(tet[1]).transpose(),
                            c = rig.tet_mesh.vertices.row(tet[2]).transpose();
      const double volume = (b - a).cross(c - a).dot(markers[k] - a) / 6.0;
      if (std::abs(volume) < 0.02) continue;
      if (volume < 0.0) std::swap(tet[0], tet[1]);
      invisible.push_back(tet);
      if (++bound == 3) break;
    }
    RigMarker marker;
    marker.label = "M" + std::to_string(k);
    marker.tet_vertex = mv;
    marker.vertex_handle = static_cast<std::int32_t>(k);
    marker.rest_position = markers[k];
    marker.bound_faces = bound;
    marker.surface_distance = 0.3;
    rig.markers.push_back(marker);
    rig.setup.vertex_handles.push_back(mv);
    rig.vertex_handle_names.push_back(marker.label);
  }
  rig.tet_mesh.tets.resize(body.tetCount() + static_cast<Eigen::Index>(invisible.size()), 4);
  rig.tet_mesh.tets.topRows(body.tetCount()) = body.tets;
  for (std::size_t i = 0; i < invisible.size(); ++i)
    for (int c = 0; c < 4; ++c) rig.tet_mesh.tets(body.tetCount() + static_cast<Eigen::Index>(i), c) = invisible[i][static_cast<std::size_t>(c)];
  if (far_region) {
    // An oriented region handle: the body tets of the last cube layer (z >= 7).
    RegionHandle region;
    for (std::int32_t t = 0; t < body.tetCount(); ++t) {
      bool far = true;
      for (int c = 0; c < 4; ++c) far = far && body.vertices(body.tets(t, c), 2) >= 7.0;
      if (far) region.tets.push_back(t);
    }
    rig.setup.region_handles.push_back(region);
    rig.region_handle_names.push_back("far");
  }
  rig.setup.stiffness.assign(static_cast<std::size_t>(rig.tet_mesh.tetCount()), 1.0);
  for (std::int32_t t = body.tetCount(); t < rig.tet_mesh.tetCount(); ++t) rig.setup.stiffness[static_cast<std::size_t>(t)] = 0.1;

  // Fine mesh: the boundary vertices (ascending tet vertex order), B = identity rows.
  std::vector<std::int32_t> fine_of(static_cast<std::size_t>(body.vertexCount()), -1), tet_of;
  for (const Face& f : faces)
    for (const std::int32_t v : f.v) fine_of[static_cast<std::size_t>(v)] = 0;
  for (std::int32_t v = 0; v < body.vertexCount(); ++v) {
    if (fine_of[static_cast<std::size_t>(v)] < 0) continue;
    fine_of[static_cast<std::size_t>(v)] = static_cast<std::int32_t>(tet_of.size());
    tet_of.push_back(v);
  }
  std::vector<std::array<std::int32_t, 3>> triangles;
  for (const Face& f : faces)
    triangles.push_back({fine_of[static_cast<std::size_t>(f.v[0])], fine_of[static_cast<std::size_t>(f.v[1])], fine_of[static_cast<std::size_t>(f.v[2])]});
  if (extra_degenerate_triangle) {
    const auto first = static_cast<std::int32_t>(tet_of.size());
    for (int i = 0; i < 3; ++i) tet_of.push_back(tet_of.front());
    triangles.push_back({first, first + 1, first + 2});
  }
  rig.fine_vertices.resize(static_cast<Eigen::Index>(tet_of.size()), 3);
  rig.pose_transfer.rows = static_cast<std::int32_t>(tet_of.size());
  rig.pose_transfer.cols = nv;
  rig.pose_transfer.row_offsets.push_back(0);
  for (std::size_t i = 0; i < tet_of.size(); ++i) {
    rig.fine_vertices.row(static_cast<Eigen::Index>(i)) = body.vertices.row(tet_of[i]);
    rig.pose_transfer.columns.push_back(tet_of[i]);
    rig.pose_transfer.weights.push_back(1.0);
    rig.pose_transfer.row_offsets.push_back(static_cast<std::int32_t>(i + 1));
  }
  rig.fine_triangles.resize(static_cast<Eigen::Index>(triangles.size()), 3);
  for (std::size_t f = 0; f < triangles.size(); ++f)
    for (int c = 0; c < 3; ++c) rig.fine_triangles(static_cast<Eigen::Index>(f), c) = triangles[f][static_cast<std::size_t>(c)];

  // Device mm -> rig units: Z-up to Y-up rotation, 1e-3 scale, a shift.
  rig.alignment.linear = 1e-3 * Eigen::AngleAxisd(-0.5 * M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  rig.alignment.translation = Eigen::Vector3d(0.25, -0.5, 1.0);
  rig.alignment.rig_units_per_mm = 1e-3;
  return rig;
}

// One frame from rig-unit marker positions (nullopt-like: `valid[k] == false` leaves marker k out
// as invalid). Marker k gets id k + 1 (id 0 is the table's unknown "X").
MarkerFrame makeFrame(const Rig& rig, const std::vector<Eigen::Vector3d>& rig_positions, const std::vector<bool>& valid,
                      std::uint64_t counter) {
  MarkerFrame frame;
  frame.frame_counter = counter;
  frame.device_timestamp_ns = 1'000'000'000 + static_cast<std::int64_t>(counter) * kPeriodNs;
  frame.receive_timestamp_ns = 77'000'000'000 + static_cast<std::int64_t>(counter) * 9'000'001;  // another clock
  const Eigen::Matrix3d inverse = rig.alignment.linear.inverse();
  frame.marker_count = static_cast<std::uint16_t>(rig_positions.size());
  for (std::size_t k = 0; k < rig_positions.size(); ++k) {
    // Reverse order in the frame: the position in the frame does not matter, the id does.
    Marker& m = frame.markers[rig_positions.size() - 1 - k];
    m.id = static_cast<std::uint16_t>(k + 1);
    m.valid = valid[k] ? 1 : 0;
    const Eigen::Vector3d mm = inverse * (rig_positions[k] - rig.alignment.translation);
    for (int c = 0; c < 3; ++c) m.position_mm[c] = valid[k] ? static_cast<float>(mm[c]) : 0.0f;
  }
  return frame;
}

std::vector<std::string> labelTable() {
  std::vector<std::string> labels{"X"};
  for (int k = 0; k < kMarkers; ++k) labels.push_back("subject:M" + std::to_string(k));
  return labels;
}

// A smooth non-rigid motion: twist about the bar's axis growing along z (up to `twist` radians at
// z = 8) plus a global rigid motion (rotation about x, shift).
Eigen::Vector3d moved(const Eigen::Vector3d& p, double twist, double tilt, const Eigen::Vector3d& shift) {
  const Eigen::Vector3d axis(1.0, 1.0, 0.0);
  const Eigen::Vector3d local = Eigen::AngleAxisd(twist * p.z() / 8.0, Eigen::Vector3d::UnitZ()) * (p - axis) + axis;
  return Eigen::AngleAxisd(tilt, Eigen::Vector3d::UnitX()) * local + shift;
}

std::vector<Eigen::Vector3d> movedMarkers(const Rig& rig, double twist, double tilt, const Eigen::Vector3d& shift) {
  std::vector<Eigen::Vector3d> out;
  for (const RigMarker& m : rig.markers) out.push_back(moved(m.rest_position, twist, tilt, shift));
  return out;
}

double maxDistance(const std::vector<float>& a, const std::vector<float>& b) {
  double worst = 0.0;
  for (std::size_t v = 0; v + 2 < a.size(); v += 3) {
    const double dx = a[v] - b[v], dy = a[v + 1] - b[v + 1], dz = a[v + 2] - b[v + 2];
    worst = std::max(worst, std::sqrt(dx * dx + dy * dy + dz * dz));
  }
  return worst;
}

double smoothstep(double u) { return u * u * (3.0 - 2.0 * u); }

// The bar rig and a live rig on it with every marker's label bound (the set-up most tests share).
struct BoundBar {
  explicit BoundBar(LiveRigOptions options = {}) : rig(makeBarRig()), live(rig, options) { live.bindLabels(labelTable()); }
  BoundBar(const BoundBar&) = delete;  // live refers to rig
  std::size_t floats() const { return static_cast<std::size_t>(live.fineVertexCount()) * 3; }  // one position buffer
  const Rig rig;
  LiveRig live;
};

LiveRigOptions withNormals() {
  LiveRigOptions options;
  options.normals = true;
  return options;
}

// ---------------------------------------------------------------------------------------------

TEST(LiveRig, TheHandMadeRigIsValid) {
  const Rig rig = makeBarRig();
  EXPECT_EQ(validateRig(rig), "");
  for (const RigMarker& m : rig.markers) EXPECT_EQ(m.bound_faces, 3) << m.label;
  EXPECT_EQ(checkTetMesh(rig.tet_mesh).inverted_tets, 0);
}

TEST(LiveRigBinding, ExactPrefixedMissingUnknownAndDuplicates) {
  const Rig rig = makeBarRig();
  LiveRig live(rig);
  const std::vector<std::string> labels{"M0", "subject:M1", "X", "", "other:M3", "M1", "pre:M0", "M11"};
  const MarkerBindingReport report = live.bindLabels(labels);
  EXPECT_EQ(report.matched, 4);
  EXPECT_EQ(live.markerOfId(0), 0);   // exact
  EXPECT_EQ(live.markerOfId(5), 1);   // exact "M1" wins over the prefixed id 1
  EXPECT_EQ(live.markerOfId(1), -1);
  EXPECT_EQ(live.markerOfId(4), 3);   // "other:M3" == "M3"
  EXPECT_EQ(live.markerOfId(7), 11);
  EXPECT_EQ(live.markerOfId(2), -1);
  EXPECT_EQ(live.markerOfId(3), -1);
  EXPECT_EQ(live.markerOfId(6), -1);
  EXPECT_EQ(live.markerOfId(999), -1);  // beyond the table
  const std::vector<std::string> missing{"M2", "M4", "M5", "M6", "M7", "M8", "M9", "M10"};
  EXPECT_EQ(report.missing, missing);
  EXPECT_EQ(report.unknown, std::vector<std::string>{"X"});
  const std::vector<std::string> duplicates{"subject:M1", "pre:M0"};
  EXPECT_EQ(report.duplicates, duplicates);
  // "M1" must not match "M11" or "subject:M11" by prefix.
  const MarkerBindingReport second = live.bindLabels(std::vector<std::string>{"subject:M11", "M1x"});
  EXPECT_EQ(second.matched, 1);
  EXPECT_EQ(live.markerOfId(0), 11);
  EXPECT_EQ(second.unknown, std::vector<std::string>{"M1x"});
}

TEST(LiveRig, UnknownIdsAreCountedAndIgnored) {
  const Rig rig = makeBarRig();
  LiveRig with_unknown(rig), without(rig);
  with_unknown.bindLabels(labelTable());
  without.bindLabels(labelTable());
  std::vector<float> a(static_cast<std::size_t>(with_unknown.fineVertexCount()) * 3), b(a.size());
  const std::vector<bool> all(kMarkers, true);
  for (int f = 0; f < 10; ++f) {
    const auto markers = movedMarkers(rig, 0.05 * f, 0.0, Eigen::Vector3d(0.01 * f, 0, 0));
    MarkerFrame frame = makeFrame(rig, markers, all, static_cast<std::uint64_t>(f));
    const MarkerFrame clean = frame;
    // id 0 ("X", not a rig marker), an id past the table, an invalid unbound one: absurd positions.
    for (const std::uint16_t id : {std::uint16_t{0}, std::uint16_t{500}, std::uint16_t{kMarkers + 1}}) {
      Marker& m = frame.markers[frame.marker_count++];
      m.id = id;
      m.valid = id == kMarkers + 1 ? 0 : 1;
      m.position_mm[0] = 1e9f;
    }
    const LiveFrameStats s = with_unknown.processFrame(frame, StepBudget{3}, a.data(), nullptr);
    const LiveFrameStats t = without.processFrame(clean, StepBudget{3}, b.data(), nullptr);
    EXPECT_EQ(s.unknown_markers, 3);
    EXPECT_EQ(t.unknown_markers, 0);
    EXPECT_EQ(s.measured_markers, kMarkers);
    EXPECT_EQ(s.occluded_markers, 0);
    EXPECT_EQ(s.flags & kLiveMarkersPredicted, 0u);
    ASSERT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(float)), 0) << "frame " << f;
  }
}

TEST(MarkerPrediction, ExactForARigidMotionOfTheWholeMesh) {
  const Rig rig = makeBarRig();
  std::vector<std::int32_t> marker_vertices;
  for (const RigMarker& m : rig.markers) marker_vertices.push_back(m.tet_vertex);
  for (const int rings : {0, 1, 2}) {
    MarkerPredictor predictor(rig.tet_mesh, rig.body_vertex_count, rig.body_tet_count, marker_vertices, MarkerPredictionOptions{rings});
    // Anchors: body vertices only, the bound faces' corners at least, more with more rings.
    for (std::int32_t k = 0; k < predictor.markerCount(); ++k) {
      const auto anchor = predictor.anchorVertices(k);
      EXPECT_GE(anchor.size(), 4u);
      for (const std::int32_t v : anchor) EXPECT_LT(v, rig.body_vertex_count);
      if (rings > 0) {
        MarkerPredictor smaller(rig.tet_mesh, rig.body_vertex_count, rig.body_tet_count, marker_vertices, MarkerPredictionOptions{rings - 1});
        EXPECT_GT(anchor.size(), smaller.anchorVertices(k).size());
      }
    }
    const Eigen::Isometry3d motion = Eigen::Translation3d(0.3, -2.0, 5.0) * Eigen::AngleAxisd(2.5, Eigen::Vector3d(1, 2, -0.5).normalized());
    std::vector<double> x(static_cast<std::size_t>(rig.tet_mesh.vertexCount()) * 3);
    for (std::int32_t v = 0; v < rig.tet_mesh.vertexCount(); ++v) {
      // Markers far off their rigid place: they must not influence their own prediction.
      const Eigen::Vector3d p = v < rig.body_vertex_count ? Eigen::Vector3d(motion * Eigen::Vector3d(rig.tet_mesh.vertices.row(v).transpose()))
                                                          : Eigen::Vector3d(100.0, 100.0, 100.0);
      for (int c = 0; c < 3; ++c) x[static_cast<std::size_t>(v) * 3 + static_cast<std::size_t>(c)] = p[c];
    }
    std::vector<Eigen::Vector3d> prediction(rig.markers.size());
    ASSERT_TRUE(predictor.predict(x, prediction));
    for (std::size_t k = 0; k < rig.markers.size(); ++k) {
      EXPECT_LT((prediction[k] - motion * rig.markers[k].rest_position).norm(), 1e-12) << "rings " << rings << " marker " << k;
    }
  }
}

TEST(MarkerPrediction, FollowsTheLocalMotionNotTheGlobalOne) {
  // The bar's vertices twisted by 90 degrees at z = 8 (0 at z = 0). The markers near the ends
  // (z = 0.5: turned by 6 degrees; z = 7.5: by 84) are predicted from their anchors' motion (one
  // ring on this coarse bar: 2 units wide, unit tets), far better than from the best rigid fit of
  // the whole bar (rings = 20 covers it: ~45 degrees).
  const Rig rig = makeBarRig();
  std::vector<std::int32_t> marker_vertices;
  for (const RigMarker& m : rig.markers) marker_vertices.push_back(m.tet_vertex);
  MarkerPredictor local(rig.tet_mesh, rig.body_vertex_count, rig.body_tet_count, marker_vertices, MarkerPredictionOptions{1});
  MarkerPredictor global(rig.tet_mesh, rig.body_vertex_count, rig.body_tet_count, marker_vertices, MarkerPredictionOptions{20});
  ASSERT_EQ(global.anchorVertices(0).size(), static_cast<std::size_t>(rig.body_vertex_count));
  std::vector<double> x(static_cast<std::size_t>(rig.tet_mesh.vertexCount()) * 3);
  for (std::int32_t v = 0; v < rig.tet_mesh.vertexCount(); ++v) {
    const Eigen::Vector3d p = moved(rig.tet_mesh.vertices.row(v).transpose(), 0.5 * M_PI, 0.0, Eigen::Vector3d::Zero());
    for (int c = 0; c < 3; ++c) x[static_cast<std::size_t>(v) * 3 + static_cast<std::size_t>(c)] = p[c];
  }
  std::vector<Eigen::Vector3d> by_local(rig.markers.size()), by_global(rig.markers.size());
  ASSERT_TRUE(local.predict(x, by_local));
  ASSERT_TRUE(global.predict(x, by_global));
  for (const std::size_t k : {0u, 1u, 2u, 3u, 8u, 9u, 10u, 11u}) {
    const Eigen::Vector3d truth = moved(rig.markers[k].rest_position, 0.5 * M_PI, 0.0, Eigen::Vector3d::Zero());
    const double local_error = (by_local[k] - truth).norm(), global_error = (by_global[k] - truth).norm();
    EXPECT_LT(local_error, 0.2 * global_error) << "marker " << k;
    EXPECT_LT(local_error, 0.15) << "marker " << k;  // 0.3 off the side: 0.15 is ~30 degrees there
  }
}

TEST(LiveRig, OccludedMarkerFollowsARigidMotionOfTheBody) {
  const Rig rig = makeBarRig();
  LiveRig live(rig);
  std::vector<std::string> labels = labelTable();
  labels[6] = "";  // marker M5 (id 6) is never named: always predicted
  const MarkerBindingReport report = live.bindLabels(labels);
  ASSERT_EQ(report.missing, std::vector<std::string>{"M5"});
  std::vector<float> x(static_cast<std::size_t>(live.fineVertexCount()) * 3);
  std::vector<bool> valid(kMarkers, true);
  valid[7] = false;  // M7 is also invalid in every frame
  const Eigen::Vector3d shift(0.4, -0.3, 0.7);
  const double tilt = 0.6;
  const Eigen::Isometry3d final_motion = Eigen::Translation3d(shift) * Eigen::AngleAxisd(tilt, Eigen::Vector3d::UnitX());
  LiveFrameStats s;
  for (int f = 0; f < 200; ++f) {
    const double u = std::min(1.0, f / 60.0);  // ramp over 0.5 s, then hold
    const auto markers = movedMarkers(rig, 0.0, u * tilt, u * shift);
    s = live.processFrame(makeFrame(rig, markers, valid, static_cast<std::uint64_t>(f)), StepBudget{3}, x.data(), nullptr);
    EXPECT_EQ(s.occluded_markers, 2);
    EXPECT_EQ(s.measured_markers, kMarkers - 2);
    EXPECT_TRUE(s.flags & kLiveMarkersPredicted);
  }
  EXPECT_EQ(live.markerState(5), MarkerTrackState::kPredicted);
  EXPECT_EQ(live.markerMeasured()[5], 0);
  EXPECT_EQ(live.markerMeasured()[4], 1);
  // The predicted markers' targets: where the rigid motion takes them (float mm in the frames:
  // measurement rounding ~1e-6).
  for (const int k : {5, 7}) {
    const Eigen::Vector3d truth = final_motion * rig.markers[static_cast<std::size_t>(k)].rest_position;
    EXPECT_LT((live.markerTargets()[static_cast<std::size_t>(k)] - truth).norm(), 1e-4) << "marker " << k;
    // Had the marker stayed at its rest position (no prediction), the error would be large.
    EXPECT_GT((rig.markers[static_cast<std::size_t>(k)].rest_position - truth).norm(), 0.5);
  }
  // The fine mesh moved rigidly too.
  double worst = 0.0;
  const auto rest = live.restPositions();
  for (std::size_t v = 0; v < rest.size(); v += 3) {
    const Eigen::Vector3d r(rest[v], rest[v + 1], rest[v + 2]);
    worst = std::max(worst, (Eigen::Vector3d(x[v], x[v + 1], x[v + 2]) - final_motion * r).norm());
  }
  EXPECT_LT(worst, 1e-4);
}

// Runs a twisting, moving bar for `frames` frames; marker M5's measurement slides 0.3 along the bar
// (skin sliding over the body), M5 is occluded in [drop, back). Returns the fine positions per frame.
std::vector<std::vector<float>> runTwist(const Rig& rig, const LiveRigOptions& options, int frames, int drop, int back,
                                         std::vector<LiveFrameStats>* stats = nullptr) {
  LiveRig live(rig, options);
  live.bindLabels(labelTable());
  std::vector<std::vector<float>> out;
  std::vector<float> x(static_cast<std::size_t>(live.fineVertexCount()) * 3);
  for (int f = 0; f < frames; ++f) {
    const double u = static_cast<double>(f) / frames;
    auto markers = movedMarkers(rig, 1.2 * u, 0.3 * u, Eigen::Vector3d(0.0, 0.5 * u, 0.0));
    markers[5] += Eigen::Vector3d(0.0, 0.0, 0.3) * std::min(1.0, f / 20.0);
    std::vector<bool> valid(kMarkers, true);
    valid[5] = f < drop || f >= back;
    const LiveFrameStats s = live.processFrame(makeFrame(rig, markers, valid, static_cast<std::uint64_t>(f)), StepBudget{3}, x.data(), nullptr);
    if (stats) stats->push_back(s);
    out.push_back(x);
  }
  return out;
}

double largestStep(const std::vector<std::vector<float>>& run, int from, int to) {
  double worst = 0.0;
  for (int f = std::max(from, 1); f < to; ++f) worst = std::max(worst, maxDistance(run[static_cast<std::size_t>(f)], run[static_cast<std::size_t>(f) - 1]));
  return worst;
}

TEST(LiveRig, NoPopAtDropoutOrReturn) {
  const Rig rig = makeBarRig();
  constexpr int kFrames = 240, kDrop = 80, kBack = 160;
  const auto reference = runTwist(rig, LiveRigOptions{}, kFrames, kFrames, kFrames);  // never occluded
  std::vector<LiveFrameStats> stats;
  const auto occluded = runTwist(rig, LiveRigOptions{}, kFrames, kDrop, kBack, &stats);
  LiveRigOptions no_blend;
  no_blend.occlusion_blend_s = 0.0;
  const auto popping = runTwist(rig, no_blend, kFrames, kDrop, kBack);
  // The reference's own largest per-frame motion of any fine vertex, after the slide ramp.
  const double motion = largestStep(reference, 30, kFrames);
  const double blended = largestStep(occluded, 30, kFrames);
  const double unblended = largestStep(popping, 30, kFrames);
  std::printf("[ measured ] bar: largest per-frame fine-vertex step: unoccluded %.5f, occluded with 0.15 s blends %.5f, "
              "without blends %.5f\n", motion, blended, unblended);
  EXPECT_LE(blended, 1.5 * motion);
  EXPECT_GT(unblended, 3.0 * motion) << "the slid marker must pop without blends, or this test proves nothing";
  // Flags and counts through the occlusion: predicted while occluded, blending for 0.15 s after
  // each edge (frame 18 after the edge is 149.99999 ms later: still blending; frame 19 is not).
  EXPECT_EQ(stats[kDrop - 1].flags & (kLiveMarkersPredicted | kLiveMarkersBlending), 0u);
  EXPECT_TRUE(stats[kDrop].flags & kLiveMarkersPredicted);
  EXPECT_TRUE(stats[kDrop].flags & kLiveMarkersBlending);
  EXPECT_EQ(stats[kDrop].blending_markers, 1);
  EXPECT_EQ(stats[kDrop].occluded_markers, 1);
  EXPECT_TRUE(stats[kDrop + 18].flags & kLiveMarkersBlending);
  EXPECT_FALSE(stats[kDrop + 19].flags & kLiveMarkersBlending);
  EXPECT_TRUE(stats[kDrop + 19].flags & kLiveMarkersPredicted);
  EXPECT_EQ(stats[kBack].occluded_markers, 0);
  EXPECT_TRUE(stats[kBack].flags & kLiveMarkersBlending);
  EXPECT_TRUE(stats[kBack + 18].flags & kLiveMarkersBlending);
  EXPECT_EQ(stats[kBack + 19].flags & kLiveMarkersBlending, 0u);
  // After the return blend the run is back on the reference (within the deformer's lag).
  EXPECT_LT(maxDistance(occluded[kFrames - 1], reference[kFrames - 1]), 0.1 * maxDistance(popping[kDrop + 40], reference[kDrop + 40]));
}

TEST(LiveRig, BlendsFollowTheSmoothstepInFrameTime) {
  BoundBar bar;  // T = 0.15 s
  const Rig& rig = bar.rig;
  LiveRig& live = bar.live;
  std::vector<float> x(bar.floats());
  // Frames at irregular times (device clock), the receive clock elsewhere and running backwards:
  // only device time may count.
  std::int64_t t = 5'000'000'000;
  auto frameAt = [&](std::int64_t time_ns, bool m0_valid, std::uint64_t counter) {
    auto markers = movedMarkers(rig, 0.2, 0.0, Eigen::Vector3d::Zero());
    markers[0] += Eigen::Vector3d(0.2, 0.0, 0.0);
    std::vector<bool> valid(kMarkers, true);
    valid[0] = m0_valid;
    MarkerFrame frame = makeFrame(rig, markers, valid, counter);
    frame.device_timestamp_ns = time_ns;
    frame.receive_timestamp_ns = 1'000'000'000'000 - static_cast<std::int64_t>(counter) * 50'000'000;
    return frame;
  };
  std::uint64_t counter = 0;
  for (int f = 0; f < 30; ++f) live.processFrame(frameAt(t += 10'000'000, true, counter++), StepBudget{3}, x.data(), nullptr);
  ASSERT_EQ(live.markerState(0), MarkerTrackState::kMeasured);
  // Dropout: the offset o = target - prediction at the first occluded frame, kept in the anchor's
  // frame (it turns with the anchor rotation R of the prediction), fades as 1 - s(u).
  live.processFrame(frameAt(t += 10'000'000, false, counter++), StepBudget{3}, x.data(), nullptr);
  const Eigen::Vector3d offset = live.markerAnchorRotations()[0].conjugate() * (live.markerTargets()[0] - live.markerPredictions()[0]);
  ASSERT_GT(offset.norm(), 0.05);
  const std::int64_t dropout = t;
  for (const std::int64_t dt : {20'000'000, 37'500'000, 75'000'000, 112'500'000, 149'000'000, 150'000'000, 300'000'000}) {
    live.processFrame(frameAt(t = dropout + dt, false, counter++), StepBudget{3}, x.data(), nullptr);
    const double fade = 1.0 - smoothstep(std::min(1.0, static_cast<double>(dt) / 150e6));
    const Eigen::Vector3d expected = live.markerPredictions()[0] + fade * (live.markerAnchorRotations()[0] * offset);
    EXPECT_LT((live.markerTargets()[0] - expected).norm(), 1e-12) << "dt " << dt;
  }
  // Return: from the prediction (offset long gone) to the measurement as s(u).
  const std::int64_t back = t + 10'000'000;
  const Eigen::Vector3d measured = moved(rig.markers[0].rest_position, 0.2, 0.0, Eigen::Vector3d::Zero()) + Eigen::Vector3d(0.2, 0, 0);
  for (const std::int64_t dt : {0, 30'000'000, 75'000'000, 120'000'000, 150'000'000}) {
    live.processFrame(frameAt(t = back + dt, true, counter++), StepBudget{3}, x.data(), nullptr);
    const double s = smoothstep(static_cast<double>(dt) / 150e6);
    const Eigen::Vector3d p = live.markerPredictions()[0];
    const Eigen::Vector3d expected = p + s * (measured - p);
    EXPECT_LT((live.markerTargets()[0] - expected).norm(), 1e-5) << "dt " << dt;  // float mm round trip
    EXPECT_EQ(live.markerState(0), dt < 150'000'000 ? MarkerTrackState::kReturning : MarkerTrackState::kMeasured) << "dt " << dt;
  }
}

TEST(LiveRig, TheDropoutOffsetFadesOutWhileTheBodyMoves) {
  // M0 is measured 0.2 off its rest offset (a slid marker) while the bar stands still, then lost
  // while the bar turns and shifts rigidly. Once the offset has faded, M0's target is the rigid
  // motion of its rest offset, not of its last measurement.
  const Rig rig = makeBarRig();
  const Eigen::Vector3d slide(0.0, 0.0, 0.2);
  const Eigen::Vector3d shift(0.3, 0.2, -0.4);
  const double tilt = 0.5;
  const Eigen::Isometry3d motion = Eigen::Translation3d(shift) * Eigen::AngleAxisd(tilt, Eigen::Vector3d::UnitX());
  {
    LiveRig live(rig);
    live.bindLabels(labelTable());
    std::vector<float> x(static_cast<std::size_t>(live.fineVertexCount()) * 3);
    std::vector<bool> valid(kMarkers, true);
    for (int f = 0; f < 200; ++f) {
      const double u = f < 60 ? 0.0 : std::min(1.0, (f - 60) / 60.0);
      auto markers = movedMarkers(rig, 0.0, u * tilt, u * shift);
      markers[0] += slide;
      valid[0] = f < 60;
      live.processFrame(makeFrame(rig, markers, valid, static_cast<std::uint64_t>(f)), StepBudget{3}, x.data(), nullptr);
    }
    const Eigen::Vector3d last_measured = motion * (rig.markers[0].rest_position + slide);
    const Eigen::Vector3d rest_offset = motion * rig.markers[0].rest_position;
    const Eigen::Vector3d target = live.markerTargets()[0];
    EXPECT_LT((target - rest_offset).norm(), 2e-3);
    EXPECT_GT((last_measured - rest_offset).norm(), 0.19);
  }
}

TEST(LiveRig, AllOccludedHoldsThePoseBitIdentically) {
  BoundBar bar(withNormals());
  const Rig& rig = bar.rig;
  LiveRig& live = bar.live;
  const std::size_t n = bar.floats();
  std::vector<float> x(n), nrm(n), held(n), held_normals(n);
  const std::vector<bool> all(kMarkers, true), none(kMarkers, false);
  // The markers twist the bar; M0 and M4 are measured 0.5 off their rest offsets (slid on the
  // skin), so their dropout offsets are large: the blend clock must stand still while the pose is
  // held, or their fade would land in the first step after the hold.
  const auto slid = [&](int frame) {
    auto m = movedMarkers(rig, 0.02 * frame, 0.01 * frame, Eigen::Vector3d::Zero());
    m[0] += Eigen::Vector3d(0.0, 0.0, 0.5);
    m[4] += Eigen::Vector3d(0.0, 0.0, -0.5);
    return m;
  };
  int f = 0;
  double largest_step = 0.0;
  std::vector<float> previous = x;
  for (; f < 40; ++f) {
    live.processFrame(makeFrame(rig, slid(f), all, static_cast<std::uint64_t>(f)), StepBudget{3}, x.data(), nrm.data());
    if (f > 0) largest_step = std::max(largest_step, maxDistance(x, previous));
    previous = x;
  }
  const std::vector<float> last = x, last_normals = nrm;
  const std::vector<double> tets(live.deformer().positions().begin(), live.deformer().positions().end());
  for (int g = 0; g < 50; ++g, ++f) {
    MarkerFrame frame = makeFrame(rig, movedMarkers(rig, 0.02 * f, 0.01 * f, Eigen::Vector3d::Zero()), none, static_cast<std::uint64_t>(f));
    if (g % 2) frame.marker_count = 0;  // also frames with no markers at all
    std::fill(held.begin(), held.end(), -1.0f);
    std::fill(held_normals.begin(), held_normals.end(), -1.0f);
    const LiveFrameStats s = live.processFrame(frame, StepBudget{3}, held.data(), held_normals.data());
    EXPECT_TRUE(s.flags & kLivePoseHeld);
    EXPECT_EQ(s.step.iterations, 0);
    EXPECT_EQ(s.measured_markers, 0);
    EXPECT_EQ(s.occluded_markers, kMarkers);
    ASSERT_EQ(std::memcmp(held.data(), last.data(), n * sizeof(float)), 0) << "held frame " << g;
    ASSERT_EQ(std::memcmp(held_normals.data(), last_normals.data(), n * sizeof(float)), 0) << "held frame " << g;
  }
  EXPECT_TRUE(std::equal(tets.begin(), tets.end(), live.deformer().positions().begin()));
  std::fill(held.begin(), held.end(), 0.0f);
  live.writeLastPose(held.data(), held_normals.data());
  EXPECT_EQ(std::memcmp(held.data(), last.data(), n * sizeof(float)), 0);
  // The markers return 50 frames of motion further on: blended back from the held pose, so the
  // first frame moves less than one frame of the motion did (the blend clock stood still while
  // held: the slid markers' offsets are still there); without the blend the mesh would jump by
  // the 50 frames at once.
  const auto returned = slid(f);
  const LiveFrameStats back = live.processFrame(makeFrame(rig, returned, all, static_cast<std::uint64_t>(f)), StepBudget{3}, x.data(), nrm.data());
  EXPECT_FALSE(back.flags & kLivePoseHeld);
  EXPECT_EQ(back.blending_markers, kMarkers);
  std::printf("[ measured ] bar: first frame after a 50-frame hold moved %.5f (largest step while moving %.5f)\n",
              maxDistance(x, last), largest_step);
  EXPECT_LT(maxDistance(x, last), 0.6 * largest_step);
  double marker_jump = 0.0;
  for (std::size_t k = 0; k < returned.size(); ++k) marker_jump = std::max(marker_jump, (returned[k] - live.markerPredictions()[k]).norm());
  EXPECT_GT(marker_jump, 5.0 * largest_step) << "the markers must have moved on during the hold";
}

// A solved pose outside the bound (tetrig/pose_bound.hpp) is never published: the last pose is
// written again bit for bit, the frame is flagged and the deformer starts again from rest. Here
// the rig's absolute bound is 8.3 units: markers shifted 0.6 along the 8-unit bar stay inside it
// (z <= 8.1) and are measured, but they carry the bar's end to z = 8.6.
TEST(LiveRig, AnImplausiblePoseIsNeverPublished) {
  Rig rig = makeBarRig();
  rig.setup.options.max_abs_coordinate = 8.3;
  LiveRigOptions options;
  options.normals = true;
  LiveRig live(rig, options);
  live.bindLabels(labelTable());
  const std::size_t n = static_cast<std::size_t>(live.fineVertexCount()) * 3;
  std::vector<float> x(n), nrm(n);
  const std::vector<bool> all(kMarkers, true);
  int f = 0;
  for (; f < 10; ++f) {
    const LiveFrameStats s = live.processFrame(makeFrame(rig, movedMarkers(rig, 0.01 * f, 0.0, Eigen::Vector3d::Zero()), all, static_cast<std::uint64_t>(f)),
                                               StepBudget{3}, x.data(), nrm.data());
    ASSERT_FALSE(s.flags & kLivePoseRejected) << "frame " << f;
  }
  const std::vector<float> last = x, last_normals = nrm;
  const LiveFrameStats s = live.processFrame(makeFrame(rig, movedMarkers(rig, 0.01 * f, 0.0, Eigen::Vector3d(0, 0, 0.6)), all, static_cast<std::uint64_t>(f)),
                                             StepBudget{3}, x.data(), nrm.data());
  ++f;
  EXPECT_TRUE(s.flags & kLivePoseRejected);
  EXPECT_EQ(s.measured_markers, kMarkers) << "the markers themselves are inside the bound";
  EXPECT_FALSE(s.flags & kLiveTargetsRejected);
  EXPECT_EQ(std::memcmp(x.data(), last.data(), n * sizeof(float)), 0) << "the last pose, bit for bit";
  EXPECT_EQ(std::memcmp(nrm.data(), last_normals.data(), n * sizeof(float)), 0);
  const auto tets = live.deformer().positions();
  double from_rest = 0.0;
  for (std::int32_t v = 0; v < rig.tet_mesh.vertexCount(); ++v)
    for (int c = 0; c < 3; ++c)
      from_rest = std::max(from_rest, std::abs(tets[static_cast<std::size_t>(v) * 3 + static_cast<std::size_t>(c)] - rig.tet_mesh.vertices(v, c)));
  EXPECT_EQ(from_rest, 0.0) << "the deformer was reset to rest";
  // The markers back inside: solved and published again.
  const LiveFrameStats back = live.processFrame(makeFrame(rig, movedMarkers(rig, 0.0, 0.0, Eigen::Vector3d::Zero()), all, static_cast<std::uint64_t>(f)),
                                                StepBudget{3}, x.data(), nrm.data());
  EXPECT_FALSE(back.flags & kLivePoseRejected);
  EXPECT_GT(maxDistance(x, last), 0.0);
}

// Poses far from rest that the targets do produce are not mistaken for implausible ones: the whole
// bar carried 500 units away, turned half round, and stretched to three times its length (1.4 rest
// diagonals from the markers' median at the ends). First in 10 frames with the sample test off
// (its markers move 50 units a frame: the pose bound alone), then at a human pace with it on, the
// bar starting out there (a first frame has nothing to be judged against).
TEST(LiveRig, FarStretchedAndTurnedPosesAreNotRejected) {
  for (const bool paced : {false, true}) {
    LiveRigOptions options;
    if (!paced) options.max_marker_speed_mm_s = 0.0;
    BoundBar bar(options);
    const Rig& rig = bar.rig;
    LiveRig& live = bar.live;
    const std::size_t n = bar.floats();
    std::vector<float> x(n);
    const std::vector<bool> all(kMarkers, true);
    const Eigen::Vector3d shift(500.0, -300.0, 200.0);
    const int ramp = paced ? 600 : 10;  // paced: the far end moves up to 0.12 units (metres here) a frame, 14.5 m/s
    std::vector<Eigen::Vector3d> targets;
    for (int f = 0; f < ramp + 20; ++f) {
      const double u = std::min(1.0, static_cast<double>(f) / ramp);
      targets.clear();
      for (const RigMarker& m : rig.markers) {
        Eigen::Vector3d p = m.rest_position;
        p.z() *= 1.0 + 2.0 * u;
        targets.push_back(Eigen::AngleAxisd(M_PI * u, Eigen::Vector3d::UnitX()) * p + (paced ? 1.0 : u) * shift);
      }
      const LiveFrameStats s = live.processFrame(makeFrame(rig, targets, all, static_cast<std::uint64_t>(f)), StepBudget{3}, x.data(), nullptr);
      ASSERT_FALSE(s.flags & kLivePoseRejected) << "frame " << f << (paced ? " (paced)" : "");
      ASSERT_EQ(s.rejected_marker_samples, 0) << "frame " << f << (paced ? " (paced)" : "");
    }
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero(), target_centroid = Eigen::Vector3d::Zero();
    for (std::size_t v = 0; v < n; v += 3) centroid += Eigen::Vector3d(x[v], x[v + 1], x[v + 2]) / static_cast<double>(n / 3);
    for (const auto& p : targets) target_centroid += p / static_cast<double>(targets.size());
    EXPECT_LT((centroid - target_centroid).norm(), 1.0) << "the published bar is where its markers are" << (paced ? " (paced)" : "");
  }
}

// ---------------------------------------------------------------------------------------------
// Implausible marker samples (LiveRigOptions::max_marker_speed_mm_s, docs/live.md "Implausible
// marker samples"). The bar here is a forearm: the same rig with device millimetres mapped 10x
// larger, so one rig unit is 10 cm and the bar 0.8 m long (rest diagonal 8.49 units = 0.85 m): the
// jump floor is 0.85 units (8.5 cm), the prediction bound 8.49 units (0.85 m), the speed limit
// (30 m/s) 300 units a second, 2.5 units a 120 Hz frame.

constexpr double kForearmUnitsPerMetre = 10.0;

Rig makeForearmRig() {
  Rig rig = makeBarRig();
  rig.alignment.linear *= 10.0;
  rig.alignment.rig_units_per_mm = 1e-2;
  return rig;
}

// A live rig on a rig, bound, with its own position buffer.
struct Player {
  explicit Player(const Rig& r, const LiveRigOptions& options = {}) : rig(r), live(r, options) {
    live.bindLabels(labelTable());
    x.resize(static_cast<std::size_t>(live.fineVertexCount()) * 3);
  }
  LiveFrameStats play(const std::vector<Eigen::Vector3d>& markers, const std::vector<bool>& valid, int f) {
    return live.processFrame(makeFrame(rig, markers, valid, static_cast<std::uint64_t>(f)), StepBudget{3}, x.data(), nullptr);
  }
  const Rig& rig;
  LiveRig live;
  std::vector<float> x;
};

// One marker thrown 100 m for one frame, then three markers' coordinates garbage for one frame: those
// samples are rejected and counted, their markers are predicted for that frame, the pose stays
// within a hair of the clean run's, and the next frame's real samples are taken again.
TEST(LiveRigPlausibility, AMarkerThrownFarForOneFrameIsRejectedAndCounted) {
  const Rig rig = makeForearmRig();
  Player clean(rig), glitched(rig);
  LiveRigOptions off;
  off.max_marker_speed_mm_s = 0.0;
  Player unguarded(rig, off);
  const std::vector<bool> all(kMarkers, true);
  constexpr int kThrow = 40, kGarbage = 50;
  double thrown_difference = 0.0, garbage_difference = 0.0, unguarded_difference = 0.0;
  for (int f = 0; f < 70; ++f) {
    // A slow twist and drift (the far end moves about 0.03 units, 3 mm, a frame).
    const std::vector<Eigen::Vector3d> markers = movedMarkers(rig, 0.004 * f, 0.002 * f, Eigen::Vector3d(0.02 * f, 0.0, 0.0));
    std::vector<Eigen::Vector3d> bad = markers;
    if (f == kThrow) bad[5] += Eigen::Vector3d(100.0 * kForearmUnitsPerMetre, 0.0, 0.0);
    if (f == kGarbage) {
      bad[1] = Eigen::Vector3d(3.1e4, -2.2e5, 7.0);
      bad[7] = Eigen::Vector3d(-1234.5, 0.5, 9.0e3);
      bad[10] = Eigen::Vector3d(17.0, 230.0, -41.0);
    }
    const LiveFrameStats c = clean.play(markers, all, f);
    const LiveFrameStats g = glitched.play(bad, all, f);
    const LiveFrameStats u = unguarded.play(bad, all, f);
    if (f == kThrow) {
      // Without the sample test the throw reaches the solve, and the pose bound (2 rest diagonals
      // around the markers' median) refuses what it makes of the bar: the last pose is held.
      EXPECT_EQ(u.rejected_marker_samples, 0);
      EXPECT_TRUE(u.flags & kLivePoseRejected);
    }
    ASSERT_EQ(c.rejected_marker_samples, 0) << "frame " << f;
    ASSERT_FALSE(g.flags & kLivePoseRejected) << "frame " << f;
    if (f == kThrow) {
      EXPECT_EQ(g.rejected_marker_samples, 1);
      EXPECT_TRUE(g.flags & kLiveMarkersRejected);
      EXPECT_EQ(g.measured_markers, kMarkers - 1);
      EXPECT_EQ(g.occluded_markers, 1) << "a rejected sample counts as an occluded marker";
      EXPECT_TRUE(g.flags & kLiveMarkersPredicted);
      EXPECT_EQ(glitched.live.markerRejected()[5], 1);
      EXPECT_EQ(glitched.live.markerMeasured()[5], 0);
      EXPECT_EQ(glitched.live.markerState(5), MarkerTrackState::kPredicted);
      EXPECT_LT((glitched.live.markerTargets()[5] - markers[5]).norm(), 0.1) << "driven from the body, not from the throw";
      thrown_difference = maxDistance(glitched.x, clean.x);
      unguarded_difference = maxDistance(unguarded.x, clean.x);
    } else if (f == kThrow + 1) {
      EXPECT_EQ(g.rejected_marker_samples, 0) << "the next real sample is taken";
      EXPECT_EQ(glitched.live.markerMeasured()[5], 1);
      EXPECT_EQ(glitched.live.markerState(5), MarkerTrackState::kReturning) << "blending back from the prediction";
    } else if (f == kGarbage) {
      EXPECT_EQ(g.rejected_marker_samples, 3);
      EXPECT_EQ(g.occluded_markers, 3);
      for (const int k : {1, 7, 10}) EXPECT_EQ(glitched.live.markerRejected()[static_cast<std::size_t>(k)], 1) << k;
      garbage_difference = maxDistance(glitched.x, clean.x);
    } else {
      EXPECT_EQ(g.rejected_marker_samples, 0) << "frame " << f;
      EXPECT_FALSE(g.flags & kLiveMarkersRejected) << "frame " << f;
    }
  }
  std::printf("[ measured ] forearm bar: largest vertex difference from the clean run in the thrown frame %.4f units (%.2f mm; "
              "without the sample test, the pose held: %.2f mm), in the garbage frame %.4f units (%.2f mm)\n",
              thrown_difference, 100.0 * thrown_difference, 100.0 * unguarded_difference, garbage_difference, 100.0 * garbage_difference);
  EXPECT_LT(thrown_difference, 0.05);   // 5 mm
  EXPECT_LT(garbage_difference, 0.05);
}

// A hand-fast motion (peak 8 m/s, reversing 4 times a second) is never rejected; the same path
// eight times as fast (64 m/s, beyond any human marker) is.
TEST(LiveRigPlausibility, FastHumanMotionIsNotRejected) {
  const Rig rig = makeForearmRig();
  const std::vector<bool> all(kMarkers, true);
  for (const double peak_m_s : {8.0, 64.0}) {
    Player run(rig);
    const double omega = 2.0 * M_PI * 2.0 * peak_m_s / 8.0;                  // rad/s
    const double amplitude = peak_m_s * kForearmUnitsPerMetre / omega;        // units: peak speed = amplitude * omega
    std::uint32_t rejected = 0;
    double fastest = 0.0;
    std::vector<Eigen::Vector3d> last;
    for (int f = 0; f < 240; ++f) {
      const double t = f * 1e-9 * static_cast<double>(kPeriodNs);
      const std::vector<Eigen::Vector3d> markers =
          movedMarkers(rig, 0.3 * std::sin(omega * t), 0.0, Eigen::Vector3d(amplitude * std::sin(omega * t), 0.0, 0.0));
      rejected += run.play(markers, all, f).rejected_marker_samples;
      for (std::size_t k = 0; k < last.size(); ++k) fastest = std::max(fastest, (markers[k] - last[k]).norm() / (1e-9 * static_cast<double>(kPeriodNs)));
      last = markers;
    }
    std::printf("[ measured ] forearm bar waved at a peak of %.0f m/s (fastest marker %.1f m/s): %u samples rejected\n", peak_m_s,
                fastest / kForearmUnitsPerMetre, rejected);
    if (peak_m_s < 10.0) {
      EXPECT_GE(fastest / kForearmUnitsPerMetre, 8.0);
      EXPECT_EQ(rejected, 0u);
    } else {
      EXPECT_GT(rejected, 0u) << "beyond the limit: rejected";
    }
  }
}

// A marker back after 1 s of occlusion, 2 m from where it left (the body carried it), lies within
// the rig's size of its prediction: taken at once. Its last sample is too old to judge it (judged
// by that, with the time capped, it would be rejected). A returning sample 1.5 rest diagonals from
// where the body has it is rejected. After a 1 s total loss every marker is taken back at once.
TEST(LiveRigPlausibility, AMarkerReturningFarFromWhereItLeftIsJudgedByItsPrediction) {
  const Rig rig = makeForearmRig();
  const double diagonal = boundingBoxDiagonal(rig.fine_vertices);
  constexpr int kDrop = 60, kBack = 180, kFrames = 240;
  for (const bool wrong : {false, true}) {
    Player run(rig);
    Eigen::Vector3d left = Eigen::Vector3d::Zero();
    for (int f = 0; f < kFrames; ++f) {
      // 2 m/s along x: 0.167 units a frame.
      std::vector<Eigen::Vector3d> markers = movedMarkers(rig, 0.0, 0.0, Eigen::Vector3d(20.0 * f * 1e-9 * static_cast<double>(kPeriodNs), 0.0, 0.0));
      std::vector<bool> valid(kMarkers, true);
      valid[5] = f < kDrop || f >= kBack;
      if (f == kDrop - 1) left = markers[5];
      if (wrong && f == kBack) markers[5] += Eigen::Vector3d(0.0, 1.5 * diagonal, 0.0);
      const LiveFrameStats s = run.play(markers, valid, f);
      if (f == kBack) {
        EXPECT_GT((markers[5] - left).norm(), diagonal) << "farther from where it left than the prediction bound";
        if (!wrong) {
          EXPECT_EQ(s.rejected_marker_samples, 0);
          EXPECT_EQ(run.live.markerMeasured()[5], 1);
          EXPECT_EQ(run.live.markerState(5), MarkerTrackState::kReturning);
        } else {
          EXPECT_EQ(s.rejected_marker_samples, 1);
          EXPECT_EQ(run.live.markerState(5), MarkerTrackState::kPredicted);
        }
      } else {
        EXPECT_EQ(s.rejected_marker_samples, 0) << "frame " << f << (wrong ? " (wrong return)" : "");
      }
    }
  }
  // Every marker lost for 1 s while the body goes on 2 m: the pose is held, and every marker is
  // taken back on its return (nothing measured the body meanwhile: a held pose judges generously).
  Player run(rig);
  for (int f = 0; f < kFrames; ++f) {
    const std::vector<Eigen::Vector3d> markers = movedMarkers(rig, 0.0, 0.0, Eigen::Vector3d(20.0 * f * 1e-9 * static_cast<double>(kPeriodNs), 0.0, 0.0));
    const std::vector<bool> valid(kMarkers, f < kDrop || f >= kBack);
    const LiveFrameStats s = run.play(markers, valid, f);
    ASSERT_EQ(s.rejected_marker_samples, 0) << "frame " << f;
    if (f == kBack) {
      EXPECT_EQ(s.measured_markers, kMarkers);
      EXPECT_FALSE(s.flags & kLivePoseHeld);
    }
  }
}

TEST(LiveRig, SameFramesGiveBitIdenticalOutputs) {
  const Rig rig = makeBarRig();
  LiveRigOptions options;
  options.normals = true;
  LiveRig a(rig, options), b(rig, options), c(rig, options);
  for (LiveRig* live : {&a, &b, &c}) live->bindLabels(labelTable());
  const std::size_t n = static_cast<std::size_t>(a.fineVertexCount()) * 3;
  std::vector<float> xa(n), xb(n), xc(n), na(n), nb(n), nc(n);
  for (int f = 0; f < 150; ++f) {
    std::vector<bool> valid(kMarkers, true);
    valid[3] = f < 30 || f > 60;
    valid[8] = f % 7 != 0;
    if (f >= 90 && f < 100) valid.assign(kMarkers, false);
    const MarkerFrame frame = makeFrame(rig, movedMarkers(rig, 0.01 * f, -0.004 * f, Eigen::Vector3d(0, 0.003 * f, 0)), valid, static_cast<std::uint64_t>(f));
    // c gets the same frames with the device time moved to the receive field: the same clock.
    MarkerFrame receive_only = frame;
    receive_only.receive_timestamp_ns = frame.device_timestamp_ns;
    receive_only.device_timestamp_ns = 0;
    const LiveFrameStats sa = a.processFrame(frame, StepBudget{2}, xa.data(), na.data());
    const LiveFrameStats sb = b.processFrame(frame, StepBudget{2}, xb.data(), nb.data());
    c.processFrame(receive_only, StepBudget{2}, xc.data(), nc.data());
    ASSERT_EQ(sa.flags, sb.flags);
    ASSERT_EQ(std::memcmp(xa.data(), xb.data(), n * sizeof(float)), 0) << "frame " << f;
    ASSERT_EQ(std::memcmp(na.data(), nb.data(), n * sizeof(float)), 0) << "frame " << f;
    ASSERT_EQ(std::memcmp(xa.data(), xc.data(), n * sizeof(float)), 0) << "frame " << f;
  }
}

// The volume constraint's linearization for the next frame runs in prepareNextFrame(), after the
// caller has published the pose (FrameLoop), or, when the caller does not call it, first thing in
// the next processFrame: the poses are the same bit for bit either way, and the work happens once
// per stepped frame, where the stats say.
TEST(LiveRig, TheVolumeConstraintCanBeLinearizedAfterPublishing) {
  const Rig rig = makeBarRig();
  // The plain settings with and without the volume constraint: what it alone changes.
  LiveRigOptions options, free_options;
  free_options.solver = SolverSettings::plain();
  options.solver = SolverSettings::plain();
  options.solver.volume_constraint = true;
  LiveRig inline_rig(rig, options), deferring(rig, options), free_rig(rig, free_options);
  for (LiveRig* live : {&inline_rig, &deferring, &free_rig}) live->bindLabels(labelTable());
  const std::size_t n = static_cast<std::size_t>(inline_rig.fineVertexCount()) * 3;
  std::vector<float> xa(n), xb(n), xc(n);
  double largest_volume_difference = 0.0;
  int held = 0;
  for (int f = 0; f < 80; ++f) {
    std::vector<bool> valid(kMarkers, true);
    if (f >= 40 && f < 45) valid.assign(kMarkers, false);  // a held stretch: nothing to linearize after it
    const MarkerFrame frame = makeFrame(rig, movedMarkers(rig, 0.015 * f, -0.01 * f, Eigen::Vector3d(0, 0.004 * f, 0)), valid,
                                        static_cast<std::uint64_t>(f));
    const LiveFrameStats sa = inline_rig.processFrame(frame, StepBudget{3}, xa.data(), nullptr);
    const LiveFrameStats sb = deferring.processFrame(frame, StepBudget{3}, xb.data(), nullptr);
    free_rig.processFrame(frame, StepBudget{3}, xc.data(), nullptr);
    ASSERT_EQ(sa.flags, sb.flags) << "frame " << f;
    ASSERT_EQ(std::memcmp(xa.data(), xb.data(), n * sizeof(float)), 0) << "frame " << f;
    const bool stepped = !(sb.flags & kLivePoseHeld);
    held += stepped ? 0 : 1;
    // The deferring rig never leaves work to its next frame; the inline one does after every
    // stepped frame (the first frame has nothing before it; a held frame runs what the frame
    // before it left).
    EXPECT_EQ(sb.prepare_ns, 0) << "frame " << f;
    const bool left_work = f > 0 && !(f >= 41 && f <= 45);
    EXPECT_EQ(sa.prepare_ns > 0, left_work) << "frame " << f;
    const std::int64_t prepared = deferring.prepareNextFrame();
    EXPECT_EQ(prepared > 0, stepped) << "frame " << f;
    EXPECT_EQ(deferring.prepareNextFrame(), 0) << "frame " << f << ": nothing is pending twice";
    const double rest = enclosedVolume(inline_rig.fineTriangles(), inline_rig.restPositions().data());
    largest_volume_difference = std::max(largest_volume_difference,
                                         std::abs(enclosedVolume(inline_rig.fineTriangles(), xc.data()) - enclosedVolume(inline_rig.fineTriangles(), xa.data())) / rest);
  }
  EXPECT_EQ(held, 5);
  EXPECT_TRUE(deferring.deformer().hasLinearConstraint());
  EXPECT_FALSE(free_rig.deformer().hasLinearConstraint());
  // The constraint did act: the unconstrained rig's volume differs somewhere.
  EXPECT_GT(largest_volume_difference, 1e-4);
}

// LiveRigOptions::after_publish_iterations: more iterations on a frame's own targets after its pose
// is published (prepareNextFrame) start the next frame nearer its converged pose, so the lag that
// builds up over frames of a fast twist shrinks. Run by prepareNextFrame or first thing in the
// next processFrame, the poses are the same bit for bit; past its deadline it runs no iteration (the
// poses are then those of a rig without it).
TEST(LiveRig, IterationsAfterPublishingStartEachFrameNearerItsConvergedPose) {
  const Rig rig = makeBarRig();
  // The plain settings (no prediction, guard or volume constraint) with and without the iterations
  // after publishing: what they alone change.
  LiveRigOptions plain_options, after_options;
  plain_options.solver = SolverSettings::plain();
  after_options.solver = SolverSettings::plain();
  after_options.solver.after_publish_iterations = 2;
  LiveRig plain(rig, plain_options), converged(rig, plain_options), after(rig, after_options), after_inline(rig, after_options),
      late(rig, after_options);
  for (LiveRig* live : {&plain, &converged, &after, &after_inline, &late}) live->bindLabels(labelTable());
  const std::size_t n = static_cast<std::size_t>(plain.fineVertexCount()) * 3;
  std::vector<float> xp(n), xc(n), xa(n), xi(n), xl(n);
  const auto past = std::chrono::steady_clock::now() - std::chrono::seconds(1);
  double plain_error = 0.0, after_error = 0.0;
  for (int f = 0; f < 40; ++f) {
    // A twist of 3 degrees per frame at the far end, with a slow tilt and drift.
    const MarkerFrame frame = makeFrame(rig, movedMarkers(rig, 0.05 * f, 0.004 * f, Eigen::Vector3d(0.002 * f, 0, 0)),
                                        std::vector<bool>(kMarkers, true), static_cast<std::uint64_t>(f));
    plain.processFrame(frame, StepBudget{3}, xp.data(), nullptr);
    converged.processFrame(frame, StepBudget{400}, xc.data(), nullptr);
    const LiveFrameStats sa = after.processFrame(frame, StepBudget{3}, xa.data(), nullptr);
    after_inline.processFrame(frame, StepBudget{3}, xi.data(), nullptr);
    late.processFrame(frame, StepBudget{3}, xl.data(), nullptr);
    ASSERT_EQ(std::memcmp(xa.data(), xi.data(), n * sizeof(float)), 0) << "frame " << f;
    ASSERT_EQ(std::memcmp(xl.data(), xp.data(), n * sizeof(float)), 0) << "frame " << f << ": past its deadline nothing ran";
    EXPECT_EQ(sa.prepare_ns, 0);
    EXPECT_EQ(sa.step.iterations, 3) << "the published pose is still the frame's 3 iterations";
    EXPECT_GT(after.prepareNextFrame(), 0) << "frame " << f;
    EXPECT_GT(late.prepareNextFrame(past), 0) << "frame " << f;  // (pending, then skipped)
    plain_error += maxDistance(xp, xc);
    after_error += maxDistance(xa, xc);
  }
  RecordProperty("plain_mean_max_error", ::testing::PrintToString(plain_error / 40));
  RecordProperty("after_mean_max_error", ::testing::PrintToString(after_error / 40));
  EXPECT_GT(plain_error / 40, 1e-3) << "the twist was meant to make 3 iterations lag";
  EXPECT_LT(after_error, 0.8 * plain_error);  // measured 0.69x (mean worst-vertex error 0.175 against 0.253)
}

// The blocked copy of B (blocks of 8 nearby fine vertices, float weights, 16-bit columns, float
// positions and sums; the default) streams what blockPoseTransfer stored and publishes the pose the
// double B gives, to within the blocked kernel's rounding ((n + 4) 2^-24 of sum_j |B_ij| |x_j|, n the
// row's entries) and the float output's (2^-23 of |x_i|), frame after frame.
TEST(LiveRig, TheCompactPoseTransferMatchesTheDoubleBToItsRounding) {
  const Rig rig = makeBarRig();
  LiveRigOptions compact_options, double_options;
  double_options.compact_pose_transfer = false;
  ASSERT_TRUE(compact_options.compact_pose_transfer);  // the default
  LiveRig compact(rig, compact_options), wide(rig, double_options);
  compact.bindLabels(labelTable());
  wide.bindLabels(labelTable());
  EXPECT_EQ(wide.poseTransferBytes(), rig.pose_transfer.bytes());
  const BlockedPoseTransfer blocked = blockPoseTransfer(
      rig.pose_transfer, std::span<const double>(rig.fine_vertices.data(), static_cast<std::size_t>(rig.fine_vertices.size())));
  EXPECT_EQ(compact.poseTransferBytes(), blocked.bytes());
  EXPECT_GE(blocked.fill(rig.pose_transfer.nonzeros()), 1.0);
  double row_sum = 0.0;  // the largest sum_j |B_ij|
  std::int32_t row_entries = 0;  // the most entries in a row
  for (std::int32_t i = 0; i < rig.pose_transfer.rows; ++i) {
    double sum = 0.0;
    for (std::int32_t k = rig.pose_transfer.row_offsets[i]; k < rig.pose_transfer.row_offsets[i + 1]; ++k)
      sum += std::abs(rig.pose_transfer.weights[static_cast<std::size_t>(k)]);
    row_sum = std::max(row_sum, sum);
    row_entries = std::max(row_entries, rig.pose_transfer.row_offsets[i + 1] - rig.pose_transfer.row_offsets[i]);
  }
  const std::size_t n = static_cast<std::size_t>(compact.fineVertexCount()) * 3;
  std::vector<float> xc(n), xw(n);
  double largest = 0.0, largest_ratio = 0.0;
  for (int f = 0; f < 60; ++f) {
    const MarkerFrame frame = makeFrame(rig, movedMarkers(rig, 0.02 * f, -0.01 * f, Eigen::Vector3d(0, 0.005 * f, 0)),
                                        std::vector<bool>(kMarkers, true), static_cast<std::uint64_t>(f));
    compact.processFrame(frame, StepBudget{3}, xc.data(), nullptr);
    wide.processFrame(frame, StepBudget{3}, xw.data(), nullptr);
    // The step is the same in both: only the product differs.
    double x_tet = 0.0;
    ASSERT_TRUE(compact.deformer().paddedPositions().empty()) << "the compact path reads float positions";
    for (const float v : compact.deformer().paddedFloatPositions()) x_tet = std::max(x_tet, std::abs(static_cast<double>(v)));
    for (std::size_t i = 0; i < n; ++i) {
      const double difference = std::abs(static_cast<double>(xc[i]) - static_cast<double>(xw[i]));
      const double bound = (row_entries + 4.0) * 0x1p-24 * row_sum * x_tet + 0x1p-23 * std::abs(static_cast<double>(xw[i]));
      ASSERT_LE(difference, bound) << "frame " << f << " value " << i;
      largest = std::max(largest, difference);
      largest_ratio = std::max(largest_ratio, difference / bound);
    }
  }
  RecordProperty("largest_difference", ::testing::PrintToString(largest));
  RecordProperty("largest_fraction_of_bound", ::testing::PrintToString(largest_ratio));
}

// With and without the coarse level (the rig as its own coarse level), the temporal prediction and
// the volume constraint (linearized after every accepted frame: a transposed product and a solve).
class LiveRigAllocations : public ::testing::TestWithParam<bool> {};

TEST_P(LiveRigAllocations, NonePerFrameAfterWarmUp) {
  // The far end is a region driven by its four markers (the fit runs every frame).
  Rig rig = makeBarRig(false, /*far_region=*/true);
  rig.marker_regions.push_back(RigMarkerRegion{0, {8, 9, 10, 11}});
  LiveRigOptions options;
  options.normals = true;
  const bool coarse = GetParam();
  // Without the coarse level: the plain settings; with it: the defaults (the prediction, the
  // implicit guard, the volume constraint) and iterations after publishing.
  if (coarse) {
    options.solver.after_publish_iterations = 2;
  } else {
    options.solver = SolverSettings::plain();
  }
  LiveRig live(rig, options, coarse ? &rig : nullptr);
  std::vector<std::string> labels = labelTable();
  labels[6] = "";  // one rig marker never named
  live.bindLabels(labels);
  const std::size_t n = static_cast<std::size_t>(live.fineVertexCount()) * 3;
  std::vector<float> x(n), nrm(n);
  // Frames made up front: dropouts, returns, a held stretch, unknown ids, a rejected sample.
  std::vector<MarkerFrame> frames;
  for (int f = 0; f < 120; ++f) {
    std::vector<bool> valid(kMarkers, true);
    valid[2] = f < 20 || f > 50;
    if (f >= 70 && f < 80) valid.assign(kMarkers, false);
    std::vector<Eigen::Vector3d> markers = movedMarkers(rig, 0.01 * f, 0.005 * f, Eigen::Vector3d::Zero());
    if (f == 60) markers[4].x() += 100.0;  // an implausible sample (rejected)
    frames.push_back(makeFrame(rig, markers, valid, static_cast<std::uint64_t>(f)));
    Marker& unknown = frames.back().markers[frames.back().marker_count++];
    unknown.id = 4000;
    unknown.valid = 1;
  }
  live.processFrame(frames[0], StepBudget{3}, x.data(), nrm.data());  // warm-up
  std::uint32_t flags = 0;
  Eigen::internal::set_is_malloc_allowed(false);
  const std::uint64_t before = test::allocationCount();
  for (std::size_t f = 1; f < frames.size(); ++f) {
    flags |= live.processFrame(frames[f], StepBudget{3}, x.data(), nrm.data()).flags;
    if (f % 2 == 0) live.prepareNextFrame();  // else the next processFrame runs it first
  }
  live.writeLastPose(x.data(), nrm.data());
  const std::uint64_t after = test::allocationCount();
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_EQ(after - before, 0u);
  // Every path ran.
  EXPECT_EQ(live.deformer().hasLinearConstraint(), coarse);
  EXPECT_TRUE(flags & kLivePoseHeld);
  EXPECT_TRUE(flags & kLiveMarkersPredicted);
  EXPECT_TRUE(flags & kLiveMarkersBlending);
  EXPECT_TRUE(flags & kLiveMarkersRejected);
}
INSTANTIATE_TEST_SUITE_P(CoarseLevel, LiveRigAllocations, ::testing::Bool(),
                         [](const ::testing::TestParamInfo<bool>& i) { return i.param ? "WithCoarseLevel" : "Plain"; });

TEST(LiveRig, NormalsAreUnitAndOutward) {
  BoundBar bar(withNormals());
  const Rig& rig = bar.rig;
  LiveRig& live = bar.live;
  const std::size_t n = bar.floats();
  const auto rest = live.restPositions();
  auto check = [&](std::span<const float> x, std::span<const float> normals, const char* what) {
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (std::size_t v = 0; v < n; v += 3) centroid += Eigen::Vector3d(x[v], x[v + 1], x[v + 2]) / static_cast<double>(n / 3);
    for (std::size_t v = 0; v < n; v += 3) {
      const Eigen::Vector3d nv(normals[v], normals[v + 1], normals[v + 2]);
      ASSERT_NEAR(nv.norm(), 1.0, 1e-6) << what << " vertex " << v / 3;
      const Eigen::Vector3d r(rest[v], rest[v + 1], rest[v + 2]);
      // A vertex inside the x = 0 or x = 2 side (not on an edge of the box) keeps the side's
      // normal (-x or +x): the motions below turn about z near the x sides only a little and about
      // x not at all.
      const bool inside_y = r.y() > 0.5 && r.y() < 1.5, inside_z = r.z() > 0.5 && r.z() < 7.5;
      if (inside_y && inside_z && r.x() < 0.5) {
        EXPECT_LT(nv.x(), -0.9) << what << " vertex " << v / 3;
      }
      if (inside_y && inside_z && r.x() > 1.5) {
        EXPECT_GT(nv.x(), 0.9) << what << " vertex " << v / 3;
      }
    }
  };
  // At rest (the box is convex: every normal points away from the centroid).
  check(rest, live.restNormals(), "rest");
  for (std::size_t v = 0; v < n; v += 3) {
    const Eigen::Vector3d d = Eigen::Vector3d(rest[v], rest[v + 1], rest[v + 2]) - Eigen::Vector3d(1, 1, 4);
    EXPECT_GT(d.dot(Eigen::Vector3d(live.restNormals()[v], live.restNormals()[v + 1], live.restNormals()[v + 2])), 0.0);
  }
  // Deformed: a mild twist and tilt.
  std::vector<float> x(n), nrm(n);
  const std::vector<bool> all(kMarkers, true);
  for (int f = 0; f < 30; ++f)
    live.processFrame(makeFrame(rig, movedMarkers(rig, 0.01 * f, 0.0, Eigen::Vector3d(0.01 * f, 0, 0)), all, static_cast<std::uint64_t>(f)), StepBudget{3}, x.data(), nrm.data());
  check(x, nrm, "deformed");
  // The area-weighted sum over a closed mesh: sum_v |n_v| A_v n_v is not zero, but the volume
  // from the published triangles stays positive (outward orientation kept).
  double volume = 0.0;
  const auto tri = live.fineTriangles();
  for (std::size_t f = 0; f < tri.size(); f += 3) {
    const auto p = [&](std::int32_t v) { return Eigen::Vector3d(x[static_cast<std::size_t>(v) * 3], x[static_cast<std::size_t>(v) * 3 + 1], x[static_cast<std::size_t>(v) * 3 + 2]); };
    volume += p(tri[f]).dot(p(tri[f + 1]).cross(p(tri[f + 2]))) / 6.0;
  }
  EXPECT_NEAR(volume, 2.0 * 2.0 * 8.0, 0.5);
}

TEST(LiveRig, DegenerateNeighbourhoodGivesAFiniteUnitNormal) {
  const Rig rig = makeBarRig(/*extra_degenerate_triangle=*/true);
  LiveRigOptions options;
  options.normals = true;
  LiveRig live(rig, options);
  live.bindLabels(labelTable());
  const std::size_t n = static_cast<std::size_t>(live.fineVertexCount()) * 3;
  std::vector<float> x(n), nrm(n);
  const std::vector<bool> all(kMarkers, true);
  std::vector<float> previous;
  for (int f = 0; f < 10; ++f) {
    live.processFrame(makeFrame(rig, movedMarkers(rig, 0.05 * f, 0.0, Eigen::Vector3d::Zero()), all, static_cast<std::uint64_t>(f)), StepBudget{3}, x.data(), nrm.data());
    for (std::size_t v = n - 9; v < n; v += 3) {
      const Eigen::Vector3d nv(nrm[v], nrm[v + 1], nrm[v + 2]);
      ASSERT_TRUE(nv.allFinite());
      EXPECT_NEAR(nv.norm(), 1.0, 1e-6);
      // The three coincident vertices have only a zero-area triangle: they keep their rest normal.
      EXPECT_EQ(nrm[v], live.restNormals()[v]);
    }
  }
}

TEST(LiveRig, RegionTargetsDriveTheStepWhenNoMarkerIsMeasured) {
  // The hook for pose sensors: a region target set before processFrame makes the frame step even
  // though every marker is occluded; without it the pose is held.
  const Rig rig = makeBarRig(false, /*far_region=*/true);
  LiveRig live(rig);
  live.bindLabels(labelTable());
  ASSERT_EQ(live.regionTargets().size(), 1u);
  std::vector<float> x(static_cast<std::size_t>(live.fineVertexCount()) * 3);
  const std::vector<bool> none(kMarkers, false);
  const auto frame = [&](std::uint64_t f) { return makeFrame(rig, movedMarkers(rig, 0.0, 0.0, Eigen::Vector3d::Zero()), none, f); };
  EXPECT_TRUE(live.processFrame(frame(0), StepBudget{3}, x.data(), nullptr).flags & kLivePoseHeld);
  const Eigen::Isometry3d turn = Eigen::Translation3d(1.0, 1.0, 0.0) * Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()) *
                                 Eigen::Translation3d(-1.0, -1.0, 0.0);
  RigidTransform target;
  target.rotation = Eigen::Quaterniond(turn.rotation());
  target.translation = turn.translation();
  live.setRegionTarget(0, target);
  live.setRegionTarget(7, target);  // out of range: ignored
  const LiveFrameStats s = live.processFrame(frame(1), StepBudget{3}, x.data(), nullptr);
  EXPECT_FALSE(s.flags & kLivePoseHeld);
  EXPECT_EQ(s.step.iterations, 3);
  EXPECT_TRUE(live.regionTargets()[0].rotation.isApprox(target.rotation));
  // The far end's fine vertices (z = 8) sit exactly on the region's transform.
  const auto rest = live.restPositions();
  int checked = 0;
  for (std::size_t v = 0; v < rest.size(); v += 3) {
    if (rest[v + 2] < 7.99f) continue;
    const Eigen::Vector3d expected = turn * Eigen::Vector3d(rest[v], rest[v + 1], rest[v + 2]);
    EXPECT_LT((Eigen::Vector3d(x[v], x[v + 1], x[v + 2]) - expected).norm(), 1e-5);
    ++checked;
  }
  EXPECT_EQ(checked, 9);
  // The next frame without a new region target holds again.
  EXPECT_TRUE(live.processFrame(frame(2), StepBudget{3}, x.data(), nullptr).flags & kLivePoseHeld);
}

// A region driven by a marker cluster (RigMarkerRegion): the bar's far end (z >= 7) follows the
// best rigid fit of its four markers (z = 7.5). The markers move by a twist growing along the bar,
// a tilt and a shift, so the four far markers move rigidly: the region lands exactly on that
// motion from the first frame, where the same rig without the region lags by a tenth of the bar's
// width and more after 3 iterations. With one of the four occluded, its prediction (carried by
// the body under it) keeps the fit within 1 % of the bar's width.
TEST(LiveRigMarkerRegion, TheRegionFollowsTheBestRigidFitOfItsMarkers) {
  Rig rig = makeBarRig(false, /*far_region=*/true);
  rig.marker_regions.push_back(RigMarkerRegion{0, {8, 9, 10, 11}});
  ASSERT_EQ(validateRig(rig), "");
  const double twist = 1.2, tilt = 0.3;
  const Eigen::Vector3d shift(0.4, -0.2, 0.3);
  // The far markers' rigid motion: p -> tilt * (Rz(twist * 7.5 / 8) (p - axis) + axis) + shift.
  const auto far_motion = [&](const Eigen::Vector3d& p) {
    const Eigen::Vector3d axis(1.0, 1.0, 0.0);
    return Eigen::Vector3d(Eigen::AngleAxisd(tilt, Eigen::Vector3d::UnitX()) *
                               (Eigen::AngleAxisd(twist * 7.5 / 8.0, Eigen::Vector3d::UnitZ()) * (p - axis) + axis) +
                           shift);
  };
  const auto far_error = [&](const LiveRig& live) {
    double worst = 0.0;
    const std::span<const double> x = live.deformer().positions();
    for (std::int32_t v = 0; v < rig.body_vertex_count; ++v) {
      const Eigen::Vector3d p = rig.tet_mesh.vertices.row(v).transpose();
      if (p.z() < 7.0) continue;
      const std::size_t i = 3 * static_cast<std::size_t>(v);
      worst = std::max(worst, (Eigen::Vector3d(x[i], x[i + 1], x[i + 2]) - far_motion(p)).norm());
    }
    return worst;
  };
  std::vector<float> x(static_cast<std::size_t>(rig.fine_vertices.rows()) * 3);  // the plain rig has the same fine mesh
  const std::vector<Eigen::Vector3d> targets = movedMarkers(rig, twist, tilt, shift);
  std::vector<bool> valid(kMarkers, true);
  // No temporal prediction: the first frame jumps from rest, and the prediction would carry that
  // jump on into the second (the same motion), which measures the prediction, not the region.
  LiveRigOptions options;
  options.solver.rotation_extrapolation = 0.0;
  LiveRig live(rig, options);
  live.bindLabels(labelTable());
  live.processFrame(makeFrame(rig, targets, valid, 0), StepBudget{3}, x.data(), nullptr);
  EXPECT_LT(far_error(live), 1e-6);
  const RigidTransform& t = live.regionTargets()[0];
  const Eigen::Vector3d probe(0.3, 1.7, 7.2);
  EXPECT_LT((t.rotation * probe + t.translation - far_motion(probe)).norm(), 1e-6);
  // The same motion without the region: the far end lags.
  const Rig plain = makeBarRig();
  LiveRig without(plain);
  without.bindLabels(labelTable());
  without.processFrame(makeFrame(plain, targets, valid, 0), StepBudget{3}, x.data(), nullptr);
  EXPECT_GT(far_error(without), 0.2);
  // Marker 9 occluded on the next frame (same motion): the prediction carries it with the far end.
  valid[9] = false;
  const LiveFrameStats s = live.processFrame(makeFrame(rig, targets, valid, 1), StepBudget{3}, x.data(), nullptr);
  EXPECT_TRUE(s.flags & kLiveMarkersPredicted);
  // (Its anchor reaches 3 tet rings into the bar, past the rigid far end: 0.0085 measured.)
  EXPECT_LT(far_error(live), 0.02);
}

TEST(LiveRigMarkerRegion, InvalidClustersAreRefused) {
  const Rig base = makeBarRig(false, /*far_region=*/true);
  const auto error = [&](const RigMarkerRegion& mr, bool oriented = true) {
    Rig rig = base;
    rig.setup.region_handles[0].oriented = oriented;
    rig.marker_regions.push_back(mr);
    return validateRig(rig);
  };
  EXPECT_EQ(error({0, {8, 9, 10}}), "");
  EXPECT_NE(error({0, {8, 9}}).find("at least 3"), std::string::npos);
  EXPECT_NE(error({1, {8, 9, 10}}).find("names region handle 1"), std::string::npos);
  EXPECT_NE(error({0, {8, 9, 12}}).find("names marker 12"), std::string::npos);
  EXPECT_NE(error({0, {8, 9, 8}}).find("twice"), std::string::npos);
  EXPECT_NE(error({0, {0, 4, 8}}).find("on a line"), std::string::npos);  // (-0.3, 1, z) for z = 0.5, 4, 7.5
  EXPECT_NE(error({0, {8, 9, 10}}, false).find("not oriented"), std::string::npos);
  Rig both = base;
  both.marker_regions.push_back({0, {8, 9, 10}});
  RigPoseSensor sensor;
  sensor.sensor_label = "hydra0";
  sensor.region_handle = 0;
  both.pose_sensors.push_back(sensor);
  EXPECT_NE(validateRig(both).find("driven twice"), std::string::npos);
}

TEST(LiveRig, RejectsInvalidRigsAndOptions) {
  Rig rig = makeBarRig();
  LiveRigOptions bad;
  bad.occlusion_blend_s = -1.0;
  EXPECT_THROW(LiveRig(rig, bad), std::invalid_argument);
  for (const double v : {-1.0, std::numeric_limits<double>::infinity(), std::numeric_limits<double>::quiet_NaN()}) {
    LiveRigOptions speed;
    speed.max_marker_speed_mm_s = v;
    EXPECT_THROW(LiveRig(rig, speed), std::invalid_argument);
    LiveRigOptions floor;
    floor.marker_jump_floor_diagonals = v;
    EXPECT_THROW(LiveRig(rig, floor), std::invalid_argument);
    LiveRigOptions prediction;
    prediction.marker_prediction_bound_diagonals = v;
    EXPECT_THROW(LiveRig(rig, prediction), std::invalid_argument);
  }
  rig.markers[0].vertex_handle = 5;  // not the handle of its vertex
  EXPECT_THROW(LiveRig{rig}, std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------
// The coarse level (tetrig/coarse_level.hpp) through the live rig.

TEST(LiveRigCoarse, RefusesACoarseRigThatDoesNotFit) {
  const Rig rig = makeBarRig();
  Rig renamed = rig;
  renamed.markers[3].label = "Q3";
  EXPECT_THROW(LiveRig(rig, {}, &renamed), std::invalid_argument);
  const Rig with_region = makeBarRig(false, true);
  EXPECT_THROW(LiveRig(rig, {}, &with_region), std::invalid_argument);
  EXPECT_THROW(LiveRig(with_region, {}, &rig), std::invalid_argument);
  // Another rig space (the targets would land elsewhere), and a coarse level of its own: the same
  // checks as a coarse level inside the rig file (coarseLevelMismatch).
  Rig moved = rig;
  moved.alignment.translation.x() += 0.01;
  EXPECT_THROW(LiveRig(rig, {}, &moved), std::invalid_argument);
  Rig nested = rig;
  nested.coarse = std::make_shared<const Rig>(rig);
  EXPECT_THROW(LiveRig(rig, {}, &nested), std::invalid_argument);
  LiveRigOptions bad;
  bad.solver.coarse_iterations = 0;
  EXPECT_THROW(LiveRig(rig, bad, &rig), std::invalid_argument);
  EXPECT_NO_THROW(LiveRig(rig, {}, &rig));
  EXPECT_EQ(LiveRig(rig).coarseLevel(), nullptr);
}

// The rig as its own coarse level: its 10-iteration rotation change starts the frame, so 3
// iterations per frame land nearer the converged pose of a fast twist than the plain chain, and
// the result is written like any other frame.
TEST(LiveRigCoarse, TheCoarseLevelStartsTheFrameNearerTheConvergedPose) {
  const Rig rig = makeBarRig();
  LiveRigOptions options;
  options.solver = SolverSettings::plain();  // the coarse level's own effect, against the plain chain
  LiveRig plain(rig, options), guided(rig, options, &rig);
  ASSERT_NE(guided.coarseLevel(), nullptr);
  plain.bindLabels(labelTable());
  guided.bindLabels(labelTable());
  const std::vector<bool> all(rig.markers.size(), true);
  std::vector<float> xp(static_cast<std::size_t>(plain.fineVertexCount()) * 3), xg = xp;
  LiveFrameStats sg;
  for (int f = 1; f <= 20; ++f) {
    const MarkerFrame frame = makeFrame(rig, movedMarkers(rig, 0.06 * f, 0.02 * f, Eigen::Vector3d::Zero()), all, static_cast<std::uint64_t>(f));
    plain.processFrame(frame, StepBudget{3}, xp.data(), nullptr);
    sg = guided.processFrame(frame, StepBudget{3}, xg.data(), nullptr);
  }
  EXPECT_GT(sg.coarse_ns, 0);
  EXPECT_GE(sg.step.total_ns, sg.coarse_ns);
  // Converged pose of the last frame's targets.
  Deformer converged(rig.tet_mesh, rig.setup);
  HandleTargets targets;
  targets.vertex_positions = guided.vertexTargets();
  targets.region_transforms = guided.regionTargets();
  targets.point_positions = guided.pointTargets();
  converged.step(targets, StepBudget{3000});
  std::vector<float> xc(xp.size());
  std::vector<double> fine(xp.size());
  applyPoseTransfer(rig.pose_transfer.view(), converged.positions().data(), fine.data());
  for (std::size_t i = 0; i < xc.size(); ++i) xc[i] = static_cast<float>(fine[i]);
  const double lag_plain = maxDistance(xp, xc), lag_guided = maxDistance(xg, xc);
  std::printf("bar twisted 3.4 degrees per frame at its end, 3 iterations per frame: %.4f plain, %.4f with the rig as its own "
              "coarse level (bar length 8)\n",
              lag_plain, lag_guided);
  EXPECT_LT(lag_guided, 0.5 * lag_plain);
}

// The bar's far end as an oriented region driven by its four markers, twisted 180 degrees over 8
// frames, 1 iteration per frame, the rig as its own coarse level (20 iterations a frame, so its guide
// is near the converged change): the guide carries the region's turn into every fine tet, and the
// fine level takes it from there alone. A fine level that interpolated the turn again started each
// frame turned twice as far near the far end (CoarseLevel.ItsGuideCarriesTheRegionsTurnOnce) and
// ended the frames 0.35-0.72 from the converged pose (measured); taking it once, 0.09.
TEST(LiveRigCoarse, TheFineLevelTakesTheRegionsTurnFromTheCoarseLevelAlone) {
  Rig rig = makeBarRig(false, /*far_region=*/true);
  rig.marker_regions.push_back(RigMarkerRegion{0, {8, 9, 10, 11}});
  ASSERT_EQ(validateRig(rig), "");
  LiveRigOptions options;
  options.solver = SolverSettings::plain();  // the guide's own effect
  options.solver.coarse_iterations = 20;
  LiveRig guided(rig, options, &rig);
  guided.bindLabels(labelTable());
  const std::vector<bool> all(rig.markers.size(), true);
  std::vector<float> x(static_cast<std::size_t>(guided.fineVertexCount()) * 3);
  double worst = 0.0;
  for (int f = 1; f <= 8; ++f) {
    const MarkerFrame frame = makeFrame(rig, movedMarkers(rig, M_PI * f / 8.0, 0.0, Eigen::Vector3d::Zero()), all,
                                        static_cast<std::uint64_t>(f));
    ASSERT_EQ(guided.processFrame(frame, StepBudget{1}, x.data(), nullptr).step.iterations, 1);
    if (f % 2 != 0) continue;
    // The converged pose of this frame's targets, from the rotations reached (the twist's winding).
    Deformer converged(rig.tet_mesh, rig.setup);
    std::vector<Eigen::Quaterniond> rotations;
    for (std::int32_t t = 0; t < rig.tet_mesh.tetCount(); ++t) rotations.push_back(guided.deformer().rotation(t));
    converged.setRotations(rotations);
    HandleTargets targets;
    targets.vertex_positions = guided.vertexTargets();
    targets.region_transforms = guided.regionTargets();
    targets.point_positions = guided.pointTargets();
    converged.step(targets, StepBudget{2000});
    const std::span<const double> a = guided.deformer().positions(), b = converged.positions();
    for (std::size_t i = 0; i + 2 < a.size(); i += 3)
      worst = std::max(worst, std::hypot(a[i] - b[i], a[i + 1] - b[i + 1], a[i + 2] - b[i + 2]));
  }
  std::printf("far region twisted 180 degrees in 8 frames, 1 iteration per frame, the rig as its own coarse level: worst "
              "distance to converged %.4f (bar width 2)\n",
              worst);
  EXPECT_LT(worst, 0.2);
}

// A frame split into steps (the volume constraint's cold start: one iteration per step; the
// re-prediction of an occluded marker: one iteration, then the rest) reports the inversion guard of
// all its iterations, as an unsplit frame does: guarded_solves summed over the steps.
TEST(LiveRig, ASplitFrameReportsTheGuardOfAllItsIterations) {
  const Rig rig = makeBarRig();
  LiveRigOptions options;
  options.solver = SolverSettings::plain();
  options.solver.inversion_guard = 3.0;
  options.solver.inversion_guard_solves = 1;
  options.solver.inversion_guard_threshold = 1.0;  // every squashed tet is held
  LiveRigOptions constrained = options;
  constrained.solver.volume_constraint = true;
  LiveRig whole(rig, options), split(rig, constrained);
  whole.bindLabels(labelTable());
  split.bindLabels(labelTable());
  ASSERT_FALSE(split.volumeNotKept());
  // The bar squashed to 0.6 of its length: its tets are held in every iteration.
  std::vector<Eigen::Vector3d> squashed;
  for (const RigMarker& m : rig.markers) squashed.emplace_back(m.rest_position.x(), m.rest_position.y(), 0.6 * m.rest_position.z());
  std::vector<float> x(static_cast<std::size_t>(whole.fineVertexCount()) * 3);
  const std::vector<bool> all(kMarkers, true);
  const MarkerFrame first = makeFrame(rig, squashed, all, 0);
  // Unsplit, from rest: the first iteration's global step holds nothing yet (the rest pose squashes
  // no tet), the next two do.
  LiveRig reference(rig, options);
  reference.bindLabels(labelTable());
  const LiveFrameStats unsplit = reference.processFrame(first, StepBudget{3}, x.data(), nullptr);
  ASSERT_EQ(unsplit.step.iterations, 3);
  ASSERT_EQ(unsplit.step.guarded_solves, 2);
  ASSERT_GT(unsplit.step.guarded_tets, 0);
  // From the squashed pose every iteration holds tets (unsplit).
  const LiveFrameStats again = reference.processFrame(makeFrame(rig, squashed, all, 1), StepBudget{3}, x.data(), nullptr);
  ASSERT_EQ(again.step.guarded_solves, 3);
  // The cold start of the volume constraint: three steps of one iteration, the first holding nothing.
  const LiveFrameStats cold = split.processFrame(first, StepBudget{3}, x.data(), nullptr);
  EXPECT_EQ(cold.step.iterations, 3);
  EXPECT_EQ(cold.step.guarded_solves, 2) << "the guard of the second and third steps";
  EXPECT_GT(cold.step.guarded_tets, 0);
  // An occluded marker, from the squashed pose: one iteration, the predictions refreshed, then two more.
  (void)whole.processFrame(first, StepBudget{3}, x.data(), nullptr);
  std::vector<bool> valid(kMarkers, true);
  valid[3] = false;
  const LiveFrameStats refreshed = whole.processFrame(makeFrame(rig, squashed, valid, 1), StepBudget{3}, x.data(), nullptr);
  ASSERT_TRUE(refreshed.flags & kLiveMarkersPredicted);
  EXPECT_EQ(refreshed.step.iterations, 3);
  EXPECT_EQ(refreshed.step.guarded_solves, 3);
  EXPECT_GT(refreshed.step.guarded_tets, 0);
}

// The volume constraint needs a closed fine mesh: on a rig whose fine mesh is open the live rig
// skips it and says so (volumeNotKept), and runs as without it; on a closed one it keeps it.
TEST(LiveRig, TheVolumeIsNotKeptOnAnOpenFineMeshAndSaysSo) {
  const Rig closed = makeBarRig();
  Rig open = closed;
  // Drop the last triangle: one hole.
  open.fine_triangles.conservativeResize(open.fine_triangles.rows() - 1, Eigen::NoChange);
  LiveRigOptions keep;  // the defaults keep the volume
  ASSERT_TRUE(keep.solver.volume_constraint);
  LiveRig kept(closed, keep), skipped(open, keep);
  EXPECT_FALSE(kept.volumeNotKept());
  EXPECT_TRUE(skipped.volumeNotKept());
  EXPECT_FALSE(skipped.deformer().hasLinearConstraint());
  LiveRigOptions without = keep;
  without.solver.volume_constraint = false;
  LiveRig free_rig(open, without);
  EXPECT_FALSE(free_rig.volumeNotKept()) << "not asked for: nothing to say";
  for (LiveRig* live : {&kept, &skipped, &free_rig}) live->bindLabels(labelTable());
  const std::size_t n = static_cast<std::size_t>(kept.fineVertexCount()) * 3;
  std::vector<float> xs(n), xf(n), xk(n);
  for (int f = 0; f < 10; ++f) {
    const MarkerFrame frame = makeFrame(closed, movedMarkers(closed, 0.03 * f, 0.01 * f, Eigen::Vector3d::Zero()),
                                        std::vector<bool>(kMarkers, true), static_cast<std::uint64_t>(f));
    skipped.processFrame(frame, StepBudget{3}, xs.data(), nullptr);
    free_rig.processFrame(frame, StepBudget{3}, xf.data(), nullptr);
    kept.processFrame(frame, StepBudget{3}, xk.data(), nullptr);
    ASSERT_EQ(std::memcmp(xs.data(), xf.data(), n * sizeof(float)), 0) << "frame " << f;
    EXPECT_EQ(skipped.prepareNextFrame(), 0) << "nothing to linearize";
    EXPECT_GT(kept.prepareNextFrame(), 0);
  }
  EXPECT_TRUE(kept.deformer().hasLinearConstraint());
}

}  // namespace
}  // namespace tetrig
