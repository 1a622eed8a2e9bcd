// Rotation extraction: the rotational part R of a deformation gradient F (paper eq. 2.7-2.8).
//
// Both functions return the proper rotation (det R = +1) that maximises tr(R^T F), i.e. the R
// minimising ||F - R||_F over SO(3). For det F > 0 that is the polar factor (F = R S, S
// symmetric positive definite); for inverted F (det F < 0) it is U diag(1, 1, -1) V^T from the SVD
// F = U Sigma V^T; for singular F it is one of the minimisers. Never NaN for finite F.
//
// - closestRotation: exact, by Horn's method: tr(R(q)^T F) = q^T N(F) q for unit quaternions q,
//   so the maximiser is the eigenvector of the largest eigenvalue of the symmetric 4x4 N(F).
//   The largest eigenvalue by Newton's method on N's characteristic polynomial and its
//   eigenvector from the adjugate of N - lambda I (closestRotationByQuartic, a few hundred
//   nanoseconds), else, where the largest eigenvalue is (nearly) repeated, Eigen's eigensolver
//   (a few microseconds). Used at load, for rigid-group averages, marker-cluster fits and as
//   the fallback of the frame kernel for inverted tets.
// - refineRotation: the warm-started iteration of Mueller, Bender, Chentanez and Macklin,
//   "A Robust Method to Extract the Rotational Part of Deformations" (MIG 2016): rotate q by
//   omega = sum_i r_i x f_i / (|sum_i r_i . f_i| + eps) (r_i, f_i: columns of R(q) and F), the
//   ascent direction of tr(R^T F). A step is kept only if it does not lower tr(R^T F), so the
//   ARAP energy never rises. Returns the angle of the last step taken (0 when converged).
// Neither allocates; both are safe on any thread.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstddef>

namespace tetrig {

Eigen::Quaterniond closestRotation(const Eigen::Matrix3d& f);

// The fast path of closestRotation: true and q set when the largest eigenvalue of N(F) converged
// quadratically and its adjugate column is well conditioned; false (q untouched) otherwise.
bool closestRotationByQuartic(const Eigen::Matrix3d& f, Eigen::Quaterniond& q);

double refineRotation(const Eigen::Matrix3d& f, Eigen::Quaterniond& q, int max_steps, double tolerance = 1e-12);

// Horn's N(F): q^T N q = tr(R(q)^T F) for unit q = (w, x, y, z).
Eigen::Matrix4d hornMatrix(const Eigen::Matrix3d& f);

// The volume term's target shift (DeformerOptions::volume_weight; the frame kernel computes it in
// float, rotation_kernel.cpp): the s with det(F + s R) = 1, so that T = F + s R is F pushed along
// its rotation R to unit volume; in double, Newton to convergence, clamped to [-0.5, 0.5]; 0 when
// det F <= 1e-6 (inverted and degenerate tets take no volume term: w = 0 for them). The reference
// for tests and for the exact energy of tools (a [(1 - w) ||F - R||^2 + w ||F - T||^2], ||F - T||^2 = 3 s^2).
double unitVolumeShift(const Eigen::Matrix3d& f, const Eigen::Matrix3d& r);

// Best rigid fit of n point pairs (Kabsch, solved by Horn's method above): the rotation R and
// translation t minimising sum_i |b_i - (R a_i + t)|^2, from the centroids ca, cb and the cross-
// covariance H = sum_i (b_i - cb)(a_i - ca)^T: R = closestRotation(H), t = cb - R ca. `from(i)` and
// `to(i)` give a_i and b_i. n > 0; no allocation.
struct RigidFit {
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
};

template <class From, class To>
RigidFit bestRigidFit(std::size_t n, From&& from, To&& to) {
  const double w = 1.0 / static_cast<double>(n);
  Eigen::Vector3d ca = Eigen::Vector3d::Zero(), cb = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    ca += w * from(i);
    cb += w * to(i);
  }
  Eigen::Matrix3d h = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < n; ++i) h.noalias() += (to(i) - cb) * (from(i) - ca).transpose();
  RigidFit fit;
  fit.rotation = closestRotation(h);
  fit.translation = cb - fit.rotation * ca;
  return fit;
}

}  // namespace tetrig
