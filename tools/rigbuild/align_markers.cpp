// Marker-to-mesh alignment: axes/unit, coarse heading from principal horizontal axes, then
// similarity ICP with the closed-form least-squares similarity of Umeyama (IEEE PAMI 1991)
// (closed form, weighted). See align_markers.hpp.
#include "tetrig/rigbuild/align_markers.hpp"

#include "tetrig/rigbuild/closest_point.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <limits>

namespace tetrig::rigbuild {
namespace {

struct Similarity {
  double s = 1.0;
  Eigen::Matrix3d r = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Vector3d apply(const Eigen::Vector3d& p) const { return s * (r * p) + t; }
};

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// Angle (in the plane basis h1, h2) of the principal axis of weighted points.
double principalAngle(const std::vector<Eigen::Vector3d>& points, const std::vector<double>& weights, const Eigen::Vector3d& h1,
                      const Eigen::Vector3d& h2) {
  double w_sum = 0;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < points.size(); ++i) {
    mean += weights[i] * Eigen::Vector2d(points[i].dot(h1), points[i].dot(h2));
    w_sum += weights[i];
  }
  mean /= w_sum;
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector2d q = Eigen::Vector2d(points[i].dot(h1), points[i].dot(h2)) - mean;
    cov += weights[i] * q * q.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
  const Eigen::Vector2d major = eig.eigenvectors().col(1);
  return std::atan2(major.y(), major.x());
}

// Weighted least-squares similarity (Umeyama 1991 with per-point weights): dst ~ c R src + t.
// Returns the 4x4 matrix [c R | t]; c = 1 when !scale.
Eigen::Matrix4d weightedSimilarity(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& dst, const std::vector<double>& w, bool scale) {
  double w_sum = 0;
  Eigen::Vector3d mu_s = Eigen::Vector3d::Zero(), mu_d = Eigen::Vector3d::Zero();
  for (Eigen::Index i = 0; i < src.cols(); ++i) {
    const double wi = w[static_cast<std::size_t>(i)];
    w_sum += wi;
    mu_s += wi * src.col(i);
    mu_d += wi * dst.col(i);
  }
  mu_s /= w_sum;
  mu_d /= w_sum;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  double var_s = 0;
  for (Eigen::Index i = 0; i < src.cols(); ++i) {
    const double wi = w[static_cast<std::size_t>(i)];
    cov += wi * (dst.col(i) - mu_d) * (src.col(i) - mu_s).transpose();
    var_s += wi * (src.col(i) - mu_s).squaredNorm();
  }
  cov /= w_sum;
  var_s /= w_sum;
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(cov, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Vector3d sign(1, 1, 1);
  if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0) sign[2] = -1;
  const Eigen::Matrix3d r = svd.matrixU() * sign.asDiagonal() * svd.matrixV().transpose();
  const double c = scale && var_s > 0 ? svd.singularValues().dot(sign) / var_s : 1.0;
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = c * r;
  m.topRightCorner<3, 1>() = mu_d - c * r * mu_s;
  return m;
}

}  // namespace

Eigen::Vector3d axisVector(const std::string& axis) {
  const bool neg = !axis.empty() && axis[0] == '-';
  const std::string a = neg ? axis.substr(1) : (!axis.empty() && axis[0] == '+' ? axis.substr(1) : axis);
  Eigen::Vector3d v;
  if (a == "x" || a == "X") {
    v = Eigen::Vector3d::UnitX();
  } else if (a == "y" || a == "Y") {
    v = Eigen::Vector3d::UnitY();
  } else if (a == "z" || a == "Z") {
    v = Eigen::Vector3d::UnitZ();
  } else {
    throw RigBuildError("unknown axis '" + axis + "': use x, y, z, -x, -y or -z");
  }
  return neg ? Eigen::Vector3d(-v) : v;
}

Eigen::Matrix3d upAxisRotation(const std::string& device_up, const std::string& rig_up) {
  const Eigen::Vector3d up_device = axisVector(device_up);
  const Eigen::Vector3d up_rig = axisVector(rig_up);
  if (up_device.dot(up_rig) < -0.5) {
    // Opposite: a half turn about an axis perpendicular to both.
    const Eigen::Vector3d perp = up_device.cross(Eigen::Vector3d::UnitX()).norm() > 0.5 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
    return Eigen::AngleAxisd(M_PI, perp).toRotationMatrix();
  }
  return Eigen::Quaterniond::FromTwoVectors(up_device, up_rig).toRotationMatrix();
}

AlignmentResult alignMarkers(const std::vector<Eigen::Vector3d>& device_mm, const SurfaceMesh& surface,
                             const AlignmentOptions& options) {
  if (surface.triangleCount() == 0) throw RigBuildError("marker alignment: the surface has no triangles");
  const SurfaceQuery query(surface.vertices, surface.triangles);
  return alignMarkers(device_mm, surface, options, [&query](const Eigen::Vector3d& p) { return query.closest(p); });
}

AlignmentResult alignMarkers(const std::vector<Eigen::Vector3d>& device_mm, const SurfaceMesh& surface,
                             const AlignmentOptions& options, const ClosestPointFunction& closest) {
  if (device_mm.empty()) throw RigBuildError("marker alignment: no markers");
  if (surface.triangleCount() == 0) throw RigBuildError("marker alignment: the surface has no triangles");
  const std::size_t n = device_mm.size();

  AlignmentResult result;
  RigAlignment& out = result.alignment;
  out.device_up = options.device_up;
  out.rig_up = options.rig_up;
  out.rig_units_per_mm = options.rig_units_per_mm;

  // 1. Axes and unit.
  const Eigen::Vector3d up_rig = axisVector(options.rig_up);
  const Eigen::Matrix3d base = options.rig_units_per_mm * upAxisRotation(options.device_up, options.rig_up);
  std::vector<Eigen::Vector3d> p(n);
  for (std::size_t i = 0; i < n; ++i) p[i] = base * device_mm[i];

  auto evaluate = [&](const Similarity& t, std::vector<Eigen::Vector3d>* targets, std::vector<double>* dist) {
    double sum = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const ClosestPoint c = closest(t.apply(p[i]));
      if (targets) (*targets)[i] = c.point + options.marker_offset * c.normal;
      if (dist) (*dist)[i] = c.distance;
      sum += c.distance;
    }
    return sum / static_cast<double>(n);
  };

  Similarity best;
  if (options.mode == "matrix") {
    if (options.matrix.size() != 12) throw RigBuildError("marker alignment: the matrix needs 12 numbers (3x4 row-major)");
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) out.linear(r, c) = options.matrix[static_cast<std::size_t>(r * 4 + c)];
      out.translation[r] = options.matrix[static_cast<std::size_t>(r * 4 + 3)];
    }
    if (!out.linear.allFinite() || std::abs(out.linear.determinant()) < 1e-300) {
      throw RigBuildError("marker alignment: the given matrix is not invertible");
    }
    out.fit_scale = std::cbrt(std::abs(out.linear.determinant())) / options.rig_units_per_mm;
  } else if (options.mode == "units") {
    out.linear = base;
    out.translation.setZero();
    out.fit_scale = 1.0;
  } else if (options.mode == "auto") {
    if (n < 3) throw RigBuildError("marker alignment: automatic alignment needs at least 3 markers (use alignment \"matrix\")");
    // 2. Coarse candidates.
    Eigen::Vector3d h1 = up_rig.unitOrthogonal();
    Eigen::Vector3d h2 = up_rig.cross(h1);
    std::vector<Eigen::Vector3d> centres;
    std::vector<double> areas;
    Eigen::Vector3d s_min = surface.vertices.colwise().minCoeff(), s_max = surface.vertices.colwise().maxCoeff();
    for (Eigen::Index f = 0; f < surface.triangles.rows(); ++f) {
      const Eigen::Vector3d a = surface.vertices.row(surface.triangles(f, 0)), b = surface.vertices.row(surface.triangles(f, 1)),
                            c = surface.vertices.row(surface.triangles(f, 2));
      centres.push_back((a + b + c) / 3.0);
      areas.push_back(0.5 * (b - a).cross(c - a).norm() + 1e-300);
    }
    Eigen::Vector3d m_min = p[0], m_max = p[0];
    for (const Eigen::Vector3d& q : p) {
      m_min = m_min.cwiseMin(q);
      m_max = m_max.cwiseMax(q);
    }
    const double mesh_height = (s_max - s_min).dot(up_rig.cwiseAbs());
    const double marker_height = (m_max - m_min).dot(up_rig.cwiseAbs());
    double s0 = 1.0;
    if (options.icp_scale && marker_height > 0 && mesh_height > 0) s0 = mesh_height / marker_height;
    const double alpha_surface = principalAngle(centres, areas, h1, h2);
    const double alpha_markers = principalAngle(p, std::vector<double>(n, 1.0), h1, h2);
    const Eigen::Vector3d s_centre = 0.5 * (s_min + s_max);
    const Eigen::Vector3d m_centre = 0.5 * (m_min + m_max);

    std::vector<Eigen::Vector3d> targets(n);
    double best_score = std::numeric_limits<double>::infinity();
    const int iterations = std::max(options.icp_iterations, 0);
    // One ICP run from `t`: pairs, closed-form fit (similarity when `scale`), until the mean
    // distance stops changing.
    std::vector<double> weights(n, 1.0);
    auto icp = [&](Similarity t, bool scale, int max_iterations, double progress_from, double progress_span, int* used) {
      double last = evaluate(t, &targets, nullptr);
      int it = 0;
      for (; it < max_iterations; ++it) {
        Eigen::Matrix3Xd src(3, static_cast<Eigen::Index>(n)), dst(3, static_cast<Eigen::Index>(n));
        for (std::size_t i = 0; i < n; ++i) {
          src.col(static_cast<Eigen::Index>(i)) = (scale ? 1.0 : t.s) * p[i];
          dst.col(static_cast<Eigen::Index>(i)) = targets[i];
        }
        // Residual weights |r|^(p-2): iteratively reweighted least squares for the L_p norm.
        for (std::size_t i = 0; i < n; ++i) {
          const double d = (t.apply(p[i]) - targets[i]).norm();
          weights[i] = options.fit_power == 2.0 ? 1.0 : std::pow(std::max(d, 1e-4 * mesh_height), options.fit_power - 2.0);
        }
        Eigen::Matrix4d m = weightedSimilarity(src, dst, weights, scale);
        Similarity next;
        if (scale) {
          next.s = std::cbrt(m.topLeftCorner<3, 3>().determinant());
          const double lo = s0 * (1.0 - options.max_scale_change), hi = s0 * (1.0 + options.max_scale_change);
          if (!std::isfinite(next.s) || next.s < lo || next.s > hi) {
            next.s = std::clamp(std::isfinite(next.s) ? next.s : s0, lo, hi);
            for (std::size_t i = 0; i < n; ++i) src.col(static_cast<Eigen::Index>(i)) = next.s * p[i];
            m = weightedSimilarity(src, dst, weights, false);
            next.r = m.topLeftCorner<3, 3>();
          } else {
            next.r = m.topLeftCorner<3, 3>() / next.s;
          }
        } else {
          next.s = t.s;
          next.r = m.topLeftCorner<3, 3>();
        }
        next.t = m.topRightCorner<3, 1>();
        const double score = evaluate(next, &targets, nullptr);
        t = next;
        if (options.progress) options.progress(progress_from + progress_span * (it + 1.0) / std::max(max_iterations, 1));
        if (std::abs(last - score) <= 1e-9 * std::max(mesh_height, 1e-12)) {
          ++it;
          break;
        }
        last = score;
      }
      if (used) *used = it;
      return t;
    };
    // Phase A: rigid ICP at the height-based scale from each heading candidate (a free scale
    // would shrink the cloud onto the surface: sum of distances -> 0 as the scale -> 0).
    for (int cand = 0; cand < 4; ++cand) {
      Similarity t;
      t.s = s0;
      // Rotation about up taking the marker axis angle onto the surface's (+ cand quarter turns).
      t.r = Eigen::AngleAxisd(alpha_surface - alpha_markers + cand * M_PI / 2, up_rig).toRotationMatrix();
      t.t = s_centre - t.s * (t.r * m_centre);
      int used = 0;
      t = icp(t, false, iterations, cand * 0.2, 0.2, &used);
      const double score = evaluate(t, nullptr, nullptr);
      if (score < best_score) {
        best_score = score;
        best = t;
        result.candidate = cand;
        result.iterations = used;
      }
    }
    // Phase B: similarity refinement from the best candidate, scale within max_scale_change of s0.
    if (options.icp_scale && options.max_scale_change > 0) {
      int used = 0;
      best = icp(best, true, iterations, 0.8, 0.2, &used);
      result.iterations += used;
    }
    out.linear = best.s * best.r * base;
    out.translation = best.t;
    out.fit_scale = best.s;
  } else {
    throw RigBuildError("marker alignment: unknown mode '" + options.mode + "' (auto, units, matrix)");
  }

  result.rig_positions.resize(n);
  result.distances.resize(n);
  double sum = 0;
  for (std::size_t i = 0; i < n; ++i) {
    result.rig_positions[i] = out.apply(device_mm[i]);
    result.distances[i] = closest(result.rig_positions[i]).distance;
    sum += result.distances[i];
  }
  result.mean_distance = sum / static_cast<double>(n);
  result.median_distance = median(result.distances);
  result.max_distance = *std::max_element(result.distances.begin(), result.distances.end());
  return result;
}

}  // namespace tetrig::rigbuild
