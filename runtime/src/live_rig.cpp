// The live rig (DESIGN.md 6a): marker binding by label, occlusion prediction blended in and out
// without pops, Deformer::step (Stoll et al. 2007 section 2.3) and pose transfer x_fine = B x_tet
// (eq. 2.12) with area-weighted vertex normals. Equations in tetrig/live_rig.hpp and docs/live.md.
#include "tetrig/live_rig_impl.hpp"
#include "tetrig/working_set.hpp"

#include "tetrig/clock.hpp"
#include "tetrig/polar.hpp"
#include "tetrig/pose_transfer.hpp"
#include "tetrig/pose_transfer_padded.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string_view>

namespace tetrig {
namespace {

constexpr std::size_t kMaxIds = 65536;  // Marker::id is 16 bits

const Rig& validated(const Rig& rig) {
  if (std::string e = validateRig(rig); !e.empty()) throw std::invalid_argument("live rig: " + e);
  return rig;
}

// Whether the live rig keeps the fine mesh's volume: asked for, and the fine mesh is closed.
bool keepsVolume(const Rig& rig, const LiveRigOptions& options) {
  return options.solver.volume_constraint &&
         closedOrientedSurface(std::span<const std::int32_t>(rig.fine_triangles.data(), static_cast<std::size_t>(rig.fine_triangles.size())));
}

// Whether a coarse level turns the fine tets by the rig's oriented regions' turns: it interpolates
// each of them over its own tets (region handle r of both is the same region: coarseLevelMismatch),
// and its guide hands each fine tet its coarse tet's change, that turn included.
bool carriesRegionTurns(const Rig& rig, const Rig& coarse) {
  const DeformerOptions& o = coarse.setup.options;
  const auto& fine_regions = rig.setup.region_handles;
  const auto& coarse_regions = coarse.setup.region_handles;
  if (!o.interpolate_rotations || !o.update_rotations || coarse_regions.size() != fine_regions.size()) return false;
  for (std::size_t r = 0; r < fine_regions.size(); ++r)
    if (fine_regions[r].oriented && !coarse_regions[r].oriented) return false;
  return true;
}

DeformerSetup liveSetup(const Rig& rig, const LiveRigOptions& options, const Rig* coarse) {
  DeformerSetup setup = rig.setup;
  setup.options.frame_guide = coarse != nullptr;
  // Under such a coarse level the fine level takes the regions' turns from the guide alone:
  // interpolating them again would start each frame turned twice as far near the regions.
  if (coarse != nullptr && carriesRegionTurns(rig, *coarse)) setup.options.interpolate_rotations = false;
  // The input of the pose transfer: float positions for B's compact copy (its float kernel), else doubles.
  const bool compact = options.compact_pose_transfer && fitsCompactPoseTransfer(rig.pose_transfer.cols);
  setup.options.padded_positions = !compact;
  setup.options.padded_float_positions = compact;
  const SolverSettings& solver = options.solver;
  setup.options.rotation_extrapolation = solver.rotation_extrapolation;
  setup.options.rotation_extrapolation_max_deg = solver.rotation_extrapolation_max_deg;
  setup.options.rotation_relaxation = solver.rotation_relaxation;
  setup.options.volume_weight = solver.volume_weight;
  setup.options.inversion_guard = solver.inversion_guard;
  setup.options.inversion_guard_threshold = solver.inversion_guard_threshold;
  setup.options.inversion_guard_solves = solver.inversion_guard_solves;
  setup.options.untangle = solver.untangle;
  setup.options.linear_constraint = keepsVolume(rig, options);
  setup.guarded_tet_count = rig.body_tet_count;
  return setup;
}

// Rest positions of a setup's vertex handles and point handles: the targets of handles nothing drives.
void restHandleTargets(const TetMesh& mesh, const DeformerSetup& setup, std::vector<Eigen::Vector3d>& vertex,
                       std::vector<Eigen::Vector3d>& point) {
  vertex.clear();
  for (const std::int32_t v : setup.vertex_handles) vertex.push_back(mesh.vertices.row(v).transpose());
  point.clear();
  for (const PointHandle& p : setup.point_handles) {
    Eigen::Vector3d rest = Eigen::Vector3d::Zero();
    for (int c = 0; c < 4; ++c) rest += p.barycentric[c] * mesh.vertices.row(mesh.tets(p.tet, c)).transpose();
    point.push_back(rest);
  }
}

// The coarse level to use: the one given, else the rig's own (when asked for), else none.
const Rig* coarseRigOf(const Rig& rig, const LiveRigOptions& options, const Rig* given) {
  if (given != nullptr) return given;
  return options.solver.use_coarse_level ? rig.coarse.get() : nullptr;
}

std::vector<std::int32_t> markerVertices(const Rig& rig) {
  std::vector<std::int32_t> v;
  for (const RigMarker& m : rig.markers) v.push_back(m.tet_vertex);
  return v;
}

std::string_view afterLastColon(std::string_view s) {
  const std::size_t colon = s.rfind(':');
  return colon == std::string_view::npos ? s : s.substr(colon + 1);
}

// Area-weighted vertex normals: sum over incident triangles of (b - a) x (c - a) (twice the area
// times the unit normal), normalised. A vertex whose sum is zero or not finite keeps `fallback`'s
// value (its previous normal). `sum` is #V*3 scratch; `normals` may alias `fallback`.
void vertexNormals(const float* x, std::span<const std::int32_t> triangles, std::span<float> sum, const float* fallback,
                   float* normals) noexcept {
  std::fill(sum.begin(), sum.end(), 0.0f);
  for (std::size_t f = 0; f + 2 < triangles.size(); f += 3) {
    const auto a = static_cast<std::size_t>(triangles[f]) * 3, b = static_cast<std::size_t>(triangles[f + 1]) * 3,
               c = static_cast<std::size_t>(triangles[f + 2]) * 3;
    const float e1x = x[b] - x[a], e1y = x[b + 1] - x[a + 1], e1z = x[b + 2] - x[a + 2];
    const float e2x = x[c] - x[a], e2y = x[c + 1] - x[a + 1], e2z = x[c + 2] - x[a + 2];
    const float nx = e1y * e2z - e1z * e2y, ny = e1z * e2x - e1x * e2z, nz = e1x * e2y - e1y * e2x;
    for (const std::size_t v : {a, b, c}) {
      sum[v] += nx;
      sum[v + 1] += ny;
      sum[v + 2] += nz;
    }
  }
  for (std::size_t v = 0; v < sum.size(); v += 3) {
    const double nx = sum[v], ny = sum[v + 1], nz = sum[v + 2];
    const double length = std::sqrt(nx * nx + ny * ny + nz * nz);
    if (length > 0.0 && std::isfinite(length)) {
      normals[v] = static_cast<float>(nx / length);
      normals[v + 1] = static_cast<float>(ny / length);
      normals[v + 2] = static_cast<float>(nz / length);
    } else {
      normals[v] = fallback[v];
      normals[v + 1] = fallback[v + 1];
      normals[v + 2] = fallback[v + 2];
    }
  }
}

}  // namespace

LiveRigImpl::LiveRigImpl(const Rig& rig, const LiveRigOptions& options, const Rig* coarse_rig)
    : rig_(&validated(rig)),
      options_(options),
      deformer_(rig.tet_mesh, liveSetup(rig, options, coarseRigOf(rig, options, coarse_rig))),
      predictor_(rig.tet_mesh, rig.body_vertex_count, rig.body_tet_count, markerVertices(rig), MarkerPredictionOptions{}) {
  if (!(options.occlusion_blend_s >= 0.0) || !std::isfinite(options.occlusion_blend_s)) {
    throw std::invalid_argument("live rig: occlusion_blend_s must be finite and >= 0");
  }
  if (!(options.untimed_frame_period_s >= 0.0) || !std::isfinite(options.untimed_frame_period_s)) {
    throw std::invalid_argument("live rig: untimed_frame_period_s must be finite and >= 0");
  }
  for (const double v : {options.max_marker_speed_mm_s, options.marker_jump_floor_diagonals, options.marker_prediction_bound_diagonals}) {
    if (!(v >= 0.0) || !std::isfinite(v)) {
      throw std::invalid_argument("live rig: max_marker_speed_mm_s and the marker bounds must be finite and >= 0");
    }
  }
  blend_ns_ = static_cast<std::int64_t>(std::llround(options.occlusion_blend_s * 1e9));
  untimed_ns_ = static_cast<std::int64_t>(std::llround(options.untimed_frame_period_s * 1e9));
  max_abs_coordinate_ = rig.setup.options.max_abs_coordinate;

  const DeformerSetup& setup = rig.setup;
  restHandleTargets(rig.tet_mesh, setup, vertex_targets_, point_targets_);
  region_targets_.assign(setup.region_handles.size(), RigidTransform{});
  for (const RegionHandle& region : setup.region_handles) region_centroid_.push_back(regionRestCentroid(rig.tet_mesh, region));
  for (const RigPoseSensor& sensor : rig.pose_sensors)
    sensors_.emplace_back(sensor, rig.alignment, region_centroid_.at(static_cast<std::size_t>(sensor.region_handle)));
  sensor_sample_.assign(sensors_.size(), nullptr);

  const std::size_t markers = rig.markers.size();
  tracks_.assign(markers, Track{});
  measurement_.assign(markers, Eigen::Vector3d::Zero());
  measured_.assign(markers, 0);
  skip_prediction_.assign(markers, 0);
  accepted_position_.assign(markers, Eigen::Vector3d::Zero());
  accepted_ns_.assign(markers, 0);
  has_accepted_.assign(markers, 0);
  rejected_.assign(markers, 0);
  if (options.compact_pose_transfer && fitsCompactPoseTransfer(rig.pose_transfer.cols))
    blocked_b_ = blockPoseTransfer(rig.pose_transfer, std::span<const double>(rig.fine_vertices.data(),
                                                                              static_cast<std::size_t>(rig.fine_vertices.size())));
  if (options.split_pose_transfer) {
    split_ = blocked_b_.rows > 0 ? std::make_unique<PoseTransferSplit>(blocked_b_.view())
                                 : std::make_unique<PoseTransferSplit>(rig.pose_transfer.view());
  }
  if (keepsVolume(rig, options)) {
    volume_constraint_ = std::make_unique<FineVolumeConstraint>(
        rig.tet_mesh, rig.body_tet_count,
        std::span<const std::int32_t>(rig.fine_triangles.data(), static_cast<std::size_t>(rig.fine_triangles.size())),
        std::span<const double>(rig.fine_vertices.data(), static_cast<std::size_t>(rig.fine_vertices.size())));
    constraint_gradient_.assign(3 * static_cast<std::size_t>(rig.tet_mesh.vertexCount()), 0.0);
    constraint_scratch_.assign(3 * static_cast<std::size_t>(rig.fine_vertices.rows()), 0.0f);
  }
  if (const Rig* coarse = coarseRigOf(rig, options, coarse_rig)) buildCoarseLevel(*coarse);
  prediction_.resize(markers);
  for (std::size_t k = 0; k < markers; ++k) {
    // The deformer starts at rest, where every prediction is the marker's rest position.
    prediction_[k] = rig.tet_mesh.vertices.row(rig.markers[k].tet_vertex).transpose();
  }
  previous_prediction_ = prediction_;
  marker_target_ = prediction_;
  rotation_.assign(markers, Eigen::Quaterniond::Identity());

  const auto fine = static_cast<std::size_t>(rig.fine_vertices.rows());
  rest_positions_.resize(fine * 3);
  const double rest_diagonal = boundingBoxDiagonal(rig.fine_vertices);
  pose_bound_ = PoseBound(rest_diagonal, max_abs_coordinate_,
                          std::max(markers, setup.vertex_handles.size() + setup.point_handles.size() + setup.region_handles.size()));
  // Plausible samples, in rig units: the alignment is a similarity (s Q), its scale s = |det|^(1/3)
  // rig units per device millimetre.
  const double units_per_mm = std::cbrt(std::abs(rig.alignment.linear.determinant()));
  max_speed_ = std::isfinite(units_per_mm) ? options.max_marker_speed_mm_s * units_per_mm : 0.0;
  jump_floor_ = options.marker_jump_floor_diagonals * rest_diagonal;
  prediction_bound_ = options.marker_prediction_bound_diagonals * rest_diagonal;
  if (max_speed_ > 0.0) {
    const double window_s = std::max(0.0, prediction_bound_ - jump_floor_) / max_speed_;
    own_window_ns_ = static_cast<std::int64_t>(std::min(window_s * 1e9, 1e18));
  }
  for (std::size_t v = 0; v < fine; ++v)
    for (int c = 0; c < 3; ++c) rest_positions_[v * 3 + static_cast<std::size_t>(c)] = static_cast<float>(rig.fine_vertices(static_cast<Eigen::Index>(v), c));
  last_positions_ = rest_positions_;
  if (options.normals) {
    // Fallback of a vertex with no usable triangle at rest: the direction from the rest centroid.
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (std::size_t v = 0; v < fine; ++v) centroid += rig.fine_vertices.row(static_cast<Eigen::Index>(v)).transpose();
    centroid /= static_cast<double>(std::max<std::size_t>(fine, 1));
    std::vector<float> outward(fine * 3);
    for (std::size_t v = 0; v < fine; ++v) {
      Eigen::Vector3d d = rig.fine_vertices.row(static_cast<Eigen::Index>(v)).transpose() - centroid;
      d = d.norm() > 0.0 ? Eigen::Vector3d(d.normalized()) : Eigen::Vector3d::UnitY();
      for (int c = 0; c < 3; ++c) outward[v * 3 + static_cast<std::size_t>(c)] = static_cast<float>(d[c]);
    }
    rest_normals_.resize(fine * 3);
    normal_sum_.resize(fine * 3);
    vertexNormals(rest_positions_.data(), fineTriangles(), normal_sum_, outward.data(), rest_normals_.data());
    last_normals_ = rest_normals_;
  }
}

void LiveRigImpl::buildCoarseLevel(const Rig& coarse) {
  if (std::string e = coarseLevelMismatch(*rig_, coarse); !e.empty()) {
    throw std::invalid_argument("live rig: " + e + " (build both from the same mesh, rig description and marker clip)");
  }
  const DeformerSetup& cs = coarse.setup;
  for (const RigMarker& m : coarse.markers) {
    std::int32_t match = 0;  // found: coarseLevelMismatch checked every label
    while (rig_->markers[static_cast<std::size_t>(match)].label != m.label) ++match;
    coarse_marker_handles_.emplace_back(m.vertex_handle, match);
  }
  restHandleTargets(coarse.tet_mesh, cs, coarse_vertex_targets_, coarse_point_targets_);
  coarse_region_targets_.assign(cs.region_handles.size(), RigidTransform{});
  DeformerSetup setup = cs;
  setup.options.padded_positions = false;
  setup.options.padded_float_positions = false;
  setup.options.rotation_extrapolation = 0.0;  // measured: no gain on the coarse chain (docs/fidelity.md)
  setup.options.rotation_relaxation = options_.solver.rotation_relaxation;
  setup.options.volume_weight = options_.solver.volume_weight;
  setup.options.inversion_guard = options_.solver.inversion_guard;
  setup.options.inversion_guard_threshold = options_.solver.inversion_guard_threshold;
  setup.options.inversion_guard_solves = options_.solver.inversion_guard_solves;
  setup.guarded_tet_count = coarse.body_tet_count;
  setup.options.frame_guide = false;
  CoarseLevelOptions co;
  co.iterations = options_.solver.coarse_iterations;
  coarse_ = std::make_unique<CoarseLevel>(rig_->tet_mesh, deformer_, coarse.tet_mesh, setup, co);
}

std::span<const std::int32_t> LiveRigImpl::fineTriangles() const noexcept {
  return {rig_->fine_triangles.data(), static_cast<std::size_t>(rig_->fine_triangles.rows()) * 3};
}

std::vector<std::string> labelSubjects(std::span<const std::string> labels_by_id) {
  std::vector<std::string> subjects;
  for (const std::string& label : labels_by_id) {
    const std::size_t colon = label.find(':');
    if (colon == std::string::npos) continue;
    std::string subject = label.substr(0, colon);
    if (std::find(subjects.begin(), subjects.end(), subject) == subjects.end()) subjects.push_back(std::move(subject));
  }
  return subjects;
}

MarkerBindingReport LiveRigImpl::bindLabels(std::span<const std::string> labels_by_id, std::string_view subject) {
  const std::size_t ids = std::min(labels_by_id.size(), kMaxIds);
  const std::vector<RigMarker>& markers = rig_->markers;
  MarkerBindingReport report;
  // Another performer's labels (a subject was named and the label's prefix is not it).
  other_subject_of_id_.assign(ids, 0);
  if (!subject.empty()) {
    for (std::size_t id = 0; id < ids; ++id) {
      const std::string& label = labels_by_id[id];
      const std::size_t colon = label.find(':');
      if (label.empty() || (colon != std::string::npos && std::string_view(label).substr(0, colon) == subject)) continue;
      other_subject_of_id_[id] = 1;
      ++report.other_subjects;
    }
  }
  // Best id per rig marker: exact (rank 2) beats stripped (rank 1), then the lowest id.
  std::vector<std::int32_t> best_id(markers.size(), -1);
  std::vector<int> best_rank(markers.size(), 0);
  std::vector<std::int32_t> candidate(ids, -1);  // the rig marker a label names, if any
  for (std::size_t id = 0; id < ids; ++id) {
    const std::string& label = labels_by_id[id];
    if (label.empty() || other_subject_of_id_[id] != 0) continue;
    int rank = 0;
    std::int32_t marker = -1;
    for (std::size_t k = 0; k < markers.size(); ++k) {
      int r = 0;
      if (label == markers[k].label) {
        r = 2;
      } else if (afterLastColon(label) == afterLastColon(markers[k].label)) {
        r = 1;
      }
      if (r > rank) {
        rank = r;
        marker = static_cast<std::int32_t>(k);
      }
    }
    if (marker < 0) continue;
    candidate[id] = marker;
    const auto k = static_cast<std::size_t>(marker);
    if (rank > best_rank[k]) {
      best_rank[k] = rank;
      best_id[k] = static_cast<std::int32_t>(id);
    }
  }
  marker_of_id_.assign(ids, -1);
  for (std::size_t k = 0; k < markers.size(); ++k) {
    if (best_id[k] < 0) {
      report.missing.push_back(markers[k].label);
      continue;
    }
    marker_of_id_[static_cast<std::size_t>(best_id[k])] = static_cast<std::int32_t>(k);
    ++report.matched;
  }
  // Pose sensors: the lowest id whose label matches (exactly, or after the last ':').
  sensor_of_id_.assign(ids, -1);
  for (std::size_t s = 0; s < sensors_.size(); ++s) {
    const std::string& want = sensors_[s].sensor().sensor_label;
    std::int32_t found = -1;
    for (std::size_t id = 0; id < ids && found < 0; ++id) {
      const std::string& label = labels_by_id[id];
      if (!label.empty() && other_subject_of_id_[id] == 0 && marker_of_id_[id] < 0 && sensor_of_id_[id] < 0 &&
          (label == want || afterLastColon(label) == afterLastColon(want))) {
        found = static_cast<std::int32_t>(id);
      }
    }
    if (found < 0) {
      report.missing_sensors.push_back(want);
      continue;
    }
    sensor_of_id_[static_cast<std::size_t>(found)] = static_cast<std::int32_t>(s);
    ++report.sensors_matched;
  }
  for (std::size_t id = 0; id < ids; ++id) {
    if (labels_by_id[id].empty() || other_subject_of_id_[id] != 0 || marker_of_id_[id] >= 0 || sensor_of_id_[id] >= 0) continue;
    (candidate[id] >= 0 ? report.duplicates : report.unknown).push_back(labels_by_id[id]);
  }
  return report;
}

void LiveRigImpl::setRegionTarget(std::int32_t region, const RigidTransform& target) noexcept {
  if (region < 0 || static_cast<std::size_t>(region) >= region_targets_.size()) return;
  region_targets_[static_cast<std::size_t>(region)] = target;
  regions_changed_ = true;
}

double LiveRigImpl::blendWeight(std::int64_t since_ns) const noexcept {
  if (blend_ns_ <= 0) return 1.0;
  const double u = std::clamp(static_cast<double>(since_ns) / static_cast<double>(blend_ns_), 0.0, 1.0);
  return u * u * (3.0 - 2.0 * u);
}

// The frame path in named steps: the clock, the measurements, the tracks and targets, the solve,
// the pose transfer and its bound. processFrame() runs them in order.

LiveFrameStats LiveRigImpl::processFrame(const MarkerFrame& frame, const StepBudget& budget, float* positions, float* normals) noexcept {
  LiveFrameStats stats;
  stats.prepare_ns = prepareNextFrame();
  const std::size_t markers = rig_->markers.size();
  const std::int64_t dt_ns = advanceClock(frame);
  const std::uint32_t measured = takeMeasurements(frame, stats);
  // The blend clock runs only on frames that step: while the pose is held nothing is shown, so
  // no blend may progress unseen and land in one step when the markers return.
  if (measured > 0 || markers == 0 || regions_changed_) now_ns_ += dt_ns;
  const std::uint32_t blending = updateTracksAndTargets(stats);

  // Hold the pose when nothing was measured (a rig without markers, or with region targets set
  // for this frame, steps anyway).
  const bool regions_changed = regions_changed_;
  regions_changed_ = false;
  if (measured == 0 && markers > 0 && !regions_changed) {
    stats.flags |= kLivePoseHeld;
    const std::int64_t t0 = monotonicNowNs();
    writeLastPose(positions, normals);
    stats.pose_transfer_ns = monotonicNowNs() - t0;
    return stats;
  }
  solve(budget, blending, stats);
  transferAndBound(measured, positions, normals, stats);
  return stats;
}

// 1. Time since the previous frame, from the frames' own timestamps (never negative).
std::int64_t LiveRigImpl::advanceClock(const MarkerFrame& frame) noexcept {
  const std::int64_t source_ns = frame.device_timestamp_ns != 0 ? frame.device_timestamp_ns : frame.receive_timestamp_ns;
  std::int64_t dt_ns = 0;
  if (!have_time_) {
    have_time_ = true;
  } else if (source_ns == 0) {
    dt_ns = untimed_ns_;
  } else if (source_ns > last_source_ns_) {
    dt_ns = source_ns - last_source_ns_;
  }
  if (source_ns != 0) last_source_ns_ = source_ns;
  sample_ns_ = dt_ns > std::numeric_limits<std::int64_t>::max() - sample_ns_ ? std::numeric_limits<std::int64_t>::max() : sample_ns_ + dt_ns;
  return dt_ns;
}

// 2. Measurements: bound ids, valid, finite, sane after alignment, plausible (plausibleSample);
// the pose sensors' samples move their regions. Returns the markers measured.
std::uint32_t LiveRigImpl::takeMeasurements(const MarkerFrame& frame, LiveFrameStats& stats) noexcept {
  const Rig& rig = *rig_;
  const std::size_t markers = rig.markers.size();
  std::fill(measured_.begin(), measured_.end(), std::uint8_t{0});
  std::fill(rejected_.begin(), rejected_.end(), std::uint8_t{0});
  const int count = std::min<int>(frame.marker_count, kMaxMarkers);
  std::uint32_t unknown = 0, rejected = 0;
  std::fill(sensor_sample_.begin(), sensor_sample_.end(), nullptr);
  for (int i = 0; i < count; ++i) {
    const Marker& mk = frame.markers[static_cast<std::size_t>(i)];
    const std::int32_t k = markerOfId(mk.id);
    if (k < 0) {
      const std::int32_t s = mk.id < sensor_of_id_.size() ? sensor_of_id_[mk.id] : -1;
      if (s >= 0) {
        sensor_sample_[static_cast<std::size_t>(s)] = &mk;
      } else if (mk.id >= other_subject_of_id_.size() || other_subject_of_id_[mk.id] == 0) {
        ++unknown;
      }
      continue;
    }
    const auto ku = static_cast<std::size_t>(k);
    if (!mk.valid || measured_[ku]) continue;
    const Eigen::Vector3d mm(mk.position_mm[0], mk.position_mm[1], mk.position_mm[2]);
    const Eigen::Vector3d x = rig.alignment.linear * mm + rig.alignment.translation;
    if (!mm.allFinite() || !x.allFinite() || x.cwiseAbs().maxCoeff() > max_abs_coordinate_ || !plausibleSample(ku, x)) {
      rejected_[ku] = 1;
      ++rejected;
      continue;
    }
    measurement_[ku] = x;
    measured_[ku] = 1;
  }
  std::uint32_t measured = 0;
  for (std::size_t k = 0; k < markers; ++k) {
    if (!measured_[k]) continue;
    ++measured;
    rejected_[k] = 0;  // another sample of it was taken
    accepted_position_[k] = measurement_[k];
    accepted_ns_[k] = sample_ns_;
    has_accepted_[k] = 1;
  }
  stats.rejected_marker_samples = static_cast<std::uint16_t>(std::min<std::uint32_t>(rejected, 0xFFFF));
  if (rejected > 0) stats.flags |= kLiveMarkersRejected;
  // Pose sensors move their regions (clutch or absolute; a sample that is not usable changes
  // nothing). A frame that carries a usable sensor sample steps even with every marker occluded.
  for (std::size_t s = 0; s < sensors_.size(); ++s) {
    const Marker* sample = sensor_sample_[s];
    if (sample == nullptr || !sample->valid || !sample->has_orientation) continue;
    const auto region = static_cast<std::size_t>(sensors_[s].sensor().region_handle);
    sensors_[s].update(sample, region_targets_[region]);
    regions_changed_ = true;
  }
  stats.unknown_markers = static_cast<std::uint16_t>(std::min<std::uint32_t>(unknown, 0xFFFF));
  stats.measured_markers = static_cast<std::uint16_t>(std::min<std::size_t>(measured, 0xFFFF));
  stats.occluded_markers = static_cast<std::uint16_t>(std::min<std::size_t>(markers - measured, 0xFFFF));
  return measured;
}

// 3. Predictions from the deformer's current pose, each marker's blend state, then the targets.
// Returns the markers blending.
std::uint32_t LiveRigImpl::updateTracksAndTargets(LiveFrameStats& stats) noexcept {
  const std::size_t markers = rig_->markers.size();
  previous_prediction_.swap(prediction_);
  refreshPredictions();
  for (std::size_t k = 0; k < markers; ++k) {
    Track& track = tracks_[k];
    if (measured_[k]) {
      if (track.state == MarkerTrackState::kPredicted) {
        if (stepped_) {
          track.state = MarkerTrackState::kReturning;
          track.return_ns = now_ns_;
        } else {
          track.state = MarkerTrackState::kMeasured;  // the first pose: nothing to blend from
          track.offset.setZero();
        }
      }
      if (track.state == MarkerTrackState::kReturning && blendWeight(now_ns_ - track.return_ns) >= 1.0) {
        track.state = MarkerTrackState::kMeasured;
        track.offset.setZero();
      }
    } else if (track.state != MarkerTrackState::kPredicted) {
      track.state = MarkerTrackState::kPredicted;
      // The last target relative to the prediction from the pose that target produced (this
      // frame's), in the anchor's frame so that it turns with the body while it fades.
      track.offset = rotation_[k].conjugate() * (marker_target_[k] - prediction_[k]);
      track.dropout_ns = now_ns_;
    }
  }
  const std::uint32_t blending = updateTargets();
  stats.blending_markers = static_cast<std::uint16_t>(std::min<std::uint32_t>(blending, 0xFFFF));
  if (stats.occluded_markers > 0) stats.flags |= kLiveMarkersPredicted;
  if (blending > 0) stats.flags |= kLiveMarkersBlending;
  return blending;
}

namespace {

// A further step of the same frame added to the frame's step statistics.
void addStep(StepStats& frame, const StepStats& more) noexcept {
  frame.iterations += more.iterations;
  frame.flags |= more.flags;
  frame.energy = more.energy;
  frame.exact_rotations += more.exact_rotations;
  frame.guarded_solves += more.guarded_solves;  // the guard of every iteration of the frame
  frame.guarded_tets = more.guarded_tets;        // held after the frame's last iteration
  frame.solve_ns += more.solve_ns;
  frame.rotation_ns += more.rotation_ns;
  frame.interpolation_ns += more.interpolation_ns;
  frame.rigid_ns += more.rigid_ns;
  frame.total_ns += more.total_ns;
}

}  // namespace

// 4. The solve: the coarse level's guide, then the fine step (split when the predictions are
// refreshed after the first iteration or the volume constraint is linearized per iteration).
void LiveRigImpl::solve(const StepBudget& budget, std::uint32_t blending, LiveFrameStats& stats) noexcept {
  const std::size_t markers = rig_->markers.size();
  const HandleTargets targets = frameTargets();
  // Refresh only when some marker is fully measured: that is what moves the body in the first
  // iteration. With every marker predicted or blending (e.g. all returning after a held pose) the
  // predictions would only chase the body they drive.
  std::uint32_t anchored = 0;
  for (std::size_t k = 0; k < markers; ++k) anchored += tracks_[k].state == MarkerTrackState::kMeasured ? 1u : 0u;
  const bool refresh = budget.max_iterations >= 2 && anchored > 0 && (stats.occluded_markers > 0 || blending > 0);
  if (coarse_) {
    // The coarse level on the same frame's marker targets: it sets the fine frame's start.
    for (const auto& [handle, marker] : coarse_marker_handles_)
      coarse_vertex_targets_[static_cast<std::size_t>(handle)] = marker_target_[static_cast<std::size_t>(marker)];
    std::copy(region_targets_.begin(), region_targets_.end(), coarse_region_targets_.begin());
    HandleTargets coarse_targets;
    coarse_targets.vertex_positions = coarse_vertex_targets_;
    coarse_targets.region_transforms = coarse_region_targets_;
    coarse_targets.point_positions = coarse_point_targets_;
    const StepStats cs = coarse_->guide(coarse_targets);
    stats.coarse_ns = cs.total_ns;
  }
  // A frame without the volume constraint yet (the first, or the first after a reset) runs its
  // first iteration free and linearizes the constraint before each further one, at the pose
  // reached (docs/fidelity.md: set only after the frame, or at rest, it is far off for a first
  // pose far from rest).
  const bool cold_constraint = volume_constraint_ && !deformer_.hasLinearConstraint() && budget.max_iterations >= 2;
  // The iterations after publishing (prepareNextFrame) continue this frame.
  const bool continued_after_publish = options_.solver.after_publish_iterations > 0;
  if (!refresh && !cold_constraint) {
    StepBudget whole = budget;
    whole.continued_after = continued_after_publish;
    stats.step = deformer_.step(targets, whole);
  } else {
    // One iteration with the predictions from the last pose, then the rest with predictions from
    // the pose that iteration gave (the measured markers have moved the body by then). On a cold
    // frame the volume constraint is linearized again before each further iteration.
    StepBudget first = budget;
    first.max_iterations = 1;
    first.continued_after = budget.max_iterations > 1 || continued_after_publish;
    stats.step = deformer_.step(targets, first);
    int left = budget.max_iterations - 1;
    if (std::chrono::steady_clock::now() >= budget.deadline) stats.step.flags |= kStepDeadlineHit;
    if (refresh && left > 0 && !(stats.step.flags & kStepDeadlineHit)) {
      refreshPredictions();
      updateTargets();
    }
    while (left > 0 && !(stats.step.flags & kStepDeadlineHit)) {
      if (cold_constraint) {
        transferPose(constraint_scratch_.data());
        linearizeVolumeConstraint(constraint_scratch_.data());
      }
      StepBudget rest = budget;
      rest.max_iterations = cold_constraint ? 1 : left;
      rest.continues_frame = true;
      rest.continued_after = rest.max_iterations < left || continued_after_publish;
      const StepStats more = deformer_.step(targets, rest);
      addStep(stats.step, more);
      if (!cold_constraint || more.iterations <= 0) break;  // one step for the rest, as asked
      left -= more.iterations;
      if (left > 0 && std::chrono::steady_clock::now() >= budget.deadline) stats.step.flags |= kStepDeadlineHit;
    }
  }
  stats.step.total_ns += stats.coarse_ns;
  stepped_ = true;
  if (stats.step.flags & kStepDeadlineHit) stats.flags |= kLiveDeadlineHit;
  if (stats.step.flags & (kStepTargetsRejected | kStepTargetsWrongSize)) stats.flags |= kLiveTargetsRejected;
}

// 5. Pose transfer into the caller's buffer, and its bound: never publish a non-finite or
// implausible value (the pose must lie near where most of this frame's markers are; without
// markers, its handles' targets). A rejected pose writes the last one again and restarts the solver.
void LiveRigImpl::transferAndBound(std::uint32_t measured, float* positions, float* normals, LiveFrameStats& stats) noexcept {
  const std::size_t markers = rig_->markers.size();
  const std::int64_t t0 = monotonicNowNs();
  const std::size_t n = rest_positions_.size();
  transferPose(positions);
  pose_bound_.beginTargets();
  if (markers > 0) {
    for (const Eigen::Vector3d& p : marker_target_) pose_bound_.addTarget(p);
  } else {
    for (const Eigen::Vector3d& p : vertex_targets_) pose_bound_.addTarget(p);
    for (const Eigen::Vector3d& p : point_targets_) pose_bound_.addTarget(p);
    for (std::size_t r = 0; r < region_targets_.size(); ++r)
      pose_bound_.addTarget(region_targets_[r].rotation * region_centroid_[r] + region_targets_[r].translation);
  }
  pose_bound_.endTargets();
  if (pose_bound_.accepts(positions, n)) {
    std::memcpy(last_positions_.data(), positions, n * sizeof(float));
    if (measured > 0) {
      // Predictions from this pose may judge the samples of returning markers (plausibleSample).
      body_valid_ = true;
      body_ns_ = sample_ns_;
    }
    // The constraint linearized at this pose, then the after-publish iterations: prepareNextFrame().
    next_frame_pending_ = volume_constraint_ != nullptr || options_.solver.after_publish_iterations > 0;
    if (options_.normals) {
      vertexNormals(positions, fineTriangles(), normal_sum_, last_normals_.data(), last_normals_.data());
      if (normals != nullptr) std::memcpy(normals, last_normals_.data(), n * sizeof(float));
    }
  } else {
    stats.flags |= kLivePoseRejected;
    writeLastPose(positions, normals);
    next_frame_pending_ = false;
    deformer_.reset();
    predictor_.reset();
    if (coarse_) coarse_->reset();
    body_valid_ = false;  // the predictions start again from rest: they judge no sample until a pose is accepted
  }
  stats.pose_transfer_ns = monotonicNowNs() - t0;
}

std::int64_t LiveRigImpl::prepareNextFrame(std::chrono::steady_clock::time_point deadline) noexcept {
  if (!next_frame_pending_) return 0;
  next_frame_pending_ = false;
  const std::int64_t t0 = monotonicNowNs();
  if (volume_constraint_) {
    // The next frame keeps the volume: g . x = V_rest - V(x0) + g . x0 at the published pose x0
    // (last_positions_ = B x0, x0 the deformer's positions: neither has changed since), with g
    // linearized again every volume_constraint_refresh_frames frames (a stale g still keeps the
    // measured volume; it only steers less well).
    if (!deformer_.hasLinearConstraint() || ++frames_since_linearized_ >= options_.solver.volume_constraint_refresh_frames) {
      linearizeVolumeConstraint(last_positions_.data());
    } else {
      deformer_.setLinearConstraintValue(volume_constraint_->value(deformer_.positions(), last_positions_.data(), constraint_gradient_));
    }
  }
  if (options_.solver.after_publish_iterations > 0 && std::chrono::steady_clock::now() < deadline) {
    // More iterations on the published frame's own targets (under the constraint just set): the
    // next frame starts nearer this frame's converged pose. Not published: the next frame's step
    // starts from here, and a held frame republishes last_positions_.
    StepBudget more;
    more.max_iterations = options_.solver.after_publish_iterations;
    more.deadline = deadline;
    more.continues_frame = true;
    (void)deformer_.step(frameTargets(), more);
  }
  return std::max<std::int64_t>(1, monotonicNowNs() - t0);
}

HandleTargets LiveRigImpl::frameTargets() const noexcept {
  HandleTargets targets;
  targets.vertex_positions = vertex_targets_;
  targets.region_transforms = region_targets_;
  targets.point_positions = point_targets_;
  return targets;
}

void LiveRigImpl::linearizeVolumeConstraint(const float* fine) noexcept {
  const double c = volume_constraint_->linearize(deformer_.positions(), fine, constraint_gradient_);
  // z = L^-1 g solved again every kConstraintDirectionFrames linearizations (the step carries the
  // multiplier in its right-hand side, so a kept z only steers what is left of it:
  // Deformer::setLinearConstraint), or when the kept z no longer fits the new g.
  const bool keep = ++directions_kept_ < kConstraintDirectionFrames;
  if (!keep || !deformer_.setLinearConstraint(constraint_gradient_, c, ConstraintDirection::kKeep)) {
    deformer_.setLinearConstraint(constraint_gradient_, c, ConstraintDirection::kSolve);
    directions_kept_ = 0;
  }
  frames_since_linearized_ = 0;
}

void LiveRigImpl::transferPose(float* positions) const noexcept {
  if (split_ && blocked_b_.rows > 0) {
    split_->apply(deformer_.paddedFloatPositions().data(), positions);
  } else if (split_) {
    split_->apply(deformer_.paddedPositions().data(), positions);
  } else if (blocked_b_.rows > 0) {
    applyPoseTransferBlocked(blocked_b_.view(), deformer_.paddedFloatPositions().data(), positions);
  } else {
    applyPoseTransferPadded(rig_->pose_transfer.view(), deformer_.paddedPositions().data(), positions);
  }
}

std::size_t LiveRigImpl::frameWorkingSet(std::span<std::span<const std::byte>> out) const noexcept {
  std::size_t n = deformer_.frameWorkingSet(out);
  if (coarse_) n += coarse_->deformer().frameWorkingSet(out.subspan(std::min(n, out.size())));
  if (blocked_b_.rows > 0) {
    n = appendWorkingSet(out, n, blocked_b_.block_offsets);
    n = appendWorkingSet(out, n, blocked_b_.columns);
    n = appendWorkingSet(out, n, blocked_b_.weights);
    n = appendWorkingSet(out, n, blocked_b_.lane_rows);
  } else {
    n = appendWorkingSet(out, n, rig_->pose_transfer.row_offsets);
    n = appendWorkingSet(out, n, rig_->pose_transfer.columns);
    n = appendWorkingSet(out, n, rig_->pose_transfer.weights);
  }
  n = appendWorkingSet(out, n, vertex_targets_);
  return appendWorkingSet(out, n, last_positions_);
}

bool LiveRigImpl::plausibleSample(std::size_t k, const Eigen::Vector3d& x) const noexcept {
  if (!(max_speed_ > 0.0)) return true;
  // The marker's own last accepted sample, while it is recent: no marker moves faster than v.
  if (has_accepted_[k]) {
    const std::int64_t since_ns = sample_ns_ - accepted_ns_[k];
    if (since_ns <= own_window_ns_) {
      const double bound = jump_floor_ + max_speed_ * 1e-9 * static_cast<double>(since_ns);
      return (x - accepted_position_[k]).squaredNorm() <= bound * bound;
    }
  }
  // Else where the body has it (its prediction from the last pose), when a pose solved from
  // accepted samples exists: a marker on the body is within the rig's size of it, plus what the
  // body may have moved since that pose. Before any such pose nothing judges a sample.
  if (!body_valid_) return true;
  const double bound = prediction_bound_ + max_speed_ * 1e-9 * static_cast<double>(sample_ns_ - body_ns_);
  return (x - prediction_[k]).squaredNorm() <= bound * bound;
}

double LiveRigImpl::dropoutWeight(const Track& track) const noexcept {
  return 1.0 - blendWeight(now_ns_ - track.dropout_ns);
}

void LiveRigImpl::refreshPredictions() noexcept {
  // A marker measured now that was measured (settled) before needs no prediction: its target is
  // the measurement. Every other one does (predicted, blending, or dropping out / returning now).
  for (std::size_t k = 0; k < skip_prediction_.size(); ++k)
    skip_prediction_[k] = !options_.predict_all_markers && measured_[k] && tracks_[k].state == MarkerTrackState::kMeasured ? 1 : 0;
  const bool finite = predictor_.predict(deformer_.positions(), prediction_, skip_prediction_);
  for (std::size_t k = 0; k < prediction_.size(); ++k) {
    if (skip_prediction_[k]) continue;
    rotation_[k] = predictor_.anchorRotation(static_cast<std::int32_t>(k));
    // A non-finite pose (should not happen): such a marker keeps its previous prediction.
    if (!finite && !prediction_[k].allFinite()) prediction_[k] = previous_prediction_[k];
  }
}

std::uint32_t LiveRigImpl::updateTargets() noexcept {
  std::uint32_t blending = 0;
  for (std::size_t k = 0; k < tracks_.size(); ++k) {
    const Track& track = tracks_[k];
    const Eigen::Vector3d& p = prediction_[k];
    Eigen::Vector3d target;
    switch (track.state) {
      case MarkerTrackState::kMeasured:
        target = measurement_[k];
        break;
      case MarkerTrackState::kReturning: {
        const Eigen::Vector3d predicted = p + dropoutWeight(track) * (rotation_[k] * track.offset);
        target = predicted + blendWeight(now_ns_ - track.return_ns) * (measurement_[k] - predicted);
        ++blending;
        break;
      }
      case MarkerTrackState::kPredicted:
      default: {
        const double fade = dropoutWeight(track);
        target = p + fade * (rotation_[k] * track.offset);
        if (fade > 0.0 && !track.offset.isZero(0.0)) ++blending;
        break;
      }
    }
    marker_target_[k] = target;
    vertex_targets_[static_cast<std::size_t>(rig_->markers[k].vertex_handle)] = target;
  }
  // Regions driven by marker clusters: the best-fit rigid transform from the markers' rest
  // positions to their targets (tetrig/rig_file.hpp, RigMarkerRegion).
  for (const RigMarkerRegion& mr : rig_->marker_regions) {
    const auto marker = [&](std::size_t i) { return static_cast<std::size_t>(mr.markers[i]); };
    const RigidFit fit = bestRigidFit(
        mr.markers.size(), [&](std::size_t i) -> const Eigen::Vector3d& { return rig_->markers[marker(i)].rest_position; },
        [&](std::size_t i) -> const Eigen::Vector3d& { return marker_target_[marker(i)]; });
    RigidTransform& t = region_targets_[static_cast<std::size_t>(mr.region_handle)];
    t.rotation = fit.rotation;
    t.translation = fit.translation;
  }
  return blending;
}

void LiveRigImpl::writeLastPose(float* positions, float* normals) const noexcept {
  if (positions != nullptr) std::memcpy(positions, last_positions_.data(), last_positions_.size() * sizeof(float));
  if (normals != nullptr && options_.normals) std::memcpy(normals, last_normals_.data(), last_normals_.size() * sizeof(float));
}

// LiveRig: the public face, each member forwarding to its LiveRigImpl (one call, no other work).
LiveRig::LiveRig(const Rig& rig, const LiveRigOptions& options, const Rig* coarse_rig)
    : impl_(std::make_unique<LiveRigImpl>(rig, options, coarse_rig)) {}
LiveRig::~LiveRig() = default;
LiveRig::LiveRig(LiveRig&&) noexcept = default;
LiveRig& LiveRig::operator=(LiveRig&&) noexcept = default;
MarkerBindingReport LiveRig::bindLabels(std::span<const std::string> labels_by_id, std::string_view subject) {
  return impl_->bindLabels(labels_by_id, subject);
}
LiveFrameStats LiveRig::processFrame(const MarkerFrame& frame, const StepBudget& budget, float* positions, float* normals) noexcept {
  return impl_->processFrame(frame, budget, positions, normals);
}
std::int64_t LiveRig::prepareNextFrame(std::chrono::steady_clock::time_point deadline) noexcept {
  return impl_->prepareNextFrame(deadline);
}
void LiveRig::writeLastPose(float* positions, float* normals) const noexcept { impl_->writeLastPose(positions, normals); }
std::int32_t LiveRig::fineVertexCount() const noexcept { return impl_->fineVertexCount(); }
std::span<const std::int32_t> LiveRig::fineTriangles() const noexcept { return impl_->fineTriangles(); }
std::span<const float> LiveRig::restPositions() const noexcept { return impl_->restPositions(); }
std::span<const float> LiveRig::restNormals() const noexcept { return impl_->restNormals(); }
const Rig& LiveRig::rig() const noexcept { return impl_->rig(); }
const Deformer& LiveRig::deformer() const noexcept { return impl_->deformer(); }
std::size_t LiveRig::frameWorkingSet(std::span<std::span<const std::byte>> out) const noexcept { return impl_->frameWorkingSet(out); }
const CoarseLevel* LiveRig::coarseLevel() const noexcept { return impl_->coarseLevel(); }
const LiveRigOptions& LiveRig::options() const noexcept { return impl_->options(); }
bool LiveRig::volumeNotKept() const noexcept { return impl_->volumeNotKept(); }
std::int64_t LiveRig::poseTransferBytes() const noexcept { return impl_->poseTransferBytes(); }
void LiveRig::setRegionTarget(std::int32_t region, const RigidTransform& target) noexcept { impl_->setRegionTarget(region, target); }
std::span<const RigidTransform> LiveRig::regionTargets() const noexcept { return impl_->regionTargets(); }
std::span<const Eigen::Vector3d> LiveRig::vertexTargets() const noexcept { return impl_->vertexTargets(); }
std::span<const Eigen::Vector3d> LiveRig::pointTargets() const noexcept { return impl_->pointTargets(); }
std::span<const Eigen::Vector3d> LiveRig::markerTargets() const noexcept { return impl_->markerTargets(); }
std::span<const Eigen::Vector3d> LiveRig::markerPredictions() const noexcept { return impl_->markerPredictions(); }
std::span<const std::uint8_t> LiveRig::markerMeasured() const noexcept { return impl_->markerMeasured(); }
std::span<const std::uint8_t> LiveRig::markerRejected() const noexcept { return impl_->markerRejected(); }
std::span<const Eigen::Quaterniond> LiveRig::markerAnchorRotations() const noexcept { return impl_->markerAnchorRotations(); }
MarkerTrackState LiveRig::markerState(std::int32_t marker) const noexcept { return impl_->markerState(marker); }
std::int32_t LiveRig::markerOfId(std::uint16_t id) const noexcept { return impl_->markerOfId(id); }

}  // namespace tetrig
