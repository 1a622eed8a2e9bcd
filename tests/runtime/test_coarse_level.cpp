// The coarse level (tetrig/coarse_level.hpp) and the deformer's frame guide it sets.
#include "deformer_test_util.hpp"
#include "tetrig/coarse_level.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

namespace tetrig {
namespace {

HandleTargets vertexTargetsOf(const std::vector<Eigen::Vector3d>& positions) {
  HandleTargets t;
  t.vertex_positions = positions;
  return t;
}

std::vector<Eigen::Quaterniond> rotationsOf(const Deformer& d) {
  std::vector<Eigen::Quaterniond> r(static_cast<std::size_t>(d.tetCount()));
  for (std::int32_t t = 0; t < d.tetCount(); ++t) r[static_cast<std::size_t>(t)] = d.rotation(t);
  return r;
}

// Converged pose of `targets` from `start` rotations: max vertex distance of `d` from it.
double distanceToConverged(const scenes::BarScene& bar, const Deformer& d, const std::vector<Eigen::Vector3d>& targets) {
  Deformer converged(bar.mesh, test::endVertexHandles(bar));
  converged.setRotations(rotationsOf(d));
  converged.step(vertexTargetsOf(targets), StepBudget{4000});
  return (test::deformedVertices(d) - test::deformedVertices(converged)).rowwise().norm().maxCoeff();
}

// The same bar, coarser: half the cubes along each axis, each twice the size.
struct BarPair {
  scenes::BarScene fine = scenes::makeBarScene(4, 4, 32);
  scenes::BarScene coarse = [] {
    scenes::BarScene c = scenes::makeBarScene(2, 2, 16);
    c.mesh.vertices *= 2.0;
    c.axis_point *= 2.0;
    c.length *= 2.0;
    return c;
  }();
};

// Targets of both bars' end vertices for the fine bar's bend by `angle`.
std::vector<Eigen::Vector3d> bendTargets(const BarPair& bars, const scenes::BarScene& which, double angle) {
  const Eigen::Isometry3d far = scenes::barBendTransform(bars.fine, angle);
  auto targets = scenes::transformedPositions(which.mesh, which.near_vertices, Eigen::Isometry3d::Identity());
  const auto far_targets = scenes::transformedPositions(which.mesh, which.far_vertices, far);
  targets.insert(targets.end(), far_targets.begin(), far_targets.end());
  return targets;
}

TEST(FrameGuide, RefusedWithoutTheOptionOrWithTheWrongSize) {
  const auto bar = scenes::makeBarScene(2, 2, 6);
  Deformer plain(bar.mesh, test::endVertexHandles(bar));
  const std::vector<float> identity = [&] {
    std::vector<float> q(4 * static_cast<std::size_t>(bar.mesh.tetCount()), 0.0f);
    for (std::size_t t = 0; t < q.size(); t += 4) q[t] = 1.0f;
    return q;
  }();
  EXPECT_FALSE(plain.setFrameGuide(identity));
  DeformerSetup setup = test::endVertexHandles(bar);
  setup.options.frame_guide = true;
  Deformer guided(bar.mesh, setup);
  EXPECT_FALSE(guided.setFrameGuide(std::span<const float>(identity).first(identity.size() - 4)));
  EXPECT_TRUE(guided.setFrameGuide(identity));
}

// A guide given per group of tets (setFrameGuideSources: one row per group) starts the step exactly
// where the same rotations given per tet do; sources of the wrong size or out of range are refused
// and the ones set stay.
TEST(FrameGuide, RowsSharedByGroupsOfTetsGuideAsTheSameRowsPerTet) {
  const auto bar = scenes::makeBarScene(2, 2, 12);
  const std::int32_t tets = bar.mesh.tetCount();
  // Three groups by position along the bar, each its own turn about a different axis.
  std::vector<std::int32_t> group(static_cast<std::size_t>(tets));
  for (std::int32_t t = 0; t < tets; ++t) {
    double z = 0.0;
    for (int k = 0; k < 4; ++k) z += 0.25 * bar.mesh.vertices(bar.mesh.tets(t, k), 2);
    group[static_cast<std::size_t>(t)] = std::min(2, static_cast<std::int32_t>(3.0 * z / bar.length));
  }
  std::vector<float> rows;
  for (int g = 0; g < 3; ++g) {
    const Eigen::Quaterniond q(Eigen::AngleAxisd(0.1 + 0.2 * g, Eigen::Vector3d::Unit(g)));
    rows.insert(rows.end(), {float(q.w()), float(q.x()), float(q.y()), float(q.z())});
  }
  std::vector<float> per_tet;
  for (const std::int32_t g : group) per_tet.insert(per_tet.end(), rows.begin() + 4 * g, rows.begin() + 4 * g + 4);
  DeformerSetup setup = test::endVertexHandles(bar);
  setup.options.frame_guide = true;
  Deformer by_tet(bar.mesh, setup), by_group(bar.mesh, setup);
  ASSERT_FALSE(by_group.setFrameGuideSources(std::span<const std::int32_t>(group).first(group.size() - 1), 3));
  std::vector<std::int32_t> out_of_range = group;
  out_of_range.back() = 3;
  ASSERT_FALSE(by_group.setFrameGuideSources(out_of_range, 3));
  EXPECT_FALSE(by_group.setFrameGuide(rows));  // still one row per tet
  ASSERT_TRUE(by_group.setFrameGuideSources(group, 3));
  EXPECT_FALSE(by_group.setFrameGuide(per_tet));
  ASSERT_TRUE(by_group.setFrameGuide(rows));
  ASSERT_TRUE(by_tet.setFrameGuide(per_tet));
  const auto targets = test::endTargets(bar, scenes::barBendTransform(bar, 0.3));
  by_tet.step(vertexTargetsOf(targets), StepBudget{1});
  by_group.step(vertexTargetsOf(targets), StepBudget{1});
  const Eigen::MatrixXd a = test::deformedVertices(by_tet), b = test::deformedVertices(by_group);
  EXPECT_EQ(a, b);
  // And the guide did turn the start: without it the same step lands elsewhere.
  Deformer unguided(bar.mesh, setup);
  unguided.step(vertexTargetsOf(targets), StepBudget{1});
  EXPECT_GT((test::deformedVertices(unguided) - a).rowwise().norm().maxCoeff(), 1e-3 * bar.length);
}

// Given the converged rotations' change as the guide, one solve lands on the converged pose of the
// new targets (one solve is exact given the right rotations), where the unguided step does not.
TEST(FrameGuide, TheExactRotationChangeLandsOnTheConvergedPoseInOneSolve) {
  const auto bar = scenes::makeBarScene(4, 4, 33);
  const auto a = test::endTargets(bar, scenes::barBendTransform(bar, 0.25 * M_PI));
  const auto b = test::endTargets(bar, scenes::barBendTransform(bar, 0.5 * M_PI));
  Deformer reference(bar.mesh, test::endVertexHandles(bar));
  reference.step(vertexTargetsOf(a), StepBudget{4000});
  const auto ra = rotationsOf(reference);
  reference.step(vertexTargetsOf(b), StepBudget{4000});
  const auto rb = rotationsOf(reference);
  std::vector<float> guide(4 * ra.size());
  for (std::size_t t = 0; t < ra.size(); ++t) {
    const Eigen::Quaterniond g = rb[t] * ra[t].conjugate();
    guide[4 * t] = static_cast<float>(g.w());
    guide[4 * t + 1] = static_cast<float>(g.x());
    guide[4 * t + 2] = static_cast<float>(g.y());
    guide[4 * t + 3] = static_cast<float>(g.z());
  }
  DeformerSetup setup = test::endVertexHandles(bar);
  setup.options.frame_guide = true;
  Deformer guided(bar.mesh, setup), unguided(bar.mesh, setup);
  guided.setRotations(ra);
  unguided.setRotations(ra);
  ASSERT_TRUE(guided.setFrameGuide(guide));
  guided.step(vertexTargetsOf(b), StepBudget{1});
  unguided.step(vertexTargetsOf(b), StepBudget{1});
  const double with = (test::deformedVertices(guided) - test::deformedVertices(reference)).rowwise().norm().maxCoeff();
  const double without = (test::deformedVertices(unguided) - test::deformedVertices(reference)).rowwise().norm().maxCoeff();
  std::printf("45 -> 90 degree bend, 1 iteration: %.2e guided by the exact rotation change, %.3f unguided (bar length %.0f)\n",
              with, without, bar.length);
  EXPECT_LT(with, 1e-3);  // float rotations
  EXPECT_GT(without, 1.0);
  // The guide is used once: the next step starts from where this one ended.
  guided.step(vertexTargetsOf(b), StepBudget{1});
  EXPECT_LT((test::deformedVertices(guided) - test::deformedVertices(reference)).rowwise().norm().maxCoeff(), 1e-3);
}

struct SwingResult {
  double plain = 0.0, coarse = 0.0;  // max vertex distance to converged after the budget
};

// From rest, the far end swung through `angle` in one frame, 3 fine iterations.
SwingResult swing(const BarPair& bars, double angle, int coarse_iterations) {
  const auto fine_targets = bendTargets(bars, bars.fine, angle);
  const auto coarse_targets = bendTargets(bars, bars.coarse, angle);
  DeformerSetup setup = test::endVertexHandles(bars.fine);
  setup.options.frame_guide = true;
  Deformer plain(bars.fine.mesh, setup), guided(bars.fine.mesh, setup);
  CoarseLevelOptions options;
  options.iterations = coarse_iterations;
  CoarseLevel coarse(bars.fine.mesh, guided, bars.coarse.mesh, test::endVertexHandles(bars.coarse), options);
  plain.step(vertexTargetsOf(fine_targets), StepBudget{3});
  coarse.guide(vertexTargetsOf(coarse_targets));
  guided.step(vertexTargetsOf(fine_targets), StepBudget{3});
  return {distanceToConverged(bars.fine, plain, fine_targets), distanceToConverged(bars.fine, guided, fine_targets)};
}

// The test: a limb swung through 90 degrees in one frame reaches a stated error in 3
// iterations with the coarse level and does not without.
TEST(CoarseLevel, ALimbSwungNinetyDegreesInOneFrameLandsNearConvergedIn3Iterations) {
  const BarPair bars;
  ASSERT_EQ(bars.fine.near_vertices.size(), 50u);
  ASSERT_EQ(bars.coarse.near_vertices.size(), 9u);
  const SwingResult r = swing(bars, 0.5 * M_PI, 30);
  std::printf("90 degree swing in one frame, 3 fine iterations (%d fine / %d coarse tets, 30 coarse iterations): %.3f plain, "
              "%.3f with the coarse level (bar length %.0f)\n",
              bars.fine.mesh.tetCount(), bars.coarse.mesh.tetCount(), r.plain, r.coarse, bars.fine.length);
  EXPECT_LT(r.coarse, 0.05 * bars.fine.length);
  EXPECT_GT(r.plain, 0.1 * bars.fine.length);
  EXPECT_LT(r.coarse, 0.3 * r.plain);
}

// A steady bend at 1.5 degrees per frame, 3 fine iterations per frame: the coarse level's rotation
// change carries the slow mode along, the plain chain lags.
TEST(CoarseLevel, FollowsASteadyBendCloser) {
  const BarPair bars;
  DeformerSetup setup = test::endVertexHandles(bars.fine);
  setup.options.frame_guide = true;
  Deformer plain(bars.fine.mesh, setup), guided(bars.fine.mesh, setup);
  CoarseLevel coarse(bars.fine.mesh, guided, bars.coarse.mesh, test::endVertexHandles(bars.coarse));
  std::vector<Eigen::Vector3d> fine_targets;
  for (int f = 1; f <= 60; ++f) {
    const double angle = 0.5 * M_PI * f / 60.0;
    fine_targets = bendTargets(bars, bars.fine, angle);
    const auto coarse_targets = bendTargets(bars, bars.coarse, angle);
    plain.step(vertexTargetsOf(fine_targets), StepBudget{3});
    coarse.guide(vertexTargetsOf(coarse_targets));
    guided.step(vertexTargetsOf(fine_targets), StepBudget{3});
  }
  const double lag_plain = distanceToConverged(bars.fine, plain, fine_targets);
  const double lag_guided = distanceToConverged(bars.fine, guided, fine_targets);
  std::printf("bend 1.5 deg/frame, 3 fine iterations/frame: lag to converged %.4f plain, %.4f with the coarse level (%d "
              "coarse iterations)\n",
              lag_plain, lag_guided, CoarseLevelOptions{}.iterations);
  EXPECT_LT(lag_guided, 0.25 * lag_plain);
}

// After a jump that inverts tets (the far end twisted 150 degrees and pushed in to 40 % of the
// length in one frame), the guided start ends each budget at no higher exact energy than the
// plain start with the same budget: with 5 coarse iterations every budget; with the default 2 (the
// coarse level itself far from its converged pose after such a jump) the live rig's budgets, up to 5
// fine iterations (at 10 the guided pose is 0.7 % higher).
TEST(CoarseLevel, AfterAnInvertingJumpEndsNoHigherThanThePlainStart) {
  const BarPair bars;
  const Eigen::Isometry3d far = scenes::barAxisTransform(bars.fine, 150.0 / 180.0 * M_PI, Eigen::Vector3d(3, -2, -19));
  const auto targets_of = [&](const scenes::BarScene& which) {
    auto t = scenes::transformedPositions(which.mesh, which.near_vertices, Eigen::Isometry3d::Identity());
    const auto f = scenes::transformedPositions(which.mesh, which.far_vertices, far);
    t.insert(t.end(), f.begin(), f.end());
    return t;
  };
  const auto fine_targets = targets_of(bars.fine), coarse_targets = targets_of(bars.coarse);
  DeformerSetup setup = test::endVertexHandles(bars.fine);
  setup.options.frame_guide = true;
  for (const int coarse_iterations : {CoarseLevelOptions{}.iterations, 5}) {
    CoarseLevelOptions options;
    options.iterations = coarse_iterations;
    const int last = coarse_iterations == 5 ? 50 : 5;
    for (const int k : {1, 2, 3, 5, 10, 20, 50}) {
      if (k > last) break;
      Deformer plain(bars.fine.mesh, setup), guided(bars.fine.mesh, setup);
      CoarseLevel coarse(bars.fine.mesh, guided, bars.coarse.mesh, test::endVertexHandles(bars.coarse), options);
      plain.step(vertexTargetsOf(fine_targets), StepBudget{k});
      coarse.guide(vertexTargetsOf(coarse_targets));
      const StepStats s = guided.step(vertexTargetsOf(fine_targets), StepBudget{k});
      const double ep = test::exactEnergy(bars.fine.mesh, plain), eg = test::exactEnergy(bars.fine.mesh, guided);
      std::printf("inverting jump, %d coarse, %2d fine iterations: exact energy plain %.6g, with the coarse level %.6g%s\n",
                  coarse_iterations, k, ep, eg, (s.flags & kStepExactRotations) ? " (inverted tets took the exact rotation)" : "");
      EXPECT_LE(eg, ep * (1.0 + 1e-9)) << coarse_iterations << " coarse, " << k << " fine iterations";
    }
  }
}

// Both ends of the bar as oriented region handles, twisted 360 degrees in 16 frames, 1 fine
// iteration per frame. The coarse level interpolates the regions' turn over its own tets, so its
// guide already carries that turn into every fine tet: a fine level that interpolates the same turn
// again starts each frame turned twice as far near the far end, and lands farther from the
// converged pose than the fine level that takes the turn from the guide alone (what the live rig
// does: LiveRig.TheFineLevelTakesTheRegionsTurnFromTheCoarseLevelAlone).
TEST(CoarseLevel, ItsGuideCarriesTheRegionsTurnOnce) {
  const BarPair bars;
  // The same length of bar at each end on both levels (a cube of the coarse bar: two of the fine).
  const auto regions = [](const scenes::BarScene& bar) {
    const double reach = 2.0 + 1e-9;
    std::vector<std::int32_t> near, far;
    for (std::int32_t t = 0; t < bar.mesh.tetCount(); ++t) {
      double lo = bar.length, hi = 0.0;
      for (int k = 0; k < 4; ++k) {
        lo = std::min(lo, bar.mesh.vertices(bar.mesh.tets(t, k), 2));
        hi = std::max(hi, bar.mesh.vertices(bar.mesh.tets(t, k), 2));
      }
      if (hi <= reach) near.push_back(t);
      if (lo >= bar.length - reach) far.push_back(t);
    }
    DeformerSetup setup;
    setup.region_handles = {RegionHandle{near, true}, RegionHandle{far, true}};
    return setup;
  };
  const auto run = [&](bool fine_interpolates) {
    DeformerSetup setup = regions(bars.fine);
    setup.options.frame_guide = true;
    setup.options.interpolate_rotations = fine_interpolates;
    Deformer fine(bars.fine.mesh, setup);
    CoarseLevel coarse(bars.fine.mesh, fine, bars.coarse.mesh, regions(bars.coarse));
    std::vector<RigidTransform> transforms(2);
    HandleTargets fine_targets, coarse_targets;
    fine_targets.region_transforms = transforms;
    double worst = 0.0;
    for (int f = 1; f <= 16; ++f) {
      const Eigen::Isometry3d far = scenes::barAxisTransform(bars.fine, 2 * M_PI * f / 16, Eigen::Vector3d::Zero());
      transforms[1].rotation = Eigen::Quaterniond(far.rotation());
      transforms[1].translation = far.translation();
      // The coarse bar's axis is the fine bar's: the same transform moves its far end.
      coarse_targets.region_transforms = transforms;
      coarse.guide(coarse_targets);
      fine.step(fine_targets, StepBudget{1});
      if (f % 4 != 0) continue;
      Deformer converged(bars.fine.mesh, regions(bars.fine));
      converged.setRotations(rotationsOf(fine));
      converged.step(fine_targets, StepBudget{2000});
      worst = std::max(worst, (test::deformedVertices(fine) - test::deformedVertices(converged)).rowwise().norm().maxCoeff());
    }
    return worst;
  };
  const double once = run(false), twice = run(true);
  std::printf("twist 360 deg in 16 frames, 1 fine iteration per frame, guided by the coarse level: worst distance to converged "
              "%.4f with the fine level taking the turn from the guide, %.4f interpolating it again (bar length %.0f)\n",
              once, twice, bars.fine.length);
  EXPECT_LT(once, 0.7 * twice);
}

TEST(CoarseLevel, RefusesBadOptions) {
  const BarPair bars;
  CoarseLevelOptions options;
  options.iterations = 0;
  DeformerSetup setup = test::endVertexHandles(bars.fine);
  setup.options.frame_guide = true;
  Deformer guided(bars.fine.mesh, setup);
  EXPECT_THROW(CoarseLevel(bars.fine.mesh, guided, bars.coarse.mesh, test::endVertexHandles(bars.coarse), options),
               std::invalid_argument);
  // A fine deformer that takes no frame guide.
  Deformer unguided(bars.fine.mesh, test::endVertexHandles(bars.fine));
  EXPECT_THROW(CoarseLevel(bars.fine.mesh, unguided, bars.coarse.mesh, test::endVertexHandles(bars.coarse)), std::invalid_argument);
}

}  // namespace
}  // namespace tetrig
