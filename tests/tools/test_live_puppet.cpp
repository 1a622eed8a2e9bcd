// Puppeteering through the live rig: the example rig assets/puppet_hydra.json (the demo bar, its
// two ends as oriented regions driven by the Hydra's controllers "hydra0" / "hydra1" in clutch
// mode) fed recorded Hydra reports (encoded and decoded with the real decoder) through
// LiveRig::processFrame: the bound sensor's region follows the controller while its button is
// held, stays put when released, the other end stays at rest, and the rig steps although it has
// no markers.
#include "tetrig/drivers/hydra.hpp"
#include "tetrig/live_rig.hpp"
#include "tetrig/rigbuild/build_rig.hpp"

#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

namespace tetrig {
namespace {

const Rig& puppetRig() {
  static const Rig rig = [] {
    const std::filesystem::path source(TETRIG_SOURCE_DIR);
    rigbuild::BuildRigInputs in;
    in.mesh = source / "assets" / "bar_4x4x33.node";
    in.description = rigbuild::readRigDescription(source / "assets" / "puppet_hydra.json");
    in.check_deformer = false;
    return rigbuild::buildRig(in);
  }();
  return rig;
}

// One Hydra report: controller 1 at `far_mm` with `buttons`, controller 0 still at the origin.
MarkerFrame hydraFrame(drivers::HydraDecoder& decoder, std::uint8_t sequence, const Eigen::Vector3f& far_mm, std::uint8_t buttons) {
  drivers::HydraRawReport raw;
  raw.sequence = sequence;
  const float identity[4] = {1.0f, 0.0f, 0.0f, 0.0f};
  const float origin[3] = {0.0f, 0.0f, 0.0f};
  const float far[3] = {far_mm.x(), far_mm.y(), far_mm.z()};
  raw.controllers[0] = drivers::hydraControllerFromPose(origin, identity);
  raw.controllers[1] = drivers::hydraControllerFromPose(far, identity);
  raw.controllers[1].buttons = buttons;
  std::uint8_t bytes[drivers::kHydraReportSize];
  EXPECT_EQ(drivers::encodeHydraReport(raw, bytes), drivers::kHydraReportSize);
  MarkerFrame frame;
  EXPECT_EQ(decoder.decode(bytes, 1'000'000 * static_cast<std::int64_t>(sequence), frame), drivers::HydraStatus::kFrame);
  return frame;
}

Eigen::Vector3d regionCentroid(const LiveRig& live, std::size_t region) {
  const Rig& rig = live.rig();
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  int n = 0;
  for (const std::int32_t t : rig.setup.region_handles[region].tets)
    for (int k = 0; k < 4; ++k) {
      sum += live.deformer().position(rig.tet_mesh.tets(t, k));
      ++n;
    }
  return sum / n;
}

TEST(LivePuppet, TheHeldControllerDrivesItsRegionAndTheReleasedOneLeavesItPut) {
  const Rig& rig = puppetRig();
  ASSERT_EQ(rig.pose_sensors.size(), 2u);
  LiveRig live(rig);
  const std::vector<std::string> labels = {drivers::kHydraSensorLabels[0], drivers::kHydraSensorLabels[1]};
  const MarkerBindingReport report = live.bindLabels(labels);
  EXPECT_EQ(report.sensors_matched, 2);
  EXPECT_TRUE(report.missing_sensors.empty());
  EXPECT_TRUE(report.unknown.empty()) << "sensor ids are not unknown markers";
  const Eigen::Vector3d near_rest = regionCentroid(live, 0), far_rest = regionCentroid(live, 1);
  std::vector<float> fine(static_cast<std::size_t>(live.fineVertexCount()) * 3);
  drivers::HydraDecoder decoder;
  std::uint8_t seq = 1;
  // Released: moving the controller does nothing.
  for (float k = 0; k < 5; k += 1) {
    const LiveFrameStats s = live.processFrame(hydraFrame(decoder, seq++, Eigen::Vector3f(10.0f * k, 0, 0), 0), StepBudget{3}, fine.data(), nullptr);
    EXPECT_EQ(s.flags & kLivePoseHeld, 0u) << "a rig without markers steps";
    EXPECT_EQ(s.unknown_markers, 0);
  }
  EXPECT_LT((regionCentroid(live, 1) - far_rest).norm(), 1e-9);
  // Held: 40 mm along x (bar units: 4 cm -> 4 units at 0.1 per mm) and 30 mm along y, from where the button went down.
  const Eigen::Vector3f start(40.0f, 0.0f, 0.0f);
  for (float k = 0; k <= 20; k += 1) {
    const Eigen::Vector3f p = start + Eigen::Vector3f(2.0f * k, 1.5f * k, 0.0f);
    live.processFrame(hydraFrame(decoder, seq++, p, 0x01), StepBudget{3}, fine.data(), nullptr);
  }
  const Eigen::Vector3d moved = regionCentroid(live, 1) - far_rest;
  EXPECT_NEAR(moved.x(), 4.0, 1e-4);
  EXPECT_NEAR(moved.y(), 3.0, 1e-4);
  EXPECT_NEAR(moved.z(), 0.0, 1e-4);
  EXPECT_LT((regionCentroid(live, 0) - near_rest).norm(), 1e-9) << "hydra0 never pressed: the near end stays at rest";
  // Released again: the controller moves on, the far end stays where it was left.
  const Eigen::Vector3d left_at = regionCentroid(live, 1);
  for (float k = 0; k < 10; k += 1)
    live.processFrame(hydraFrame(decoder, seq++, Eigen::Vector3f(200.0f, -50.0f * k, 0.0f), 0), StepBudget{3}, fine.data(), nullptr);
  EXPECT_LT((regionCentroid(live, 1) - left_at).norm(), 1e-9);
  // The fine mesh follows: its far-end vertices moved by about the region's motion.
  float max_x = -1e30f;
  for (std::size_t i = 0; i < fine.size(); i += 3) max_x = std::max(max_x, fine[i]);
  EXPECT_GT(max_x, 4.0f + 4.0f - 0.1f) << "the bar is 4 units wide; its far end moved 4 units along x";
}

}  // namespace
}  // namespace tetrig
