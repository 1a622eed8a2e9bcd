// The fused SIMD rotation pass against the scalar double-precision references: closestRotation
// (exact polar) and differentialCoordinates (delta = G^T D g, eq. 2.5). The pass works in float
// on displacements (rotation_kernel.hpp), so its bounds are float ones: rounding of ~1e-7
// relative; the bounds below sit 3-10x above what this code measures (printed by the tests).
#include "scenes.hpp"
#include "tetrig/laplacian.hpp"
#include "tetrig/ldlt_factor.hpp"
#include "tetrig/polar.hpp"
#include "tetrig/rotation_kernel.hpp"
#include "tetrig/rotation_prediction.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

namespace tetrig {
namespace {

struct KernelScene {
  TetMesh mesh;
  TetRestFrames frames;
  std::vector<double> weights;
  std::vector<TetBlock> blocks;
  std::vector<double> xyz;  // deformed positions, kVectorStride per vertex, mesh order (= solver order here)
  std::vector<double> u;    // the same as displacements from rest: the pass's input
  std::vector<std::uint16_t> exact_lanes;  // rotationPass scratch
};

RotationPassStats runPass(KernelScene& s, float* delta, int steps) {
  for (size_t i = 0; i < s.u.size(); ++i)
    s.u[i] = s.xyz[i] - (i % kVectorStride == 3 ? 0.0 : s.mesh.vertices(static_cast<Eigen::Index>(i / kVectorStride),
                                                                         static_cast<Eigen::Index>(i % kVectorStride)));
  return rotationPass(s.blocks.data(), static_cast<std::int32_t>(s.blocks.size()), s.u.data(), delta, steps,
                      s.exact_lanes.data());
}

Vertices positions(const KernelScene& s) {
  Vertices x(s.mesh.vertexCount(), 3);
  for (std::int32_t v = 0; v < s.mesh.vertexCount(); ++v)
    for (int c = 0; c < 3; ++c) x(v, c) = s.xyz[kVectorStride * static_cast<size_t>(v) + static_cast<size_t>(c)];
  return x;
}

// A bar with a random smooth deformation plus noise; a few tets can invert when `inverted`.
KernelScene makeScene(std::uint32_t seed, double noise) {
  KernelScene s;
  s.mesh = scenes::makeBar(2, 2, 6);
  s.frames = computeRestFrames(s.mesh);
  s.weights = tetWeights(s.frames, {});
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal;
  s.xyz.assign(static_cast<size_t>(s.mesh.vertexCount()) * kVectorStride, 0.0);
  s.u = s.xyz;
  for (std::int32_t v = 0; v < s.mesh.vertexCount(); ++v) {
    const Eigen::Vector3d p = s.mesh.vertices.row(v).transpose();
    // Bend about x by an angle growing along z, plus noise.
    const Eigen::Vector3d q = Eigen::AngleAxisd(0.15 * p.z(), Eigen::Vector3d::UnitX()) * p;
    for (int c = 0; c < 3; ++c) s.xyz[kVectorStride * static_cast<size_t>(v) + static_cast<size_t>(c)] = q[c] + noise * normal(rng);
  }
  const std::int32_t m = s.mesh.tetCount();
  s.blocks.assign(static_cast<size_t>((m + kTetBlockWidth - 1) / kTetBlockWidth), TetBlock{});
  s.exact_lanes.assign(s.blocks.size(), 0xffff);
  for (std::int32_t t = 0; t < static_cast<std::int32_t>(s.blocks.size()) * kTetBlockWidth; ++t) {
    TetBlock& b = s.blocks[static_cast<size_t>(t / kTetBlockWidth)];
    const int l = t % kTetBlockWidth;
    b.rotation[0][l] = 1.0f;
    b.rotation[1][l] = b.rotation[2][l] = b.rotation[3][l] = 0.0f;
    const bool real = t < m;
    for (int c = 0; c < 4; ++c) b.corner_offset[c][l] = real ? kVectorStride * s.mesh.tets(t, c) : 0;
    for (int i = 0; i < 9; ++i)
      b.edge_inverse[i][l] =
          real ? static_cast<float>(s.frames.edge_inverse[static_cast<size_t>(t)](i / 3, i % 3)) : (i % 4 == 0);
    b.weight[l] = real ? static_cast<float>(s.weights[static_cast<size_t>(t)]) : 0.0f;
  }
  return s;
}

Eigen::Quaterniond laneRotation(const KernelScene& s, std::int32_t t) {
  const TetBlock& b = s.blocks[static_cast<size_t>(t / kTetBlockWidth)];
  const int l = t % kTetBlockWidth;
  return {b.rotation[0][l], b.rotation[1][l], b.rotation[2][l], b.rotation[3][l]};
}

// Reference delta of the displacement form: sum_j a_j (R_j - I) G_j = G^T D g(R) - G^T D g(I).
Vertices referenceDelta(const KernelScene& s, const std::vector<Eigen::Matrix3d>& rotations) {
  const std::vector<Eigen::Matrix3d> identity(rotations.size(), Eigen::Matrix3d::Identity());
  return differentialCoordinates(s.mesh, s.frames, s.weights, rotations) -
         differentialCoordinates(s.mesh, s.frames, s.weights, identity);
}

TEST(RotationKernel, ConvergesToTheExactRotationAndMatchesTheReferenceDelta) {
  KernelScene s = makeScene(1, 0.02);
  const Vertices x = positions(s);
  // Many passes of 2 steps from a cold start (identity): the warm start carries over between passes.
  RotationPassStats stats;
  for (int pass = 0; pass < 30; ++pass) {
    stats = runPass(s, nullptr, 2);
  }
  std::vector<Eigen::Matrix3d> rotations;
  double energy = 0.0, worst = 0.0;
  for (std::int32_t t = 0; t < s.mesh.tetCount(); ++t) {
    const Eigen::Matrix3d f = deformationGradient(s.mesh, s.frames, x, t);
    const Eigen::Quaterniond q = laneRotation(s, t);
    EXPECT_NEAR(q.norm(), 1.0, 1e-6);
    // Float rounding of F (E^-1 stored in float, the product in float) and of the iteration
    // moves the fixed point by ~1e-7; a double pass reaches 1e-8 here.
    const double error = (q.toRotationMatrix() - closestRotation(f).toRotationMatrix()).norm();
    EXPECT_LT(error, 1e-6) << "tet " << t;
    worst = std::max(worst, error);
    rotations.push_back(q.normalized().toRotationMatrix());
    energy += s.weights[static_cast<size_t>(t)] * (f - rotations.back()).squaredNorm();
  }
  std::printf("rotation kernel (float): worst rotation error against the exact polar %.2g\n", worst);
  EXPECT_NEAR(stats.energy, energy, 1e-6 * energy);
  // One more pass with the scatter: delta equals the reference sum a (R - I) G.
  std::vector<float> delta(s.xyz.size(), 0.0f);
  runPass(s, delta.data(), 2);
  const Vertices reference = referenceDelta(s, rotations);
  ASSERT_GT(reference.cwiseAbs().maxCoeff(), 1e-3) << "the bend must give a delta to compare";
  for (std::int32_t v = 0; v < s.mesh.vertexCount(); ++v)
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(delta[kVectorStride * static_cast<size_t>(v) + static_cast<size_t>(c)], reference(v, c), 1e-6);
  // differentialPass gives the same delta from the stored rotations: the same float arithmetic up
  // to how the compiler contracts it into FMAs (a few float ulps; |delta| < 1 here).
  std::vector<float> delta2(s.xyz.size(), 0.0f);
  differentialPass(s.blocks.data(), static_cast<std::int32_t>(s.blocks.size()), delta2.data());
  for (size_t i = 0; i < delta.size(); ++i) EXPECT_NEAR(delta2[i], delta[i], 5e-7);
}

// At rest (u = 0) the pass returns exactly what it was given: identity rotations, zero delta,
// zero energy. Float storage does not move the rest state (displacement form).
TEST(RotationKernel, RestIsReproducedExactly) {
  KernelScene s = makeScene(5, 0.0);
  for (std::int32_t v = 0; v < s.mesh.vertexCount(); ++v)
    for (int c = 0; c < 3; ++c) s.xyz[kVectorStride * static_cast<size_t>(v) + static_cast<size_t>(c)] = s.mesh.vertices(v, c);
  std::vector<float> delta(s.xyz.size(), 0.0f);
  const RotationPassStats stats = runPass(s, delta.data(), 2);
  EXPECT_EQ(stats.energy, 0.0);
  EXPECT_EQ(stats.exact_fallbacks, 0);
  for (std::int32_t t = 0; t < s.mesh.tetCount(); ++t) {
    const Eigen::Quaterniond q = laneRotation(s, t);
    EXPECT_EQ(q.w(), 1.0) << "tet " << t;
    EXPECT_EQ(q.vec().norm(), 0.0) << "tet " << t;
  }
  for (double d : delta) EXPECT_EQ(d, 0.0);
}

TEST(RotationKernel, InvertedTetsTakeTheExactProperRotation) {
  KernelScene s = makeScene(2, 0.0);
  // Reflect the whole deformed mesh through the plane x = 0: every tet is inverted.
  for (size_t v = 0; v < s.xyz.size(); v += kVectorStride) s.xyz[v] = -s.xyz[v];
  const Vertices x = positions(s);
  const RotationPassStats stats = runPass(s, nullptr, 2);
  EXPECT_EQ(stats.exact_fallbacks, s.mesh.tetCount());
  for (std::int32_t t = 0; t < s.mesh.tetCount(); ++t) {
    const Eigen::Matrix3d f = deformationGradient(s.mesh, s.frames, x, t);
    ASSERT_LT(f.determinant(), 0.0);
    const Eigen::Matrix3d r = laneRotation(s, t).toRotationMatrix();
    EXPECT_NEAR(r.determinant(), 1.0, 1e-6);  // stored in float
    EXPECT_NEAR((r.cwiseProduct(f)).sum(), (closestRotation(f).toRotationMatrix().cwiseProduct(f)).sum(), 1e-6);
  }
}

// Far from unit scale. The step is scale-free (|q| stays near 1), so a stretch of 1e14 converges
// like a unit one; at 1e40 the edges do not fit in a float at all, and those lanes are flagged
// and take the exact rotation in double. Either way nothing non-finite reaches the rotations,
// delta or the energy. (Between ~1e19 and 1e38 the rotations stay right but the float energy
// term overflows to +inf: docs/deformation.md.)
TEST(RotationKernel, HugeStretchesConvergeOrTakeTheExactRotation) {
  for (const double scale : {1e14, 1e40}) {
    KernelScene s = makeScene(6, 0.0);
    for (std::int32_t v = 0; v < s.mesh.vertexCount(); ++v)
      for (int c = 0; c < 3; ++c) s.xyz[kVectorStride * static_cast<size_t>(v) + static_cast<size_t>(c)] *= scale;
    const Vertices x = positions(s);
    for (int pass = 0; pass < 30; ++pass) runPass(s, nullptr, 2);
    std::vector<float> delta(s.xyz.size(), 0.0f);
    const RotationPassStats stats = runPass(s, delta.data(), 2);
    EXPECT_EQ(stats.exact_fallbacks, scale > 1e38 ? s.mesh.tetCount() : 0) << "scale " << scale;
    EXPECT_TRUE(std::isfinite(stats.energy)) << "scale " << scale;
    for (float d : delta) ASSERT_TRUE(std::isfinite(d)) << "scale " << scale;
    for (std::int32_t t = 0; t < s.mesh.tetCount(); ++t) {
      const Eigen::Matrix3d f = deformationGradient(s.mesh, s.frames, x, t);
      EXPECT_LT((laneRotation(s, t).toRotationMatrix() - closestRotation(f).toRotationMatrix()).norm(), 1e-6)
          << "scale " << scale << " tet " << t;
    }
  }
}

// Many refinement steps in one pass (DeformerOptions allows up to 64): q must not grow out of
// float range between normalisations (it grew by ~3x per step before the step was made
// scale-free, and overflowed after ~40 steps).
TEST(RotationKernel, SixtyFourStepsFromAColdStartStayFiniteAndConverge) {
  KernelScene s = makeScene(7, 0.05);
  const Vertices x = positions(s);
  const RotationPassStats stats = runPass(s, nullptr, 64);
  EXPECT_EQ(stats.exact_fallbacks, 0);
  EXPECT_TRUE(std::isfinite(stats.energy));
  for (std::int32_t t = 0; t < s.mesh.tetCount(); ++t) {
    const Eigen::Matrix3d f = deformationGradient(s.mesh, s.frames, x, t);
    EXPECT_LT((laneRotation(s, t).toRotationMatrix() - closestRotation(f).toRotationMatrix()).norm(), 1e-6) << "tet " << t;
  }
}

TEST(RotationKernel, EachPassNeverLowersAnyTetsTrace) {
  KernelScene s = makeScene(3, 0.3);  // heavy noise: far from converged, some tets inverted
  const Vertices x = positions(s);
  std::vector<double> before(static_cast<size_t>(s.mesh.tetCount()), -1e300);
  for (int pass = 0; pass < 5; ++pass) {
    runPass(s, nullptr, 1);
    for (std::int32_t t = 0; t < s.mesh.tetCount(); ++t) {
      const Eigen::Matrix3d f = deformationGradient(s.mesh, s.frames, x, t);
      const double trace = (laneRotation(s, t).toRotationMatrix().cwiseProduct(f)).sum();
      // Float: a step may lower the trace by the kernel's rounding allowance, 1e-6 (1 + ||F||^2).
      EXPECT_GE(trace, before[static_cast<size_t>(t)] - 1e-6 * (1.0 + f.squaredNorm())) << "tet " << t << " pass " << pass;
      before[static_cast<size_t>(t)] = trace;
    }
  }
}

// Some tets inverted, most not: the exact fix-up after the pass replaces exactly the flagged
// lanes' rotations, and corrects delta and the energy as if the pass had used them from the start.
TEST(RotationKernel, MixedInvertedTetsGetTheExactRotationInDeltaAndEnergy) {
  KernelScene s = makeScene(4, 0.25);
  const Vertices x = positions(s);
  std::vector<float> delta(s.xyz.size(), 0.0f);
  const RotationPassStats stats = runPass(s, delta.data(), 2);
  std::int32_t inverted = 0;
  std::vector<Eigen::Matrix3d> rotations;
  double energy = 0.0;
  for (std::int32_t t = 0; t < s.mesh.tetCount(); ++t) {
    const Eigen::Matrix3d f = deformationGradient(s.mesh, s.frames, x, t);
    const bool flagged = (s.exact_lanes[static_cast<size_t>(t / kTetBlockWidth)] >> (t % kTetBlockWidth)) & 1;
    EXPECT_EQ(flagged, f.determinant() <= 1e-12) << "tet " << t;
    const Eigen::Matrix3d r = laneRotation(s, t).toRotationMatrix();
    if (f.determinant() <= 1e-12) {
      ++inverted;
      EXPECT_LT((r - closestRotation(f).toRotationMatrix()).norm(), 1e-6) << "tet " << t;
    }
    rotations.push_back(laneRotation(s, t).normalized().toRotationMatrix());
    energy += s.weights[static_cast<size_t>(t)] * (f - r).squaredNorm();
  }
  ASSERT_GT(inverted, 0) << "the scene must invert some tets";
  ASSERT_LT(inverted, s.mesh.tetCount() / 2) << "and keep most of them proper";
  EXPECT_EQ(stats.exact_fallbacks, inverted);
  EXPECT_NEAR(stats.energy, energy, 1e-6 * energy);
  const Vertices reference = referenceDelta(s, rotations);
  for (std::int32_t v = 0; v < s.mesh.vertexCount(); ++v)
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(delta[kVectorStride * static_cast<size_t>(v) + static_cast<size_t>(c)], reference(v, c), 1e-6);
  // The padding lanes of the last block (weight 0) are never flagged.
  const std::int32_t used = s.mesh.tetCount() % kTetBlockWidth;
  if (used != 0) {
    EXPECT_EQ(s.exact_lanes.back() >> used, 0);
  }
}

// A bar squeezed along z (a little more on one side: tets at 80-95 % of their volume) with tet 7
// inverted: its first corner moved `through` times its height beyond the opposite face.
KernelScene squeezedScene(double through) {
  KernelScene s = makeScene(11, 0.01);
  for (std::int32_t v = 0; v < s.mesh.vertexCount(); ++v) {
    double* p = &s.xyz[kVectorStride * static_cast<size_t>(v)];
    p[2] *= 0.8 + 0.02 * p[0];
  }
  Vertices x = positions(s);
  const auto c = s.mesh.tets.row(7);
  const Eigen::Vector3d centroid = (x.row(c[1]) + x.row(c[2]) + x.row(c[3])).transpose() / 3.0;
  const Eigen::Vector3d moved = centroid + through * (centroid - Eigen::Vector3d(x.row(c[0]).transpose()));
  for (int k = 0; k < 3; ++k) s.xyz[kVectorStride * static_cast<size_t>(c[0]) + static_cast<size_t>(k)] = moved[k];
  return s;
}

// The largest difference between `delta` and the plain pass's delta on the same scene.
double differenceToPlainPass(KernelScene& s, const std::vector<float>& delta) {
  std::vector<float> plain(s.xyz.size(), 0.0f);
  rotationPass(s.blocks.data(), static_cast<std::int32_t>(s.blocks.size()), s.u.data(), plain.data(), 2, s.exact_lanes.data());
  double differs = 0.0;
  for (size_t i = 0; i < plain.size(); ++i) differs = std::max(differs, static_cast<double>(std::abs(plain[i] - delta[i])));
  return differs;
}

// The inversion guard (rotation_kernel.hpp, inversionGuard): against the double reference, on the
// squeezed bar below (tets at 80-95 % of their volume) with one inverted tet: each guarded tet's
// target is M = R + alpha (R - F), alpha = k min(1, (tau - det F) / tau) (0 at det F >= tau, k on
// the inverted tet, which takes the exact rotation), lowered so that alpha ||R - F|| is at most
// c = kInversionGuardPushCap; delta is sum_j a_j (M_j - I) G_j and the energy
// sum_j a_j (||F - R||^2 + alpha ||F - R||^2), or 2 c ||F - R|| - c^2 / alpha beyond the cap.
// differentialPass gives the same delta.
TEST(RotationKernel, InversionGuardMatchesTheDoubleReference) {
  KernelScene s = squeezedScene(2.0);  // tet 7 far through: its push is capped
  const Vertices x = positions(s);
  for (int pass = 0; pass < 30; ++pass) runPass(s, nullptr, 2);
  constexpr float kTau = 0.9f;
  std::vector<float> guard(s.blocks.size() * kTetBlockWidth, 0.0f);
  for (std::int32_t t = 0; t < s.mesh.tetCount(); ++t) guard[static_cast<size_t>(t)] = (t % 5 == 0) ? 0.0f : 0.3f + 0.7f * static_cast<float>(t % 7) / 6.0f;
  guard[7] = 1.0f;  // tet 7's slot: the scene keeps mesh order
  std::vector<float> delta(s.xyz.size(), 0.0f);
  const RotationPassStats stats =
      rotationPass(s.blocks.data(), static_cast<std::int32_t>(s.blocks.size()), s.u.data(), delta.data(), 2,
                   s.exact_lanes.data(), 0.0f, nullptr, guard.data(), kTau);
  std::vector<Eigen::Matrix3d> targets;
  double energy = 0.0;
  int guarded = 0, inverted_guarded = 0, capped = 0;
  for (std::int32_t t = 0; t < s.mesh.tetCount(); ++t) {
    const Eigen::Matrix3d f = deformationGradient(s.mesh, s.frames, x, t);
    const Eigen::Matrix3d r = laneRotation(s, t).normalized().toRotationMatrix();
    const double k = guard[static_cast<size_t>(t)];
    double alpha = std::clamp(k * (kTau - f.determinant()) / kTau, 0.0, k);
    const double off = (r - f).norm(), c = kInversionGuardPushCap;
    double extra = alpha * off * off;
    if (alpha * off > c) {  // capped: the push is c, the energy linear beyond (Huber)
      ++capped;
      extra = c * (2.0 * off - c / alpha);
      alpha = c / off;
    }
    guarded += alpha > 0.0;
    inverted_guarded += alpha > 0.0 && f.determinant() <= 0.0;
    targets.push_back(r + alpha * (r - f));
    energy += s.weights[static_cast<size_t>(t)] * (off * off + extra);
  }
  std::printf("inversion guard: %d tets guarded, %d of them inverted, %d pushes capped\n", guarded, inverted_guarded, capped);
  ASSERT_GE(capped, 1) << "the inverted tet is far from its rotation: its push must be capped";
  ASSERT_GE(inverted_guarded, 1) << "the inverted tet must be guarded for the test to cover the exact path";
  ASSERT_GE(guarded, 10);
  EXPECT_NEAR(stats.energy, energy, 2e-5 * energy);
  const Vertices reference = referenceDelta(s, targets);
  for (std::int32_t v = 0; v < s.mesh.vertexCount(); ++v)
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(delta[kVectorStride * static_cast<size_t>(v) + static_cast<size_t>(c)], reference(v, c), 2e-6) << "vertex " << v;
  EXPECT_GT(differenceToPlainPass(s, delta), 1e-3) << "without the guard the pass must differ (the test can fail)";
  std::vector<float> again(s.xyz.size(), 0.0f);
  differentialPass(s.blocks.data(), static_cast<std::int32_t>(s.blocks.size()), again.data(), s.u.data(), nullptr,
                   guard.data(), kTau);
  for (size_t i = 0; i < again.size(); ++i) EXPECT_NEAR(again[i], delta[i], 2e-6) << "entry " << i;
}

// The volume term (rotation_kernel.hpp, volumeBlend): against the double reference, on a bent bar
// squeezed along its length (tets lose up to ~20 % of their volume) with one inverted tet: each
// tet's target is M = (1 - w) R + w (F + s R) with det(F + s R) = 1 (unitVolumeShift), delta is
// sum_j a_j (M_j - I) G_j, the energy sum_j a_j [(1 - w) ||F - R||^2 + 3 w s^2]; the inverted tet
// and w = 0 lanes keep the plain R. differentialPass gives the same delta from the stored rotations.
TEST(RotationKernel, VolumeTermMatchesTheDoubleReference) {
  KernelScene s = squeezedScene(0.3);
  const Vertices x = positions(s);
  for (int pass = 0; pass < 30; ++pass) runPass(s, nullptr, 2);  // rotations converged: the reference uses them
  // Per-slot weights: w varies over the tets (0 on every fifth, and on all of blocks 2-4: the pair
  // 2-3 then takes the plain pass, the pair 4-5 the volume pass for block 5), 0 in padding lanes.
  ASSERT_GE(s.blocks.size(), 7u);
  std::vector<float> weight(s.blocks.size() * kTetBlockWidth, 0.0f);
  for (std::int32_t t = 0; t < s.mesh.tetCount(); ++t) {
    const bool none = t % 5 == 0 || (t >= 2 * kTetBlockWidth && t < 5 * kTetBlockWidth);
    weight[static_cast<size_t>(t)] = none ? 0.0f : 0.3f + 0.6f * static_cast<float>(t % 7) / 6.0f;
  }
  std::vector<float> delta(s.xyz.size(), 0.0f);
  const RotationPassStats stats =
      rotationPass(s.blocks.data(), static_cast<std::int32_t>(s.blocks.size()), s.u.data(), delta.data(), 2,
                   s.exact_lanes.data(), 0.0f, weight.data());
  std::vector<Eigen::Matrix3d> targets;
  double energy = 0.0, largest_shift = 0.0, smallest_det = 1.0;
  int inverted = 0;
  for (std::int32_t t = 0; t < s.mesh.tetCount(); ++t) {
    const Eigen::Matrix3d f = deformationGradient(s.mesh, s.frames, x, t);
    const Eigen::Matrix3d r = laneRotation(s, t).normalized().toRotationMatrix();
    const double shift = unitVolumeShift(f, r);
    // Inverted and degenerate tets are plain (w = 0): the exact rotation alone.
    const double w = f.determinant() > 1e-6 ? weight[static_cast<size_t>(t)] : 0.0;
    if (f.determinant() <= 0.0) {
      ++inverted;
      EXPECT_EQ(shift, 0.0);
    } else {
      smallest_det = std::min(smallest_det, f.determinant());
      EXPECT_NEAR((f + shift * r).determinant(), 1.0, 1e-12) << "tet " << t;
    }
    largest_shift = std::max(largest_shift, std::abs(shift));
    targets.push_back((1.0 - w) * r + w * (f + shift * r));
    energy += s.weights[static_cast<size_t>(t)] * ((1.0 - w) * (f - r).squaredNorm() + 3.0 * w * shift * shift);
  }
  std::printf("volume term: smallest det F %.3f, largest shift %.3f, %d inverted tet(s)\n", smallest_det, largest_shift, inverted);
  ASSERT_GE(inverted, 1);
  ASSERT_LT(smallest_det, 0.85) << "the squeeze must change volumes for the test to mean anything";
  ASSERT_GT(largest_shift, 0.04);
  EXPECT_NEAR(stats.energy, energy, 2e-5 * energy);
  const Vertices reference = referenceDelta(s, targets);
  double worst = 0.0;
  for (std::int32_t v = 0; v < s.mesh.vertexCount(); ++v)
    for (int c = 0; c < 3; ++c) {
      const double d = delta[kVectorStride * static_cast<size_t>(v) + static_cast<size_t>(c)] - reference(v, c);
      worst = std::max(worst, std::abs(d));
      EXPECT_NEAR(delta[kVectorStride * static_cast<size_t>(v) + static_cast<size_t>(c)], reference(v, c), 2e-6) << "vertex " << v;
    }
  std::printf("volume term: worst delta difference to the double reference %.2g (|delta| up to %.2g)\n", worst,
              reference.cwiseAbs().maxCoeff());
  EXPECT_GT(differenceToPlainPass(s, delta), 1e-3) << "without the volume term the pass must differ (the test can fail)";
  // differentialPass: the same delta from the stored rotations and the displacements. (The inverted
  // tet's exact rotation is applied by the pass after its vector part; here it is simply stored.)
  std::vector<float> again(s.xyz.size(), 0.0f);
  differentialPass(s.blocks.data(), static_cast<std::int32_t>(s.blocks.size()), again.data(), s.u.data(), weight.data());
  for (size_t i = 0; i < again.size(); ++i) EXPECT_NEAR(again[i], delta[i], 2e-6) << "entry " << i;
}

// A vertex thrown out of float range (a displacement of 1e30: F beyond float for its tets) leaves
// delta finite with the volume term, in the rotation pass and in differentialPass: those tets take
// the exact rotation and no volume term, never 0 * inf.
TEST(RotationKernel, VolumeTermKeepsDeltaFiniteForAnFOutOfFloatRange) {
  KernelScene s = makeScene(13, 0.01);
  s.xyz[kVectorStride * 5 + 1] = 1e30;
  const std::vector<float> weight(s.blocks.size() * kTetBlockWidth, 0.9f);
  std::vector<float> delta(s.xyz.size(), 0.0f);
  runPass(s, nullptr, 2);  // fills s.u
  const RotationPassStats stats = rotationPass(s.blocks.data(), static_cast<std::int32_t>(s.blocks.size()), s.u.data(),
                                               delta.data(), 2, s.exact_lanes.data(), 0.0f, weight.data());
  EXPECT_GT(stats.exact_fallbacks, 0) << "the far vertex must send its tets to the exact rotation";
  for (size_t i = 0; i < delta.size(); ++i) ASSERT_TRUE(std::isfinite(delta[i])) << "rotation pass, entry " << i;
  std::vector<float> again(s.xyz.size(), 0.0f);
  differentialPass(s.blocks.data(), static_cast<std::int32_t>(s.blocks.size()), again.data(), s.u.data(), weight.data());
  for (size_t i = 0; i < again.size(); ++i) ASSERT_TRUE(std::isfinite(again[i])) << "differentialPass, entry " << i;
}

// At rest the volume term adds nothing: u = 0 gives R = I, s = 0 and a zero delta, exactly.
TEST(RotationKernel, VolumeTermKeepsRestExactly) {
  KernelScene s = makeScene(5, 0.0);
  for (std::int32_t v = 0; v < s.mesh.vertexCount(); ++v)
    for (int c = 0; c < 3; ++c) s.xyz[kVectorStride * static_cast<size_t>(v) + static_cast<size_t>(c)] = s.mesh.vertices(v, c);
  for (size_t i = 0; i < s.u.size(); ++i) s.u[i] = 0.0;
  const std::vector<float> weight(s.blocks.size() * kTetBlockWidth, 0.9f);
  std::vector<float> delta(s.xyz.size(), 0.0f);
  const RotationPassStats stats =
      rotationPass(s.blocks.data(), static_cast<std::int32_t>(s.blocks.size()), s.u.data(), delta.data(), 2,
                   s.exact_lanes.data(), 0.0f, weight.data());
  EXPECT_EQ(stats.energy, 0.0);
  for (const float d : delta) EXPECT_EQ(d, 0.0f);
}


// The frame-start kernel (rotation_prediction.hpp) against its formula in double, on every path:
// velocity (alpha 1) with and without a guide, the angle cap on and off, guide only (alpha 0), and
// a damped alpha (the scalar loop).
TEST(RotationPrediction, MatchesTheQuaternionFormulaInDouble) {
  std::mt19937 rng(5);
  std::normal_distribution<double> normal;
  const auto random = [&](double spread) {
    return Eigen::Quaterniond(1.0 + normal(rng) * spread, normal(rng) * spread, normal(rng) * spread, normal(rng) * spread).normalized();
  };
  constexpr int kBlocks = 3, W = kTetBlockWidth, n = kBlocks * W;
  const double cap = 5.0 * M_PI / 180.0;
  const float max_sin_half = static_cast<float>(std::sin(0.5 * cap));
  std::vector<Eigen::Quaterniond> r(n), p(n), g(n);
  for (int t = 0; t < n; ++t) {
    r[static_cast<std::size_t>(t)] = random(10.0);
    // Half the lanes move less than the cap since P, half more.
    p[static_cast<std::size_t>(t)] = random(t % 2 == 0 ? 0.01 : 0.5) * r[static_cast<std::size_t>(t)];
    g[static_cast<std::size_t>(t)] = random(0.3);
  }
  for (const float alpha : {1.0f, 0.0f, 0.5f}) {
    for (const bool with_guide : {false, true}) {
      std::vector<TetBlock> blocks(kBlocks);
      std::vector<float> previous(4 * n), guide(4 * n);
      for (int t = 0; t < n; ++t) {
        const int b = t / W, l = t % W;
        const auto put = [&](float* base, const Eigen::Quaterniond& q) {
          base[l] = static_cast<float>(q.w());
          base[W + l] = static_cast<float>(q.x());
          base[2 * W + l] = static_cast<float>(q.y());
          base[3 * W + l] = static_cast<float>(q.z());
        };
        put(&blocks[static_cast<std::size_t>(b)].rotation[0][0], r[static_cast<std::size_t>(t)]);
        put(&previous[static_cast<std::size_t>(4 * b * W)], p[static_cast<std::size_t>(t)]);
        put(&guide[static_cast<std::size_t>(4 * b * W)], g[static_cast<std::size_t>(t)]);
      }
      predictFrameRotations(blocks.data(), kBlocks, previous.data(), with_guide ? guide.data() : nullptr, alpha, max_sin_half);
      double worst = 0.0, worst_previous = 0.0;
      int capped = 0;
      for (int t = 0; t < n; ++t) {
        const auto i = static_cast<std::size_t>(t);
        const Eigen::Quaterniond base = with_guide ? (g[i] * r[i]).normalized() : r[i];
        Eigen::Quaterniond expect = base;
        if (alpha != 0.0f) {
          Eigen::Quaterniond d = r[i] * p[i].conjugate();
          if (d.w() < 0.0) d.coeffs() = -d.coeffs();
          Eigen::AngleAxisd aa(d);
          if (aa.angle() > cap) {
            aa.angle() = cap;
            ++capped;
          }
          aa.angle() *= alpha;
          expect = (Eigen::Quaterniond(aa) * base).normalized();
        }
        const int b = t / W, l = t % W;
        const auto get = [&](const float* q) {
          return Eigen::Quaterniond(q[l], q[W + l], q[2 * W + l], q[3 * W + l]);
        };
        const Eigen::Quaterniond got = get(&blocks[static_cast<std::size_t>(b)].rotation[0][0]);
        const Eigen::Quaterniond got_previous = get(&previous[static_cast<std::size_t>(4 * b * W)]);
        worst = std::max(worst, std::min((got.coeffs() - expect.coeffs()).norm(), (got.coeffs() + expect.coeffs()).norm()));
        worst_previous = std::max(worst_previous, (got_previous.coeffs() - base.coeffs()).norm());
      }
      EXPECT_LT(worst, 2e-6) << "alpha " << alpha << (with_guide ? " with" : " without") << " a guide";
      EXPECT_LT(worst_previous, 2e-6) << "alpha " << alpha << (with_guide ? " with" : " without") << " a guide";
      if (alpha != 0.0f) {
        EXPECT_GT(capped, n / 4);  // both paths of the cap ran
        EXPECT_LT(capped, 3 * n / 4);
      }
    }
  }
}

}  // namespace
}  // namespace tetrig
