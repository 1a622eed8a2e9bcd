// Rotation extraction on random, reflected, near-singular and singular matrices.
#include "tetrig/polar.hpp"

#include <Eigen/Dense>
#include <Eigen/SVD>
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace tetrig {
namespace {

Eigen::Matrix3d randomRotation(std::mt19937& rng) {
  std::normal_distribution<double> normal;
  Eigen::Quaterniond q(normal(rng), normal(rng), normal(rng), normal(rng));
  return q.normalized().toRotationMatrix();
}

// Reference: R = U diag(1, 1, det(U V^T)) V^T maximises tr(R^T F) over SO(3).
Eigen::Matrix3d svdRotation(const Eigen::Matrix3d& f) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(f, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return svd.matrixU() * d * svd.matrixV().transpose();
}

void expectProperRotation(const Eigen::Matrix3d& r, const char* what) {
  ASSERT_TRUE(r.allFinite()) << what;
  EXPECT_NEAR(r.determinant(), 1.0, 1e-6) << what;
  EXPECT_LT((r.transpose() * r - Eigen::Matrix3d::Identity()).norm(), 1e-6) << what;
}

double traceWith(const Eigen::Matrix3d& r, const Eigen::Matrix3d& f) { return (r.cwiseProduct(f)).sum(); }

TEST(Polar, HornMatrixEncodesTheTrace) {
  std::mt19937 rng(1);
  std::normal_distribution<double> normal;
  for (int i = 0; i < 100; ++i) {
    Eigen::Matrix3d f;
    for (int k = 0; k < 9; ++k) f.data()[k] = normal(rng);
    const Eigen::Quaterniond q = Eigen::Quaterniond(normal(rng), normal(rng), normal(rng), normal(rng)).normalized();
    const Eigen::Vector4d v(q.w(), q.x(), q.y(), q.z());
    EXPECT_NEAR(v.dot(hornMatrix(f) * v), traceWith(q.toRotationMatrix(), f), 1e-12);
  }
}

TEST(Polar, AgreesWithSvdOnWellConditionedMatrices) {
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> stretch(0.5, 2.0);
  for (int i = 0; i < 500; ++i) {
    const Eigen::Matrix3d r = randomRotation(rng);
    const Eigen::Matrix3d s_basis = randomRotation(rng);
    const Eigen::Matrix3d s =
        s_basis * Eigen::Vector3d(stretch(rng), stretch(rng), stretch(rng)).asDiagonal() * s_basis.transpose();
    const Eigen::Matrix3d f = r * s;  // polar factors known: R and SPD S
    const Eigen::Matrix3d exact = closestRotation(f).toRotationMatrix();
    expectProperRotation(exact, "exact");
    EXPECT_LT((exact - r).norm(), 1e-9);
    EXPECT_LT((exact - svdRotation(f)).norm(), 1e-9);
    // The iteration converges to the same rotation even from a cold start at the identity.
    Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
    refineRotation(f, q, 500, 1e-14);
    EXPECT_LT((q.toRotationMatrix() - r).norm(), 1e-6) << "sample " << i;
  }
}

TEST(Polar, ReflectedMatricesGiveTheProperMaximiser) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> stretch(0.3, 3.0);
  for (int i = 0; i < 500; ++i) {
    Eigen::Matrix3d f = randomRotation(rng) * Eigen::Vector3d(stretch(rng), stretch(rng), stretch(rng)).asDiagonal() *
                        randomRotation(rng);
    f.col(i % 3) *= -1.0;  // det F < 0: an inverted tet
    ASSERT_LT(f.determinant(), 0.0);
    const Eigen::Matrix3d exact = closestRotation(f).toRotationMatrix();
    expectProperRotation(exact, "reflected");
    EXPECT_NEAR(traceWith(exact, f), traceWith(svdRotation(f), f), 1e-9);
  }
}

TEST(Polar, NearSingularAndSingularMatricesNeverGiveNaN) {
  std::mt19937 rng(4);
  std::normal_distribution<double> normal;
  const double scales[] = {1e-3, 1e-8, 1e-14, 0.0};
  for (double tiny : scales) {
    for (int i = 0; i < 200; ++i) {
      const Eigen::Vector3d sigma(1.0 + std::abs(normal(rng)), (i % 2) ? tiny : 1.0, tiny);
      const Eigen::Matrix3d f = randomRotation(rng) * sigma.asDiagonal() * randomRotation(rng);
      const Eigen::Matrix3d exact = closestRotation(f).toRotationMatrix();
      expectProperRotation(exact, "near-singular");
      EXPECT_NEAR(traceWith(exact, f), traceWith(svdRotation(f), f), 1e-8);
      Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
      refineRotation(f, q, 20);
      expectProperRotation(q.toRotationMatrix(), "iterative near-singular");
    }
  }
  // All-zero, rank-one, and the saddle the iteration cannot leave: F = a 180-degree turn, q = I.
  const Eigen::Matrix3d zero = Eigen::Matrix3d::Zero();
  expectProperRotation(closestRotation(zero).toRotationMatrix(), "zero");
  const Eigen::Matrix3d rank_one = Eigen::Vector3d(1, 2, 3) * Eigen::RowVector3d(0.5, -1, 2);
  expectProperRotation(closestRotation(rank_one).toRotationMatrix(), "rank one");
  const Eigen::Matrix3d half_turn = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  EXPECT_LT((closestRotation(half_turn).toRotationMatrix() - half_turn).norm(), 1e-9);
}

// closestRotation's fast path (Newton on N's characteristic polynomial, the eigenvector from an
// adjugate column) against the SVD maximiser: taken for almost every generic matrix, inverted or
// not, with the same trace to rounding; declined where the largest eigenvalue of N is repeated
// (F = 0, and F = diag(1, 1, -1), whose maximisers form a circle), where the eigensolver answers.
TEST(Polar, TheQuarticPathAgreesWithTheSvdAndDeclinesRepeatedRoots) {
  std::mt19937 rng(6);
  std::normal_distribution<double> normal;
  int taken = 0;
  const int samples = 2000;
  for (int i = 0; i < samples; ++i) {
    Eigen::Matrix3d f;
    for (int k = 0; k < 9; ++k) f.data()[k] = normal(rng);
    if ((i % 2 == 0) != (f.determinant() < 0.0)) f.col(0) *= -1.0;  // half of them inverted
    Eigen::Quaterniond q(0.0, 0.0, 0.0, 0.0);
    if (!closestRotationByQuartic(f, q)) continue;
    ++taken;
    expectProperRotation(q.toRotationMatrix(), "quartic");
    EXPECT_NEAR(q.norm(), 1.0, 1e-12);
    EXPECT_NEAR(traceWith(q.toRotationMatrix(), f), traceWith(svdRotation(f), f), 1e-10 * (1.0 + f.norm())) << "sample " << i;
  }
  EXPECT_GE(taken, samples * 99 / 100);
  Eigen::Quaterniond untouched(0.5, 0.5, 0.5, 0.5);
  EXPECT_FALSE(closestRotationByQuartic(Eigen::Matrix3d::Zero(), untouched));
  const Eigen::Matrix3d reflection = Eigen::Vector3d(1.0, 1.0, -1.0).asDiagonal();
  EXPECT_FALSE(closestRotationByQuartic(reflection, untouched));
  EXPECT_EQ(untouched.coeffs(), Eigen::Quaterniond(0.5, 0.5, 0.5, 0.5).coeffs());
  // closestRotation still answers both, through the eigensolver.
  expectProperRotation(closestRotation(reflection).toRotationMatrix(), "reflection");
  EXPECT_NEAR(traceWith(closestRotation(reflection).toRotationMatrix(), reflection), 1.0, 1e-12);
}

TEST(Polar, RefinementNeverLowersTheTrace) {
  std::mt19937 rng(5);
  std::normal_distribution<double> normal;
  for (int i = 0; i < 1000; ++i) {
    Eigen::Matrix3d f;
    for (int k = 0; k < 9; ++k) f.data()[k] = normal(rng);
    Eigen::Quaterniond q(randomRotation(rng));
    double before = traceWith(q.toRotationMatrix(), f);
    for (int step = 0; step < 5; ++step) {
      refineRotation(f, q, 1);
      const double after = traceWith(q.toRotationMatrix(), f);
      EXPECT_GE(after, before - 1e-12);
      before = after;
    }
    EXPECT_NEAR(q.norm(), 1.0, 1e-12);
  }
}

TEST(Polar, NonFiniteInputGivesIdentityNotNaN) {
  Eigen::Matrix3d f = Eigen::Matrix3d::Identity();
  f(1, 2) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_TRUE(closestRotation(f).coeffs().allFinite());
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  refineRotation(f, q, 3);
  EXPECT_TRUE(q.coeffs().allFinite());
}

// The best rigid fit recovers an exact rigid motion of a point set, and with noisy points it is
// a minimum: no small change of its rotation or translation lowers the squared residual.
TEST(Polar, BestRigidFitRecoversARigidMotionAndMinimisesTheResidual) {
  std::mt19937 rng(11);
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<Eigen::Vector3d> a, b;
  const Eigen::Quaterniond q = Eigen::Quaterniond(Eigen::AngleAxisd(2.3, Eigen::Vector3d(1, -2, 0.5).normalized()));
  const Eigen::Vector3d t(4.0, -1.0, 7.5);
  for (int i = 0; i < 7; ++i) {
    a.emplace_back(g(rng), g(rng), g(rng));
    b.push_back(q * a.back() + t);
  }
  const auto from = [&](std::size_t i) { return a[i]; };
  const auto to = [&](std::size_t i) { return b[i]; };
  const RigidFit exact = bestRigidFit(a.size(), from, to);
  EXPECT_LT(exact.rotation.angularDistance(q), 1e-12);
  EXPECT_LT((exact.translation - t).norm(), 1e-12);

  for (auto& p : b) p += 0.05 * Eigen::Vector3d(g(rng), g(rng), g(rng));
  const RigidFit fit = bestRigidFit(a.size(), from, to);
  const auto residual = [&](const Eigen::Quaterniond& r, const Eigen::Vector3d& s) {
    double e = 0.0;
    for (std::size_t i = 0; i < a.size(); ++i) e += (b[i] - (r * a[i] + s)).squaredNorm();
    return e;
  };
  const double best = residual(fit.rotation, fit.translation);
  for (int axis = 0; axis < 3; ++axis)
    for (const double step : {-1e-3, 1e-3}) {
      const Eigen::Quaterniond turned = Eigen::Quaterniond(Eigen::AngleAxisd(step, Eigen::Vector3d::Unit(axis))) * fit.rotation;
      EXPECT_GT(residual(turned, fit.translation), best) << "axis " << axis;
      EXPECT_GT(residual(fit.rotation, fit.translation + step * Eigen::Vector3d::Unit(axis)), best) << "axis " << axis;
    }
}

}  // namespace
}  // namespace tetrig
