// Plausibility of an automatic marker alignment: fit scale, extent coverage, distances (see
// alignment_checks.hpp).
#include "tetrig/rigbuild/alignment_checks.hpp"
#include "tetrig/rigbuild/format_number.hpp"

#include "tetrig/rigbuild/align_markers.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace tetrig::rigbuild {
namespace {

std::string percent(double fraction) { return formatNumber("%.3g %%", 100.0 * fraction); }

// Widest horizontal direction of the surface: principal axis of the face centres, weighted by
// area, projected onto the plane perpendicular to `up` (the arm span of a T-pose).
Eigen::Vector3d widestHorizontalAxis(const SurfaceMesh& surface, const Eigen::Vector3d& up) {
  const Eigen::Vector3d h1 = up.unitOrthogonal(), h2 = up.cross(h1);
  double w_sum = 0;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  Eigen::Matrix2d second = Eigen::Matrix2d::Zero();
  for (Eigen::Index f = 0; f < surface.triangles.rows(); ++f) {
    const Eigen::Vector3d a = surface.vertices.row(surface.triangles(f, 0)), b = surface.vertices.row(surface.triangles(f, 1)),
                          c = surface.vertices.row(surface.triangles(f, 2));
    const double w = 0.5 * (b - a).cross(c - a).norm();
    const Eigen::Vector3d m = (a + b + c) / 3.0;
    const Eigen::Vector2d q(m.dot(h1), m.dot(h2));
    w_sum += w;
    mean += w * q;
    second += w * q * q.transpose();
  }
  if (!(w_sum > 0)) return h1;
  mean /= w_sum;
  const Eigen::Matrix2d cov = second / w_sum - mean * mean.transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
  const Eigen::Vector2d major = eig.eigenvectors().col(1);
  return (major.x() * h1 + major.y() * h2).normalized();
}

ExtentCoverage coverage(const SurfaceMesh& surface, const Eigen::Vector3d& axis, const std::vector<Eigen::Vector3d>& positions,
                        const std::vector<std::string>& labels) {
  ExtentCoverage c;
  c.axis = axis;
  const Eigen::VectorXd along = surface.vertices * axis;
  c.mesh_lo = along.minCoeff();
  c.mesh_hi = along.maxCoeff();
  c.marker_lo = positions.front().dot(axis);
  c.marker_hi = c.marker_lo;
  c.label_lo = c.label_hi = labels.front();
  for (std::size_t i = 1; i < positions.size(); ++i) {
    const double v = positions[i].dot(axis);
    if (v < c.marker_lo) {
      c.marker_lo = v;
      c.label_lo = labels[i];
    }
    if (v > c.marker_hi) {
      c.marker_hi = v;
      c.label_hi = labels[i];
    }
  }
  const double extent = c.mesh_hi - c.mesh_lo;
  if (extent > 0) {
    c.gap_lo = (c.marker_lo - c.mesh_lo) / extent;
    c.gap_hi = (c.mesh_hi - c.marker_hi) / extent;
  }
  return c;
}

}  // namespace

std::string AlignmentCheck::failures() const {
  std::string what;
  for (const auto* list : {&scale_failures, &pose_failures}) {
    for (const std::string& f : *list) what += (what.empty() ? "" : "; ") + f;
  }
  return what;
}

std::string AlignmentCheck::summary() const {
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "fit scale %.4g; up: lowest marker %s %+.1f %% of the height from the bottom, highest %s %+.1f %% from the top; "
                "widest horizontal axis: outermost markers %s %+.1f %% and %s %+.1f %% of the width from the ends; "
                "%d of %d markers further than %.3g from the surface; distance median %.3g max %.3g",
                fit_scale, up.label_lo.c_str(), 100.0 * up.gap_lo, up.label_hi.c_str(), 100.0 * up.gap_hi, across.label_lo.c_str(),
                100.0 * across.gap_lo, across.label_hi.c_str(), 100.0 * across.gap_hi, far_markers, markers, far_distance,
                median_distance, max_distance);
  return buf;
}

AlignmentCheck checkAlignment(const SurfaceMesh& surface, const std::string& up_axis, const std::vector<Eigen::Vector3d>& positions,
                              const std::vector<double>& distances, const std::vector<std::string>& labels, double fit_scale,
                              const AlignmentCheckLimits& limits) {
  if (positions.empty() || positions.size() != distances.size() || positions.size() != labels.size()) {
    throw RigBuildError("checkAlignment: positions, distances and labels must be non-empty and of one count");
  }
  if (surface.vertexCount() == 0 || surface.triangleCount() == 0) throw RigBuildError("checkAlignment: the surface is empty");
  AlignmentCheck c;
  c.fit_scale = fit_scale;
  c.markers = static_cast<int>(positions.size());
  const Eigen::Vector3d up = axisVector(up_axis);
  c.up = coverage(surface, up, positions, labels);
  c.across = coverage(surface, widestHorizontalAxis(surface, up), positions, labels);
  c.diagonal = (surface.vertices.colwise().maxCoeff() - surface.vertices.colwise().minCoeff()).norm();
  c.far_distance = limits.far_distance_fraction * c.diagonal;
  std::vector<double> sorted = distances;
  std::sort(sorted.begin(), sorted.end());
  c.median_distance = sorted.size() % 2 ? sorted[sorted.size() / 2] : 0.5 * (sorted[sorted.size() / 2 - 1] + sorted[sorted.size() / 2]);
  c.max_distance = sorted.back();
  for (const double d : distances) c.far_markers += d > c.far_distance ? 1 : 0;

  if (limits.check_scale && !(fit_scale >= limits.min_fit_scale && fit_scale <= limits.max_fit_scale)) {
    c.scale_failures.push_back("fit scale " + formatNumber("%.3g", fit_scale) + " is outside " + formatNumber("%.3g", limits.min_fit_scale) + ".." +
                               formatNumber("%.3g", limits.max_fit_scale));
  }
  if (limits.check_pose) {
    const std::string limit = " (limit " + percent(limits.max_extent_gap) + ")";
    if (c.up.gap_lo > limits.max_extent_gap) {
      c.pose_failures.push_back("the lowest marker (" + c.up.label_lo + ") is " + percent(c.up.gap_lo) +
                                " of the mesh's height above its bottom" + limit);
    }
    if (c.up.gap_hi > limits.max_extent_gap) {
      c.pose_failures.push_back("the highest marker (" + c.up.label_hi + ") is " + percent(c.up.gap_hi) + " of the mesh's height below its top" +
                                limit);
    }
    if (c.across.gap_lo > limits.max_extent_gap || c.across.gap_hi > limits.max_extent_gap) {
      const double short_gap = std::max(c.across.gap_lo, c.across.gap_hi), other = std::min(c.across.gap_lo, c.across.gap_hi);
      const std::string ends = other >= 0 ? percent(c.across.gap_lo) + " and " + percent(c.across.gap_hi) + " of its width short of its ends"
                                          : percent(short_gap) + " of its width short of one end and " + percent(-other) + " beyond the other";
      c.pose_failures.push_back("along the mesh's widest horizontal axis the outermost markers (" + c.across.label_lo + ", " +
                                c.across.label_hi + ") end " + ends + limit);
    }
    const double far_fraction = static_cast<double>(c.far_markers) / c.markers;
    if (far_fraction > limits.max_far_fraction) {
      c.pose_failures.push_back(std::to_string(c.far_markers) + " of " + std::to_string(c.markers) + " markers (" + percent(far_fraction) +
                                ") are further than " + formatNumber("%.3g", c.far_distance) + " (" + percent(limits.far_distance_fraction) +
                                " of the mesh's diagonal) from the surface (limit " + percent(limits.max_far_fraction) + " of the markers)");
    }
  }
  return c;
}

}  // namespace tetrig::rigbuild
