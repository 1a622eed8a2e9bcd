// The live rig (DESIGN.md 6a): one labelled marker frame in, one deformed fine mesh out.
//
//   LiveRig live(rig);                                   // load: Deformer (factorization), prediction data
//   MarkerBindingReport r = live.bindLabels(labels);     // load: the source's label table -> rig markers
//   std::vector<float> x(live.fineVertexCount() * 3);
//   LiveFrameStats s = live.processFrame(frame, budget, x.data(), nullptr);   // per frame
//
// Per frame: every bound, valid, finite, plausible marker (device mm) -> rig units through rig.alignment ->
// its vertex handle's target; every other rig marker (occluded, invalid, rejected, or named by no source)
// is driven by its prediction (docs/live.md, "Occlusion": its rest offset carried by the
// current rigid motion of the body it is bound to), blended in and out over
// LiveRigOptions::occlusion_blend_s so nothing pops (docs/live.md, "Occlusion"); then
// Deformer::step(budget); then x_fine = B x_tet (Stoll et al. 2007 eq. 2.12) from the deformer's
// padded positions into the caller's buffer (and area-weighted vertex normals when asked for).
// Occlusion never changes the factor: markers stay vertex handles, only their targets change.
//
// Blends (s(u) = u^2 (3 - 2u) for u in [0, 1], 1 beyond: the smoothstep, zero slope at both ends;
// T = occlusion_blend_s; p(t) the marker's prediction at time t and R(t) its anchor's rotation,
// both from the deformer's current pose):
//   dropout at t0 (first frame without a measurement): the last target x relative to the
//       prediction from the pose it produced, in the anchor's frame, o = R(t0)^T (x - p(t0));
//       P(t) = p(t) + (1 - s((t - t0) / T)) R(t) o      (= x at t0: continuous; the offset turns
//                                                        with the body and fades out);
//   return at t1 (first frame measured again, measurement m(t)):
//       target(t) = P(t) + s((t - t1) / T) (m(t) - P(t))   (starts at P, ends at m).
// Time is the frames' own: device_timestamp_ns when non-zero, else receive_timestamp_ns (never the
// wall clock, so a live run replays bit for bit offline from the same frames and iteration counts),
// accumulated as an internal blend clock that never runs backwards (a timestamp earlier than the
// previous frame's advances it by 0; a frame with neither timestamp by untimed_frame_period_s) and
// that stands still on held frames (below): a blend progresses only in frames that are shown.
// Measured markers of the first frame that steps are taken as they are (there is no earlier pose
// to blend from). A frame with no measured rig marker holds the last pose (no step, kLivePoseHeld),
// unless the rig has no markers or a region target was set for the frame (setRegionTarget).
// Plausible samples (docs/live.md, "Implausible marker samples"): a valid sample that is not finite,
// lies beyond the rig's max_abs_coordinate, or lies farther from its marker's expected position than
// a human marker can move (LiveRigOptions::max_marker_speed_mm_s: the last accepted sample of that
// marker while it is recent, else its prediction, with floors from the rig's rest diagonal) is
// rejected: counted, and the marker is treated as occluded for that frame. Its next plausible sample
// is taken again (blending back from the prediction).
// Published poses: outside a box (kPoseBoundReach = 2 rest diagonals, docs/live.md "Never NaN", around the
// per-axis median of the markers' targets) the last pose is written again and flagged.
// Refresh: when some markers are predicted or blending and
// some are fully measured, the step runs one iteration, the predictions are recomputed from the
// pose that iteration gave, and the remaining iterations run with the new targets (predictions
// otherwise lag the measured markers by one frame); the iteration count and deadline are those
// of `budget` over both calls.
//
// Threads and ownership: `rig` is referenced, not copied: it must outlive the LiveRig. The
// constructor and bindLabels() are load-time code (allocate, may throw). processFrame(),
// writeLastPose(), setRegionTarget() and the accessors belong to one thread at a time (the solver
// thread): processFrame() allocates nothing, takes no lock, throws nothing and does no I/O.
#pragma once

#include "tetrig/deformer.hpp"
#include "tetrig/marker_frame.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/solver_settings.hpp"

#include <Eigen/Core>

#include <chrono>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace tetrig {

class CoarseLevel;
class LiveRigImpl;

struct LiveRigOptions {
  double occlusion_blend_s = 0.15;   // blend time when a marker drops out and when it returns (0: no blend)
  bool normals = false;              // also write per-vertex normals of the fine mesh
  double untimed_frame_period_s = 1.0 / 120.0;  // clock advance of a frame with neither timestamp
  bool compact_pose_transfer = true;  // stream a copy of B in blocks of 8 nearby fine vertices, float
                                     // weights and 16-bit columns (blockPoseTransfer), instead of the rig's
                                     // double B row by row, summed from float tet positions in float:
                                     // 0.35-0.45x the float CSR kernel's time in the caches, 0.45-0.5x out
                                     // of them (docs/live.md, "The pose transfer in blocks"), a fine vertex
                                     // within (n + 4) 2^-24 of |B| |x_tet| of the double product, n the
                                     // row's entries; rigs of more than 65536 tet vertices use the double B
  bool split_pose_transfer = false; // run the pose transfer on this thread and one worker thread made at
                                     // load (PoseTransferSplit; bit-identical results); for machines with 2+ cores
  bool predict_all_markers = false;  // false: predict only the markers that need it (not measured, or
                                     // blending); true: every marker every frame (markerPredictions()
                                     // then holds a current prediction for measured markers too; tools, tests)
  // The solver's settings (tetrig/solver_settings.hpp): the accurate ones by default. The fine-volume
  // constraint (solver.volume_constraint) is skipped on a rig whose fine mesh is not closed
  // (volumeNotKept()).
  SolverSettings solver;
  // Plausible samples only (docs/live.md, "Implausible marker samples"): a measured sample farther
  // from its marker's expected position than a human marker can move is treated as occluded for that
  // frame and counted (LiveFrameStats::rejected_marker_samples). D = the fine mesh's rest diagonal,
  // v = max_marker_speed_mm_s in rig units (through rig.alignment's scale), tau = time on the frames'
  // own clock, F_jump = marker_jump_floor_diagonals * D, F_pred = marker_prediction_bound_diagonals * D.
  // Expected position and bound: the marker's last accepted sample, within F_jump + v * tau, while
  // tau <= (F_pred - F_jump) / v; else, once some pose has been solved from accepted samples, its
  // prediction, within F_pred + v * (time since that pose); else none (accepted).
  double max_marker_speed_mm_s = 30000.0;       // 30 m/s (real clips: at most 12.4 m/s); 0: no sample is rejected
  double marker_jump_floor_diagonals = 0.1;     // slack on a marker's own last sample (SMPL: 0.26 m)
  double marker_prediction_bound_diagonals = 1.0;  // slack on its prediction (SMPL: 2.6 m)
};

enum LiveFrameFlags : std::uint32_t {
  kLivePoseHeld = 1u << 0,          // no rig marker measured in this frame: the last pose was kept (no step)
  kLiveMarkersPredicted = 1u << 1,  // some rig markers were driven by their prediction
  kLiveMarkersBlending = 1u << 2,   // some markers are blending between prediction and measurement
  kLiveDeadlineHit = 1u << 3,       // the step stopped at the deadline before max_iterations
  kLiveTargetsRejected = 1u << 4,   // the deformer rejected the targets (kept the previous ones)
  kLivePoseRejected = 1u << 5,      // the step produced a non-finite or implausible pose (outside
                                    // the pose bound's box): the last pose was written and the
                                    // deformer was reset to rest (should never happen)
  kLiveMarkersRejected = 1u << 6,   // some valid marker samples were rejected (rejected_marker_samples): those
                                    // markers were driven by their prediction, as occluded ones
};

struct LiveFrameStats {
  StepStats step;                    // the deformer's own stats (iterations, energy, flags, phase times); zero when held
  std::int64_t pose_transfer_ns = 0; // x_fine = B x_tet (+ normals), or the copy of the last pose when held
  std::int64_t coarse_ns = 0;        // the coarse level's step and guide (with a coarse rig), also counted in step.total_ns
  std::int64_t prepare_ns = 0;       // prepareNextFrame() work the caller left to this frame (run first; 0 when it
                                     // called prepareNextFrame() after the last frame, or had nothing to prepare)
  std::uint16_t measured_markers = 0;   // rig markers measured in this frame (blending back ones included)
  std::uint16_t occluded_markers = 0;   // rig markers driven by their prediction (unbound ones included)
  std::uint16_t blending_markers = 0;   // rig markers in a dropout fade or a return blend
  std::uint16_t unknown_markers = 0;    // frame markers whose id names no rig marker (ignored)
  std::uint16_t rejected_marker_samples = 0;  // valid samples of rig markers rejected: non-finite, beyond the rig's
                                              // max_abs_coordinate, or implausible (max_marker_speed_mm_s); their
                                              // markers count in occluded_markers (unless another sample was taken)
  std::uint32_t flags = 0;              // LiveFrameFlags
};

struct MarkerBindingReport {
  std::int32_t matched = 0;               // rig markers bound to a source id
  std::vector<std::string> missing;       // rig markers the source never names (always predicted), rig order
  std::vector<std::string> unknown;       // source labels the rig does not know (ignored), id order
  std::vector<std::string> duplicates;    // source labels naming a rig marker another id already took (ignored)
  std::int32_t sensors_matched = 0;       // rig pose sensors (rig.pose_sensors) bound to a source id
  std::vector<std::string> missing_sensors;  // pose sensors the source never names (their regions stay put)
  std::int32_t other_subjects = 0;        // with a subject: source labels of other subjects (or none), not bound
};

// The subjects a label table names, in order of first appearance: the parts before the first ':'
// ("alice:LFHD" -> "alice"), as Vicon writes one performer's markers. Labels without ':' name none.
std::vector<std::string> labelSubjects(std::span<const std::string> labels_by_id);

// Per-marker state of the occlusion blend.
enum class MarkerTrackState : std::uint8_t {
  kPredicted = 0,  // no measurement: prediction (+ fading dropout offset)
  kReturning = 1,  // measured again: blending from the prediction to the measurement
  kMeasured = 2,   // the measurement itself
};

class LiveRig {
 public:
  // Load time: copies rig.setup with padded positions on and builds the Deformer (factorization),
  // the prediction anchors, the rest normals and every per-frame buffer. Throws what the Deformer
  // and MarkerPredictor throw, and std::invalid_argument for a rig that fails validateRig or for
  // negative options.
  // coarse_rig (optional): a coarser rig of the same mesh and markers (tetrig build-rig with fewer
  // --tet-vertices) solved every frame before the fine iterations; its rotation change starts the
  // fine tets (docs/fidelity.md, "Coarse level"). Without one, the rig's own coarse level (Rig::coarse) is
  // used if it has one and options.solver.use_coarse_level. Its markers are matched to the rig's by label (every one
  // must be in the rig), its region handles take the rig's region targets (same count required),
  // its other handles stay at rest. Throws std::invalid_argument when it does not fit the rig
  // (coarseLevelMismatch in tetrig/rig_file.hpp: the same checks as a coarse level inside a rig file). The
  // live rig keeps no reference to it.
  explicit LiveRig(const Rig& rig, const LiveRigOptions& options = {}, const Rig* coarse_rig = nullptr);
  ~LiveRig();
  LiveRig(LiveRig&&) noexcept;
  LiveRig& operator=(LiveRig&&) noexcept;

  // Load time (allocates): binds the source's label table (labels_by_id[id] labels every Marker
  // with that id; only ids < 65536 can occur) to the rig's markers. A label matches a rig marker
  // when equal, or when the parts after their last ':' are equal ("meinard:LFHD" == "LFHD"); an
  // exact match wins over a stripped one, then the lowest id. Empty labels name nothing. Replaces
  // any earlier binding; marker blend states are kept. Not concurrently with processFrame().
  // With a `subject` (one performer of a source carrying several), only labels "subject:NAME" take
  // part (the subject is the text before the first ':'); every other label is another performer's: not bound, not reported or counted as
  // unknown (MarkerBindingReport::other_subjects, LiveFrameStats::unknown_markers).
  MarkerBindingReport bindLabels(std::span<const std::string> labels_by_id, std::string_view subject = {});

  // One frame: frame -> handle targets -> Deformer::step(budget) -> pose transfer into the caller's
  // buffers. positions: fineVertexCount()*3 floats (rig units, x0 y0 z0 x1 ...), required;
  // normals: fineVertexCount()*3 floats (unit vectors) or nullptr (ignored unless
  // LiveRigOptions::normals). Never writes a non-finite value. No allocation, lock, exception, I/O.
  LiveFrameStats processFrame(const MarkerFrame& frame, const StepBudget& budget, float* positions, float* normals) noexcept;

  // Work a frame leaves for the next one, done now: with SolverSettings::volume_constraint, the
  // constraint's linearization at the pose just published (the boundary's volume gradient, the fine
  // volume, and one frame in eight the solve for its direction z: about 0.1x a plain frame's cost); then SolverSettings::after_publish_iterations more
  // iterations on that frame's targets, stopped at `deadline` (the linearization is not). Call it
  // after publishing processFrame's buffers, so that this work stays off the receive -> published
  // path (FrameLoop does, with the frame's deadline); a processFrame that finds it still pending runs
  // it first, without a deadline (LiveFrameStats::prepare_ns). Either way the poses are bit for bit
  // the same when no deadline cuts the iterations. Returns the nanoseconds it took (at least 1), or 0
  // when nothing was pending. No allocation, lock, exception or I/O; same thread as processFrame.
  std::int64_t prepareNextFrame(std::chrono::steady_clock::time_point deadline = std::chrono::steady_clock::time_point::max()) noexcept;

  // The memory a frame reads (the deformer's and the coarse level's blocks, factors and vectors,
  // the pose transfer, the published pose), as byte ranges written to `out` (at most out.size());
  // returns how many there are. FrameLoop reads them just before a frame is due
  // (FrameLoopOptions::spin_before_frame_ns). Same thread as processFrame; no allocation.
  std::size_t frameWorkingSet(std::span<std::span<const std::byte>> out) const noexcept;

  // The last pose again (the rest pose before the first frame): for a stale source or a held pose.
  // Same buffers as processFrame (normals written only with LiveRigOptions::normals). No allocation.
  void writeLastPose(float* positions, float* normals) const noexcept;

  std::int32_t fineVertexCount() const noexcept;
  std::span<const std::int32_t> fineTriangles() const noexcept;  // #F*3 vertex indices, outward (CCW from outside)
  std::span<const float> restPositions() const noexcept;   // #fine*3, rig units
  std::span<const float> restNormals() const noexcept;     // #fine*3 (empty unless normals)
  const Rig& rig() const noexcept;
  const Deformer& deformer() const noexcept;
  const CoarseLevel* coarseLevel() const noexcept;  // nullptr without a coarse rig (tools, tests: internal type)
  const LiveRigOptions& options() const noexcept;
  // True when options.solver.volume_constraint asked for the fine mesh's volume to be kept but the
  // rig's fine mesh is not closed (and consistently oriented), so the constraint was skipped; tools
  // say so once.
  bool volumeNotKept() const noexcept;
  // Bytes of B each frame's pose transfer streams: the blocked copy's, or the rig's double B's.
  std::int64_t poseTransferBytes() const noexcept;

  // Region handles' targets (x = R x_rest + t, rig units), passed to every step: identity (rest)
  // unless something drives them, e.g. pose sensors, on the solver thread before processFrame.
  // setRegionTarget also makes the next processFrame step when no marker is measured (a held pose
  // would ignore the region); an index out of range is ignored. No allocation.
  void setRegionTarget(std::int32_t region, const RigidTransform& target) noexcept;
  std::span<const RigidTransform> regionTargets() const noexcept;  // one per rig.setup.region_handles
  // The vertex- and point-handle targets the last processFrame stepped with (rig units; markers'
  // handles carry their targets, the other handles their rest positions): with regionTargets(), what
  // a second Deformer of the rig needs to solve the same frame (tetrig_fidelity's converged reference).
  std::span<const Eigen::Vector3d> vertexTargets() const noexcept;
  std::span<const Eigen::Vector3d> pointTargets() const noexcept;

  // For tests and tools, per rig marker (rig.markers order), as of the last processFrame:
  std::span<const Eigen::Vector3d> markerTargets() const noexcept;      // the target it was driven with, rig units
  std::span<const Eigen::Vector3d> markerPredictions() const noexcept;  // its prediction, rig units
  std::span<const std::uint8_t> markerMeasured() const noexcept;        // 1: measured in that frame
  std::span<const std::uint8_t> markerRejected() const noexcept;        // 1: its sample was rejected (so predicted)
  std::span<const Eigen::Quaterniond> markerAnchorRotations() const noexcept;  // R of its prediction
  MarkerTrackState markerState(std::int32_t marker) const noexcept;
  // The rig marker bound to source id `id`, or -1.
  std::int32_t markerOfId(std::uint16_t id) const noexcept;

 private:
  std::unique_ptr<LiveRigImpl> impl_;  // the live rig's state (tetrig/live_rig_impl.hpp, internal)
};

}  // namespace tetrig
