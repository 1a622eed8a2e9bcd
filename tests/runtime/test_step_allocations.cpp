// Deformer::step() allocates nothing after the first call: a counting global allocator and
// Eigen's runtime malloc check (EIGEN_RUNTIME_NO_MALLOC, compiled into tetrig::runtime).
#include "deformer_test_util.hpp"
#include "counting_allocator.hpp"
#include "test_data.hpp"
#include "tetrig/coarse_level.hpp"
#include "tetrig/tet_mesh_io.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <new>


namespace tetrig {
namespace {

// Runs `frames` frames and returns the allocations counted during all steps after the first;
// `flags` gets the union of the steps' flags.
std::uint64_t allocationsDuringSteps(Deformer& deformer, const std::vector<HandleTargets>& frames, int iterations,
                            std::uint32_t* flags = nullptr) {
  deformer.step(frames.front(), StepBudget{iterations});  // warm-up
  std::uint32_t seen = 0;
  Eigen::internal::set_is_malloc_allowed(false);
  const std::uint64_t before = ::tetrig::test::allocationCount();
  for (const auto& targets : frames) seen |= deformer.step(targets, StepBudget{iterations}).flags;
  const std::uint64_t after = ::tetrig::test::allocationCount();
  Eigen::internal::set_is_malloc_allowed(true);
  if (flags != nullptr) *flags = seen;
  return after - before;
}

TEST(StepAllocations, CountingAllocatorSeesTheTestItself) {
  // The counter works: a vector allocation is seen.
  const std::uint64_t before = ::tetrig::test::allocationCount();
  // (An explicit operator new call: new-expressions may be elided by the compiler.)
  void* probe = ::operator new(64);
  ::operator delete(probe);
  EXPECT_EQ(::tetrig::test::allocationCount() - before, 1u);
}

TEST(StepAllocations, NoneOnABarWithVertexHandles) {
  const auto bar = scenes::makeBarScene(4, 4, 33);
  Deformer deformer(bar.mesh, test::endVertexHandles(bar));
  std::vector<std::vector<Eigen::Vector3d>> positions;
  for (int f = 0; f < 6; ++f)
    positions.push_back(test::endTargets(bar, scenes::barAxisTransform(bar, 0.3 * f, Eigen::Vector3d(0, f, 0))));
  // A last frame that squashes the bar to 40 % inverts tets: the exact-rotation fallback runs too.
  positions.push_back(test::endTargets(bar, scenes::barAxisTransform(bar, 2.6, Eigen::Vector3d(3, -2, -20))));
  std::vector<HandleTargets> frames(positions.size());
  for (size_t f = 0; f < positions.size(); ++f) frames[f].vertex_positions = positions[f];
  std::uint32_t flags = 0;
  EXPECT_EQ(allocationsDuringSteps(deformer, frames, 3, &flags), 0u);
  EXPECT_TRUE(flags & kStepExactRotations) << "the fallback path was meant to run";
}

// With the temporal prediction, the volume term and the inversion guard (which differentialPass
// applies after the frame-start prediction too).
TEST(StepAllocations, NoneWithTheTemporalPredictionAndTheVolumeTerm) {
  const auto bar = scenes::makeBarScene(4, 4, 33);
  DeformerSetup setup = test::endVertexHandles(bar);
  setup.options.rotation_extrapolation = 1.0;
  setup.options.volume_weight = 0.5;
  setup.options.inversion_guard = 1.0;
  setup.options.inversion_guard_threshold = 0.95;  // the bend squashes tets a little: the guard acts
  Deformer deformer(bar.mesh, setup);
  std::vector<std::vector<Eigen::Vector3d>> positions;
  for (int f = 0; f < 6; ++f) positions.push_back(test::endTargets(bar, scenes::barBendTransform(bar, 0.1 * f)));
  std::vector<HandleTargets> frames(positions.size());
  for (size_t f = 0; f < positions.size(); ++f) frames[f].vertex_positions = positions[f];
  EXPECT_EQ(allocationsDuringSteps(deformer, frames, 3, nullptr), 0u);
}

// The implicit inversion guard (its conjugate-gradient vectors are preallocated) and the untangling
// of the published pose (its vertex list reserved at load) on frames that squash the bar to 40 %: it
// must act for the test to mean anything.
TEST(StepAllocations, NoneWithTheImplicitInversionGuard) {
  const auto bar = scenes::makeBarScene(4, 4, 33);
  DeformerSetup setup = test::endVertexHandles(bar);
  setup.options.inversion_guard = 3.0;
  setup.options.inversion_guard_solves = 2;
  setup.options.untangle = true;
  Deformer deformer(bar.mesh, setup);
  std::vector<std::vector<Eigen::Vector3d>> positions;
  for (int f = 0; f < 6; ++f)
    positions.push_back(test::endTargets(bar, scenes::barAxisTransform(bar, 0.3 * f, Eigen::Vector3d(0, f, -3.0 * f))));
  std::vector<HandleTargets> frames(positions.size());
  for (size_t f = 0; f < positions.size(); ++f) frames[f].vertex_positions = positions[f];
  EXPECT_EQ(allocationsDuringSteps(deformer, frames, 3, nullptr), 0u);
  const StepStats last = deformer.step(frames.back(), StepBudget{3});
  EXPECT_GT(last.guarded_solves, 0) << "the squash was meant to engage the guard";
  EXPECT_GT(last.guarded_tets, 0);
}

// setLinearConstraint (one solve) before every step, and the constrained steps.
TEST(StepAllocations, NoneWithALinearConstraint) {
  const auto bar = scenes::makeBarScene(4, 4, 33);
  DeformerSetup setup = test::endVertexHandles(bar);
  setup.options.linear_constraint = true;
  Deformer deformer(bar.mesh, setup);
  std::vector<double> g(3 * static_cast<std::size_t>(bar.mesh.vertexCount()), 0.0);
  for (std::size_t i = 0; i < g.size(); i += 3) g[i] = 1.0;  // the sum of the x coordinates
  HandleTargets targets;
  const auto positions = test::endTargets(bar, scenes::barBendTransform(bar, 0.3));
  targets.vertex_positions = positions;
  ASSERT_TRUE(deformer.setLinearConstraint(g, 0.0));
  deformer.step(targets, StepBudget{3});  // warm-up
  Eigen::internal::set_is_malloc_allowed(false);
  const std::uint64_t before = ::tetrig::test::allocationCount();
  bool all_set = true;
  for (int f = 0; f < 5; ++f) {
    all_set = deformer.setLinearConstraint(g, 0.1 * f) && all_set;
    deformer.step(targets, StepBudget{3});
  }
  const std::uint64_t after = ::tetrig::test::allocationCount();
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(all_set);
  EXPECT_EQ(after - before, 0u);
}

// The coarse level's frame (its own step, the rotation change, the fine deformer's frame guide) and
// the guided fine step, with the temporal prediction on too.
TEST(StepAllocations, NoneWithTheCoarseLevel) {
  const auto fine = scenes::makeBarScene(4, 4, 32);
  auto coarse_bar = scenes::makeBarScene(2, 2, 16);
  coarse_bar.mesh.vertices *= 2.0;
  DeformerSetup setup = test::endVertexHandles(fine);
  setup.options.frame_guide = true;
  setup.options.rotation_extrapolation = 1.0;
  Deformer deformer(fine.mesh, setup);
  CoarseLevel coarse(fine.mesh, deformer, coarse_bar.mesh, test::endVertexHandles(coarse_bar));
  std::vector<std::vector<Eigen::Vector3d>> fine_targets, coarse_targets;
  for (int f = 0; f < 8; ++f) {
    const Eigen::Isometry3d far = scenes::barAxisTransform(fine, 0.3 * f, Eigen::Vector3d(0, f, 0));
    fine_targets.push_back(test::endTargets(fine, far));
    auto c = scenes::transformedPositions(coarse_bar.mesh, coarse_bar.near_vertices, Eigen::Isometry3d::Identity());
    const auto cf = scenes::transformedPositions(coarse_bar.mesh, coarse_bar.far_vertices, far);
    c.insert(c.end(), cf.begin(), cf.end());
    coarse_targets.push_back(std::move(c));
  }
  const auto run = [&](std::size_t f) {
    HandleTargets ft, ct;
    ft.vertex_positions = fine_targets[f];
    ct.vertex_positions = coarse_targets[f];
    coarse.guide(ct);
    return deformer.step(ft, StepBudget{3});
  };
  run(0);  // warm-up
  Eigen::internal::set_is_malloc_allowed(false);
  const std::uint64_t before = ::tetrig::test::allocationCount();
  for (std::size_t f = 1; f < fine_targets.size(); ++f) run(f);
  const std::uint64_t after = ::tetrig::test::allocationCount();
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_EQ(after - before, 0u);
  // The guide was used: the coarse level moved.
  EXPECT_GT(coarse.deformer().rotation(0).angularDistance(Eigen::Quaterniond::Identity()) +
                coarse.deformer().rotation(coarse.deformer().tetCount() - 1).angularDistance(Eigen::Quaterniond::Identity()),
            0.01);
}

TEST(StepAllocations, NoneWithRegionsInterpolationRigidGroupsAndPointHandles) {
  const auto bar = scenes::makeBarScene(4, 4, 20);
  DeformerSetup setup;
  setup.region_handles = {RegionHandle{bar.near_tets, true}, RegionHandle{bar.far_tets, true}};
  setup.rigid_groups = {RigidGroup{{100, 101, 102, 103, 900, 901}}};
  PointHandle point;
  point.tet = 200;
  point.barycentric = Eigen::Vector4d(0.25, 0.25, 0.25, 0.25);
  setup.point_handles = {point};
  Deformer deformer(bar.mesh, setup);
  std::vector<std::vector<RigidTransform>> transforms;
  std::vector<std::vector<Eigen::Vector3d>> points;
  for (int f = 0; f < 8; ++f) {
    const Eigen::Isometry3d far = scenes::barAxisTransform(bar, 0.4 * f, Eigen::Vector3d(0.2 * f, 0, 0));
    transforms.push_back({RigidTransform{}, RigidTransform{Eigen::Quaterniond(far.rotation()), far.translation()}});
    points.push_back({Eigen::Vector3d(2.0 + 0.1 * f, 2.0, 9.0)});
  }
  std::vector<HandleTargets> frames(transforms.size());
  for (size_t f = 0; f < frames.size(); ++f) {
    frames[f].region_transforms = transforms[f];
    frames[f].point_positions = points[f];
  }
  EXPECT_EQ(allocationsDuringSteps(deformer, frames, 3), 0u);
}

TEST(StepAllocations, NoneOnTheArmadilloTetMesh) {
  TETRIG_REQUIRE_DATA(path, "meshes/PositionBasedDynamics/armadillo_4k.node");
  const TetMesh mesh = readTetGen(path);
  // Handles: the 40 lowest and the 40 highest vertices (feet and ears), the top ones moved.
  std::vector<std::int32_t> order(static_cast<size_t>(mesh.vertexCount()));
  for (std::int32_t v = 0; v < mesh.vertexCount(); ++v) order[static_cast<size_t>(v)] = v;
  std::sort(order.begin(), order.end(), [&](auto a, auto b) { return mesh.vertices(a, 1) < mesh.vertices(b, 1); });
  DeformerSetup setup;
  setup.vertex_handles.assign(order.begin(), order.begin() + 40);
  setup.vertex_handles.insert(setup.vertex_handles.end(), order.end() - 40, order.end());
  Deformer deformer(mesh, setup);
  std::vector<std::vector<Eigen::Vector3d>> positions(6);
  std::vector<HandleTargets> frames(6);
  for (size_t f = 0; f < 6; ++f) {
    for (size_t i = 0; i < setup.vertex_handles.size(); ++i) {
      Eigen::Vector3d p = mesh.vertices.row(setup.vertex_handles[i]).transpose();
      if (i >= 40) p.x() += 0.05 * static_cast<double>(f);
      positions[f].push_back(p);
    }
    frames[f].vertex_positions = positions[f];
  }
  EXPECT_EQ(allocationsDuringSteps(deformer, frames, 3), 0u);
}

}  // namespace
}  // namespace tetrig
