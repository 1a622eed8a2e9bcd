// Rotation extraction. Exact: Horn, "Closed-form solution of absolute orientation using unit
// quaternions" (JOSA A 1987), the max-eigenvector of N(F). Iterative: Mueller et al., "A Robust
// Method to Extract the Rotational Part of Deformations" (MIG 2016).
#include "tetrig/polar.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>

namespace tetrig {

Eigen::Matrix4d hornMatrix(const Eigen::Matrix3d& f) {
  // Expanding tr(R(q)^T F) = sum_ab R_ab(q) F_ab with R(q) quadratic in (w, x, y, z).
  Eigen::Matrix4d n;
  n(0, 0) = f(0, 0) + f(1, 1) + f(2, 2);
  n(1, 1) = f(0, 0) - f(1, 1) - f(2, 2);
  n(2, 2) = -f(0, 0) + f(1, 1) - f(2, 2);
  n(3, 3) = -f(0, 0) - f(1, 1) + f(2, 2);
  n(0, 1) = n(1, 0) = f(2, 1) - f(1, 2);
  n(0, 2) = n(2, 0) = f(0, 2) - f(2, 0);
  n(0, 3) = n(3, 0) = f(1, 0) - f(0, 1);
  n(1, 2) = n(2, 1) = f(0, 1) + f(1, 0);
  n(1, 3) = n(3, 1) = f(0, 2) + f(2, 0);
  n(2, 3) = n(3, 2) = f(1, 2) + f(2, 1);
  return n;
}

Eigen::Quaterniond closestRotation(const Eigen::Matrix3d& f) {
  if (!f.allFinite()) return Eigen::Quaterniond::Identity();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> eigen(hornMatrix(f));
  const Eigen::Vector4d v = eigen.eigenvectors().col(3);  // eigenvalues ascend
  Eigen::Quaterniond q(v[0], v[1], v[2], v[3]);
  const double norm = q.norm();
  if (!(norm > 0.0) || !std::isfinite(norm)) return Eigen::Quaterniond::Identity();
  q.coeffs() /= norm;
  return q;
}

double refineRotation(const Eigen::Matrix3d& f, Eigen::Quaterniond& q, int max_steps, double tolerance) {
  double last_angle = 0.0;
  Eigen::Matrix3d r = q.toRotationMatrix();
  double trace = (r.cwiseProduct(f)).sum();
  double damping = 1.0;  // halved after a rejected step, so an overshoot is not repeated
  for (int step = 0; step < max_steps; ++step) {
    Eigen::Vector3d omega = r.col(0).cross(f.col(0)) + r.col(1).cross(f.col(1)) + r.col(2).cross(f.col(2));
    omega *= damping / (std::abs(trace) + 1e-9);
    const double angle = omega.norm();
    if (!(angle > tolerance)) return 0.0;  // converged; also stops on NaN
    const Eigen::Quaterniond candidate =
        (Eigen::Quaterniond(Eigen::AngleAxisd(angle, omega / angle)) * q).normalized();
    const Eigen::Matrix3d r_candidate = candidate.toRotationMatrix();
    const double trace_candidate = (r_candidate.cwiseProduct(f)).sum();
    if (!(trace_candidate >= trace)) {
      damping *= 0.5;
      continue;
    }
    q = candidate;
    r = r_candidate;
    trace = trace_candidate;
    last_angle = angle;
  }
  return last_angle;
}

double unitVolumeShift(const Eigen::Matrix3d& f, const Eigen::Matrix3d& r) {
  if (!(f.determinant() > 1e-6)) return 0.0;
  // det(A + s I) = s^3 + tr(A) s^2 + c2(A) s + det(A), A = R^T F, c2 = the sum of principal 2x2 minors.
  const Eigen::Matrix3d a = r.transpose() * f;
  const double t = a.trace();
  const double c = a(0, 0) * a(1, 1) - a(0, 1) * a(1, 0) + a(0, 0) * a(2, 2) - a(0, 2) * a(2, 0) + a(1, 1) * a(2, 2) -
                   a(1, 2) * a(2, 1);
  const double d = a.determinant();
  double s = 0.0;
  for (int it = 0; it < 100; ++it) {
    const double value = ((s + t) * s + c) * s + d - 1.0;
    const double slope = (3.0 * s + 2.0 * t) * s + c;
    if (!(slope != 0.0)) return 0.0;
    const double step = value / slope;
    s -= step;
    if (!std::isfinite(s)) return 0.0;
    if (std::abs(step) < 1e-15) break;
  }
  return std::clamp(s, -0.5, 0.5);
}

}  // namespace tetrig
