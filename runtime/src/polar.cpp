// Rotation extraction. Exact: Horn, "Closed-form solution of absolute orientation using unit
// quaternions" (JOSA A 1987), the max-eigenvector of N(F), found as in Theobald's QCP ("Rapid
// calculation of RMSDs using a quaternion-based characteristic polynomial", Acta Cryst. A 2005):
// Newton on the characteristic polynomial, the eigenvector from an adjugate column. Iterative: Mueller et al., "A Robust
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

bool closestRotationByQuartic(const Eigen::Matrix3d& f, Eigen::Quaterniond& q) {
  const Eigen::Matrix4d n = hornMatrix(f);
  // Characteristic polynomial of the traceless symmetric N, by Newton's identities from the power
  // sums p_k = tr(N^k): P(l) = l^4 + c2 l^2 + c1 l + c0, c2 = -p2 / 2, c1 = -p3 / 3, c0 = det N.
  const Eigen::Matrix4d n2 = n * n;
  const double p2 = n2.trace();
  if (!(p2 > 0.0) || !std::isfinite(p2)) return false;
  const double p3 = n2.cwiseProduct(n).sum();  // tr(N^2 N), N symmetric
  const double c2 = -0.5 * p2, c1 = -p3 / 3.0, c0 = n.determinant();
  // Newton from sqrt(p2) (no eigenvalue is larger: sum l_i^2 = p2) down to the largest root: P is
  // convex for l^2 >= p2 / 12, and the largest eigenvalue is at least sqrt(p2 / 12) (four
  // eigenvalues summing to 0), so the steps fall monotonically onto it.
  const double scale = std::sqrt(p2);
  double lambda = scale;
  bool converged = false;
  for (int step = 0; step < 32 && !converged; ++step) {
    const double l2 = lambda * lambda;
    const double value = (l2 + c2) * l2 + c1 * lambda + c0;
    const double slope = (4.0 * l2 + 2.0 * c2) * lambda + c1;
    if (!(slope > 0.0)) return false;  // at a multiple root: leave it to the eigensolver
    const double change = value / slope;
    lambda -= change;
    converged = std::abs(change) <= 1e-12 * scale;
  }
  if (!converged) return false;  // slow (linear) convergence: a near-multiple largest root
  // The eigenvector from the adjugate of A = N - lambda I: for a simple eigenvalue adj(A) = c v v^T,
  // so its column j with the largest diagonal |c| v_j^2 is the best-conditioned multiple of v.
  const Eigen::Matrix4d a = n - lambda * Eigen::Matrix4d::Identity();
  const auto minor = [&](int skip_row, int skip_col) {
    int r[3], c[3];
    for (int i = 0, k = 0; i < 4; ++i)
      if (i != skip_row) r[k++] = i;
    for (int i = 0, k = 0; i < 4; ++i)
      if (i != skip_col) c[k++] = i;
    return a(r[0], c[0]) * (a(r[1], c[1]) * a(r[2], c[2]) - a(r[1], c[2]) * a(r[2], c[1])) -
           a(r[0], c[1]) * (a(r[1], c[0]) * a(r[2], c[2]) - a(r[1], c[2]) * a(r[2], c[0])) +
           a(r[0], c[2]) * (a(r[1], c[0]) * a(r[2], c[1]) - a(r[1], c[1]) * a(r[2], c[0]));
  };
  int best = 0;
  double best_diagonal = 0.0;
  for (int j = 0; j < 4; ++j) {
    const double d = std::abs(minor(j, j));
    if (d > best_diagonal) {
      best_diagonal = d;
      best = j;
    }
  }
  // Too small: the largest eigenvalue is (nearly) repeated and the adjugate loses its digits.
  if (!(best_diagonal >= 1e-6 * scale * scale * scale)) return false;
  Eigen::Vector4d v;
  for (int i = 0; i < 4; ++i) v[i] = ((i + best) % 2 == 0 ? 1.0 : -1.0) * minor(best, i);  // adj(A)(i, best)
  const double norm = v.norm();
  if (!(norm > 0.0) || !std::isfinite(norm)) return false;
  v /= norm;
  q = Eigen::Quaterniond(v[0], v[1], v[2], v[3]);
  return true;
}

Eigen::Quaterniond closestRotation(const Eigen::Matrix3d& f) {
  if (!f.allFinite()) return Eigen::Quaterniond::Identity();
  Eigen::Quaterniond fast;
  if (closestRotationByQuartic(f, fast)) return fast;
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
