// The tracking measure: the change of each measured marker's distance to its skin point
// (tracking_measure.hpp).
#include "tetrig/rigbuild/tracking_measure.hpp"

#include "tetrig/live_rig.hpp"
#include "tetrig/rigbuild/closest_point.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>

namespace tetrig::rigbuild {

Percentiles percentilesOf(std::vector<double> v) {
  Percentiles p;
  p.count = v.size();
  if (v.empty()) return p;
  std::sort(v.begin(), v.end());
  const auto at = [&v](double q) {
    const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size())));
    return v[std::min(v.size() - 1, rank == 0 ? 0 : rank - 1)];
  };
  p.median = at(0.5);
  p.p90 = at(0.9);
  p.p99 = at(0.99);
  p.max = v.back();
  return p;
}

namespace {

// Barycentric coordinates of p (a point of triangle abc) with respect to a, b, c.
Eigen::Vector3d barycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d v0 = b - a, v1 = c - a, v2 = p - a;
  const double d00 = v0.dot(v0), d01 = v0.dot(v1), d11 = v1.dot(v1), d20 = v2.dot(v0), d21 = v2.dot(v1);
  const double den = d00 * d11 - d01 * d01;
  if (!(std::abs(den) > 0.0)) return {1.0, 0.0, 0.0};  // a degenerate triangle: its first corner
  const double v = (d11 * d20 - d01 * d21) / den, w = (d00 * d21 - d01 * d20) / den;
  return {1.0 - v - w, v, w};
}

}  // namespace

TrackingMeasure::TrackingMeasure(const Rig& rig) : rig_(rig), samples_(rig.markers.size()) {
  mm_per_unit_ = rig.alignment.rig_units_per_mm > 0.0 ? 1.0 / rig.alignment.rig_units_per_mm : 1.0;
  const SurfaceQuery surface(rig.fine_vertices, rig.fine_triangles);
  skin_.reserve(rig.markers.size());
  for (const RigMarker& m : rig.markers) {
    const Eigen::Vector3d rest = rig.tet_mesh.vertices.row(m.tet_vertex).transpose();
    const ClosestPoint cp = surface.closest(rest);
    SkinPoint s;
    s.triangle = cp.face;
    const auto corner = [&](int k) { return Eigen::Vector3d(rig.fine_vertices.row(rig.fine_triangles(cp.face, k)).transpose()); };
    const Eigen::Vector3d w = barycentric(cp.point, corner(0), corner(1), corner(2));
    s.a = w[0];
    s.b = w[1];
    s.c = w[2];
    s.rest_distance = (rest - (s.a * corner(0) + s.b * corner(1) + s.c * corner(2))).norm();
    skin_.push_back(s);
  }
}

void TrackingMeasure::addFrame(std::span<const float> x, std::span<const Eigen::Vector3d> markers, std::span<const std::uint8_t> measured) {
  ++frames_;
  for (std::size_t m = 0; m < skin_.size() && m < markers.size() && m < measured.size(); ++m) {
    if (!measured[m]) continue;
    const SkinPoint& s = skin_[m];
    Eigen::Vector3d p = Eigen::Vector3d::Zero();
    const double w[3] = {s.a, s.b, s.c};
    for (int k = 0; k < 3; ++k) {
      const auto v = static_cast<std::size_t>(rig_.fine_triangles(s.triangle, k)) * 3;
      p += w[k] * Eigen::Vector3d(x[v], x[v + 1], x[v + 2]);
    }
    samples_[m].push_back(std::abs((markers[m] - p).norm() - s.rest_distance) * mm_per_unit_);
  }
}

void TrackingMeasure::addFrame(std::span<const float> x, const LiveRig& live) {
  std::vector<std::uint8_t> measured(rig_.markers.size(), 0);
  for (std::size_t m = 0; m < measured.size(); ++m) {
    measured[m] = live.markerMeasured()[m] != 0 && live.markerState(static_cast<std::int32_t>(m)) == MarkerTrackState::kMeasured;
  }
  addFrame(x, live.markerTargets(), measured);
}

Percentiles TrackingMeasure::all() const {
  std::vector<double> v;
  for (const auto& s : samples_) v.insert(v.end(), s.begin(), s.end());
  return percentilesOf(std::move(v));
}

Percentiles TrackingMeasure::marker(std::size_t index) const { return percentilesOf(samples_.at(index)); }

}  // namespace tetrig::rigbuild
