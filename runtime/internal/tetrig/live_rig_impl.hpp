// The live rig's state (internal): what tetrig::LiveRig (tetrig/live_rig.hpp) holds behind its
// pointer: the deformer, the occlusion tracks and predictions, the plausibility tests, the coarse
// level, the fine-volume constraint and the pose-transfer copy the frame streams. The equations,
// the frame's steps and the threading rules are live_rig.hpp's; live_rig.cpp implements them. Only
// the runtime and its tests include this header.
#pragma once

#include "tetrig/coarse_level.hpp"
#include "tetrig/deformer.hpp"
#include "tetrig/live_rig.hpp"
#include "tetrig/marker_frame.hpp"
#include "tetrig/marker_prediction.hpp"
#include "tetrig/pose_bound.hpp"
#include "tetrig/pose_sensor.hpp"
#include "tetrig/pose_transfer_blocked.hpp"
#include "tetrig/pose_transfer_split.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/volume_constraint.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <chrono>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace tetrig {

class LiveRigImpl {
 public:
  // The members of tetrig::LiveRig of the same names, which forward here (live_rig.hpp documents them).
  LiveRigImpl(const Rig& rig, const LiveRigOptions& options, const Rig* coarse_rig);
  MarkerBindingReport bindLabels(std::span<const std::string> labels_by_id, std::string_view subject);
  LiveFrameStats processFrame(const MarkerFrame& frame, const StepBudget& budget, float* positions, float* normals) noexcept;
  std::int64_t prepareNextFrame(std::chrono::steady_clock::time_point deadline = std::chrono::steady_clock::time_point::max()) noexcept;
  void writeLastPose(float* positions, float* normals) const noexcept;
  std::int32_t fineVertexCount() const noexcept { return static_cast<std::int32_t>(rest_positions_.size() / 3); }
  std::span<const std::int32_t> fineTriangles() const noexcept;
  std::span<const float> restPositions() const noexcept { return rest_positions_; }
  std::span<const float> restNormals() const noexcept { return rest_normals_; }
  const Rig& rig() const noexcept { return *rig_; }
  const Deformer& deformer() const noexcept { return deformer_; }
  const CoarseLevel* coarseLevel() const noexcept { return coarse_.get(); }
  std::size_t frameWorkingSet(std::span<std::span<const std::byte>> out) const noexcept;
  const LiveRigOptions& options() const noexcept { return options_; }
  bool volumeNotKept() const noexcept { return options_.solver.volume_constraint && volume_constraint_ == nullptr; }
  std::int64_t poseTransferBytes() const noexcept {
    return blocked_b_.rows > 0 ? blocked_b_.bytes() : rig_->pose_transfer.bytes();
  }
  void setRegionTarget(std::int32_t region, const RigidTransform& target) noexcept;
  std::span<const RigidTransform> regionTargets() const noexcept { return region_targets_; }
  std::span<const Eigen::Vector3d> vertexTargets() const noexcept { return vertex_targets_; }
  std::span<const Eigen::Vector3d> pointTargets() const noexcept { return point_targets_; }
  std::span<const Eigen::Vector3d> markerTargets() const noexcept { return marker_target_; }
  std::span<const Eigen::Vector3d> markerPredictions() const noexcept { return prediction_; }
  std::span<const std::uint8_t> markerMeasured() const noexcept { return measured_; }
  std::span<const std::uint8_t> markerRejected() const noexcept { return rejected_; }
  std::span<const Eigen::Quaterniond> markerAnchorRotations() const noexcept { return rotation_; }
  MarkerTrackState markerState(std::int32_t marker) const noexcept { return tracks_[static_cast<std::size_t>(marker)].state; }
  std::int32_t markerOfId(std::uint16_t id) const noexcept {
    return id < marker_of_id_.size() ? marker_of_id_[id] : -1;
  }

 private:
  struct Track {
    MarkerTrackState state = MarkerTrackState::kPredicted;
    Eigen::Vector3d offset = Eigen::Vector3d::Zero();  // dropout offset o, in the anchor's frame (R^T o)
    std::int64_t dropout_ns = 0;                       // t0 (internal clock)
    std::int64_t return_ns = 0;                        // t1 (internal clock)
  };

  void buildCoarseLevel(const Rig& coarse);                  // load time
  double blendWeight(std::int64_t since_ns) const noexcept;  // s((now - event) / T)
  // processFrame's steps, in order (live_rig.cpp).
  std::int64_t advanceClock(const MarkerFrame& frame) noexcept;                    // dt since the last frame
  std::uint32_t takeMeasurements(const MarkerFrame& frame, LiveFrameStats& stats) noexcept;  // returns the markers measured
  std::uint32_t updateTracksAndTargets(LiveFrameStats& stats) noexcept;           // returns the markers blending
  void solve(const StepBudget& budget, std::uint32_t blending, LiveFrameStats& stats) noexcept;
  void transferAndBound(std::uint32_t measured, float* positions, float* normals, LiveFrameStats& stats) noexcept;
  double dropoutWeight(const Track& track) const noexcept;   // 1 - s((now - t0) / T)
  void refreshPredictions() noexcept;                         // prediction_ from the deformer's pose
  void transferPose(float* positions) const noexcept;         // B x_tet of the deformer's pose
  void linearizeVolumeConstraint(const float* fine) noexcept; // the constraint at the deformer's pose (fine = B x_tet)
  HandleTargets frameTargets() const noexcept;                // the last frame's vertex, region and point targets
  std::uint32_t updateTargets() noexcept;                     // targets from the states; returns the blending count
  bool plausibleSample(std::size_t marker, const Eigen::Vector3d& x) const noexcept;  // LiveRigOptions::max_marker_speed_mm_s

  const Rig* rig_ = nullptr;
  LiveRigOptions options_;
  Deformer deformer_;
  MarkerPredictor predictor_;
  BlockedPoseTransfer blocked_b_;             // when options.compact_pose_transfer and the rig fits (else empty)
  std::unique_ptr<PoseTransferSplit> split_;  // when options.split_pose_transfer
  std::unique_ptr<FineVolumeConstraint> volume_constraint_;  // when options.solver.volume_constraint and the fine mesh is closed
  std::vector<double> constraint_gradient_;                // its g, #tetV*3
  std::vector<float> constraint_scratch_;                  // a first iteration's fine pose (#fine*3), on a cold frame
  int frames_since_linearized_ = 0;
  // The volume constraint's direction z = L^-1 g: solved at one linearization in this many, kept
  // between (docs/deformation.md, "Volume constraint").
  static constexpr int kConstraintDirectionFrames = 8;
  int directions_kept_ = 0;
  bool next_frame_pending_ = false;  // the last accepted frame awaits prepareNextFrame()
  // Coarse level (with a coarse rig): its handle targets, and per coarse marker its vertex handle
  // and the rig marker that drives it.
  std::unique_ptr<CoarseLevel> coarse_;
  std::vector<Eigen::Vector3d> coarse_vertex_targets_, coarse_point_targets_;
  std::vector<RigidTransform> coarse_region_targets_;
  std::vector<std::pair<std::int32_t, std::int32_t>> coarse_marker_handles_;  // (coarse vertex handle, rig marker)
  std::int64_t blend_ns_ = 0;
  std::int64_t untimed_ns_ = 0;
  double max_abs_coordinate_ = 0.0;
  PoseBound pose_bound_;                          // this frame's box (targets + margin)
  std::vector<Eigen::Vector3d> region_centroid_;  // rest centroid of each region handle's tets

  // Binding: source id -> rig marker (-1: unknown).
  std::vector<std::int32_t> marker_of_id_;
  std::vector<std::uint8_t> other_subject_of_id_;  // 1: another performer's marker (bindLabels' subject)
  // Pose sensors (rig.pose_sensors): one driver each, the source id that carries it, and this
  // frame's sample (tetrig/pose_sensor.hpp).
  std::vector<PoseSensorDriver> sensors_;
  std::vector<std::int32_t> sensor_of_id_;
  std::vector<const Marker*> sensor_sample_;

  // Handle targets passed to step().
  std::vector<Eigen::Vector3d> vertex_targets_;  // one per vertex handle (non-marker ones stay at rest)
  std::vector<RigidTransform> region_targets_;
  std::vector<Eigen::Vector3d> point_targets_;   // rest positions of the point handles

  // Per rig marker.
  std::vector<Track> tracks_;
  std::vector<Eigen::Vector3d> measurement_, prediction_, previous_prediction_, marker_target_;
  std::vector<Eigen::Quaterniond> rotation_;  // the anchor rotation R of each prediction
  std::vector<std::uint8_t> measured_;
  std::vector<std::uint8_t> skip_prediction_;  // per marker: measured and settled, no prediction needed
  // Plausible samples (plausibleSample): each marker's last accepted sample and when (sample clock).
  std::vector<Eigen::Vector3d> accepted_position_;
  std::vector<std::int64_t> accepted_ns_;
  std::vector<std::uint8_t> has_accepted_, rejected_;
  double max_speed_ = 0.0;          // rig units per second (0: no test)
  double jump_floor_ = 0.0;         // rig units
  double prediction_bound_ = 0.0;   // rig units
  std::int64_t own_window_ns_ = 0;  // a marker's own last sample is its reference while this recent
  std::int64_t sample_ns_ = 0;      // the frames' own clock, advanced on every frame (held ones too)
  std::int64_t body_ns_ = 0;        // when the last pose solved from accepted samples was published
  bool body_valid_ = false;         // such a pose exists since the start or the last reset

  // Clock (internal, ns) and whether any frame has stepped yet.
  bool have_time_ = false;
  std::int64_t last_source_ns_ = 0;
  std::int64_t now_ns_ = 0;
  bool stepped_ = false;
  bool regions_changed_ = false;  // setRegionTarget since the last processFrame

  // Output: rest and last pose (floats, #fine*3), normals accumulator.
  std::vector<float> rest_positions_, last_positions_;
  std::vector<float> rest_normals_, last_normals_, normal_sum_;
};

}  // namespace tetrig
