// tetrig_fidelity: how far the budgeted live result lands from the converged pose, frame by frame,
// on real motion capture (issue #12, docs/fidelity.md).
//
//   tetrig_fidelity --rig RIG --c3d CLIP [--c3d CLIP2 ...] --iterations 1,2,3,5 --reference-every 10 --json FILE
//
// For each clip and each iteration count k, a fresh LiveRig plays every frame of the clip through
// LiveRig::processFrame with StepBudget{k} (no deadline: the result does not depend on the machine),
// exactly as `tetrig run` does (labels bound once, occlusion prediction, warm start from frame to
// frame). On every frame: inverted body tets and the fine mesh's volume against rest. On every
// `reference_every`-th frame, the reference: a second, plain Deformer of the same rig starts from the
// live deformer's rotations after the frame's step (the state the frame ends in) and iterates on the
// same frame's handle targets until the energy stops falling (relative change per 25 iterations below
// --tolerance, at most --max-reference-iterations). Then:
//   error        distance of every body tet vertex, budgeted to converged, in mm: RMS and worst;
//   energy       E(x) = sum_j a_j ||F_j(x) - R_j||_F^2 with R_j = closestRotation(F_j) (exact, in
//                double: Horn's method, det R = +1) and a_j = stiffness_j |vol_j|, over all tets
//                (body and invisible); with --volume-weight w, that of the volume term's deformer:
//                sum_j a_j [(1 - w) ||F_j - R_j||^2 + w ||F_j - T_j||^2] (unitVolumeShift, polar.hpp),
//                and the reference solves with it too; excess = (E(x_budget) - E(x_conv)) / E(x_conv), left out
//                (and counted) for frames whose converged energy is below 1e-6 of the clip's median;
//   inverted     body tets with det F_j <= 0, budgeted (every frame) and converged;
//   volume       the fine mesh's enclosed volume (B x) against its rest volume, budgeted (every frame)
//                and converged.
// The JSON holds "runs": one object per clip and k with the keys docs/fidelity.md lists.
// Mechanism switches (--no-...) turn off the live rig's frame-step aids one by one, for measuring
// what each buys.
#include "tetrig/drivers/c3d_playback.hpp"
#include "tetrig/laplacian.hpp"
#include "tetrig/live_rig.hpp"
#include "tetrig/polar.hpp"
#include "tetrig/pose_transfer.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/rotation_kernel.hpp"
#include "tetrig/tet_mesh.hpp"
#include "tetrig/volume_constraint.hpp"
#include "tetrig/rigbuild/tet_quality.hpp"
#include "tetrig/rigbuild/tracking_measure.hpp"
#include "tetrig/rigbuild/write_file_atomic.hpp"
#include "solver_flags.hpp"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <limits>
#include <map>
#include <memory>
#include <span>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace {

using tetrig::Rig;

using tetrig::rigbuild::Percentiles;
Percentiles percentiles(std::vector<double> v) { return tetrig::rigbuild::percentilesOf(std::move(v)); }

nlohmann::json toJson(const Percentiles& p) {
  return {{"median", p.median}, {"p90", p.p90}, {"p99", p.p99}, {"max", p.max}, {"count", p.count}};
}

// tracking_mm: the whole clip's percentiles, and each marker's under "per_marker" (by label).
nlohmann::json trackingJson(const tetrig::rigbuild::TrackingMeasure& t, const Rig& rig) {
  nlohmann::json j = toJson(t.all());
  nlohmann::json per = nlohmann::json::object();
  for (std::size_t m = 0; m < rig.markers.size(); ++m) per[rig.markers[m].label] = toJson(t.marker(m));
  j["per_marker"] = std::move(per);
  return j;
}

// The exact energy and the inverted body tets of a tet-mesh pose (#V*3 doubles).
struct PoseMeasure {
  double energy = 0.0;
  std::vector<std::pair<std::int32_t, double>> inverted;  // each inverted body tet and its det F
  int invertedBodyTets() const { return static_cast<int>(inverted.size()); }
};

// The rig marker nearest to a rest point (its index in rig.markers), -1 without markers: a body
// vertex's or tet's region.
std::int32_t nearestMarker(const Rig& rig, const Eigen::RowVector3d& p) {
  std::int32_t nearest = -1;
  double best = std::numeric_limits<double>::infinity();
  for (std::size_t m = 0; m < rig.markers.size(); ++m) {
    const double d = (p - rig.tet_mesh.vertices.row(rig.markers[m].tet_vertex)).squaredNorm();
    if (d < best) {
      best = d;
      nearest = static_cast<std::int32_t>(m);
    }
  }
  return nearest;
}

// Where a pose loses volume and inverts tets: its body tets summed by region, a region being the
// rig marker nearest to a tet's rest centroid (the same regions `worst_near` names, for tets).
class RegionTally {
 public:
  explicit RegionTally(const Rig& rig) : rig_(rig), rest_volume_(static_cast<std::size_t>(rig.body_tet_count)) {
    region_.assign(static_cast<std::size_t>(rig.body_tet_count), -1);
    for (std::int32_t t = 0; t < rig.body_tet_count; ++t) {
      rest_volume_[static_cast<std::size_t>(t)] = tetrig::signedVolume(rig.tet_mesh, t);
      body_rest_volume_ += rest_volume_[static_cast<std::size_t>(t)];
      Eigen::RowVector3d c = Eigen::RowVector3d::Zero();
      for (int k = 0; k < 4; ++k) c += 0.25 * rig.tet_mesh.vertices.row(rig.tet_mesh.tets(t, k));
      region_[static_cast<std::size_t>(t)] = nearestMarker(rig, c);
    }
  }

  // x: tet-mesh positions (#V*3 doubles). {"volume_change_near": the `top` regions whose body tets
  // lost the most volume, each {label, change: their volume change over the whole body's rest
  // volume}, most lost first; "inverted_near": {label: inverted body tets}; "inverted_tets": each
  // inverted body tet, {tet, volume_ratio: det F, rest_radius_ratio: 3 r / R at rest, near: its
  // region's label, corners: its four tet vertices}}. Regions are empty without markers.
  nlohmann::json tally(std::span<const double> x, std::size_t top) const {
    std::vector<double> change(rig_.markers.size(), 0.0);
    std::vector<int> inverted(rig_.markers.size(), 0);
    nlohmann::json inverted_tets = nlohmann::json::array();
    for (std::int32_t t = 0; t < rig_.body_tet_count; ++t) {
      const std::int32_t r = region_[static_cast<std::size_t>(t)];
      if (r < 0) continue;
      const auto p = [&](int k) {
        const auto v = 3 * static_cast<std::size_t>(rig_.tet_mesh.tets(t, k));
        return Eigen::Vector3d(x[v], x[v + 1], x[v + 2]);
      };
      const Eigen::Vector3d a = p(0);
      const double volume = (p(1) - a).dot((p(2) - a).cross(p(3) - a)) / 6.0;  // as tetrig::signedVolume
      const double rest = rest_volume_[static_cast<std::size_t>(t)];
      change[static_cast<std::size_t>(r)] += volume - rest;
      if (volume * rest <= 0.0) {
        ++inverted[static_cast<std::size_t>(r)];
        const auto c = rig_.tet_mesh.tets.row(t);
        inverted_tets.push_back({{"tet", t},
                                 {"volume_ratio", volume / rest},
                                 {"rest_radius_ratio", tetrig::rigbuild::tetRadiusRatio(rig_.tet_mesh, t)},
                                 {"near", label(t)},
                                 {"corners", {c[0], c[1], c[2], c[3]}}});
      }
    }
    std::vector<std::size_t> order(change.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return change[a] < change[b]; });
    nlohmann::json lost = nlohmann::json::array();
    for (std::size_t i = 0; i < std::min(top, order.size()) && change[order[i]] < 0.0; ++i)
      lost.push_back({{"label", rig_.markers[order[i]].label}, {"change", change[order[i]] / body_rest_volume_}});
    nlohmann::json inv = nlohmann::json::object();
    for (std::size_t m = 0; m < inverted.size(); ++m)
      if (inverted[m] > 0) inv[rig_.markers[m].label] = inverted[m];
    return {{"volume_change_near", std::move(lost)}, {"inverted_near", std::move(inv)}, {"inverted_tets", std::move(inverted_tets)}};
  }

  // The label of a body tet's region (its rest centroid's nearest marker), "" without markers.
  std::string label(std::int32_t t) const {
    const std::int32_t r = region_[static_cast<std::size_t>(t)];
    return r < 0 ? std::string() : rig_.markers[static_cast<std::size_t>(r)].label;
  }

 private:
  const Rig& rig_;
  std::vector<double> rest_volume_;
  std::vector<std::int32_t> region_;  // per body tet: index into rig.markers, -1 without markers
  double body_rest_volume_ = 0.0;
};

class Measurer {
 public:
  // volume_weight: the energy is that of the volume term's deformer (DeformerOptions::volume_weight,
  // a floor under the rig's per-tet weights: tetrig::tetVolumeWeights),
  // a_j [(1 - w_j) ||F_j - R_j||^2 + w_j ||F_j - T_j||^2], rigid-group tets plain.
  // guard, threshold: the inversion guard's (DeformerOptions::inversion_guard) extra a alpha ||F - R||^2
  // on body tets squashed below the threshold.
  Measurer(const Rig& rig, double volume_weight, double guard, double threshold, bool guard_push_cap)
      : rig_(rig), frames_(tetrig::computeRestFrames(rig.tet_mesh)),
        weights_(tetrig::tetWeights(frames_, rig.setup.stiffness)),
        volume_weight_(volumeWeights(rig, volume_weight)),
        guard_(static_cast<std::size_t>(rig.tet_mesh.tetCount()), 0.0), guard_threshold_(threshold),
        guard_push_cap_(guard_push_cap) {
    for (std::int32_t t = 0; t < rig.body_tet_count; ++t) guard_[static_cast<std::size_t>(t)] = guard;
    for (const auto& group : rig.setup.rigid_groups)
      for (const std::int32_t t : group.tets) guard_[static_cast<std::size_t>(t)] = 0.0;
    fine_rest_volume_ = fineVolume(rig.fine_vertices.data());
  }

  static std::vector<double> volumeWeights(const Rig& rig, double volume_weight) {
    tetrig::DeformerSetup setup = rig.setup;
    setup.options.volume_weight = volume_weight;
    return tetrig::tetVolumeWeights(setup, rig.tet_mesh.tetCount());
  }

  PoseMeasure measure(std::span<const double> x, bool energy) const {
    PoseMeasure m;
    const auto& tets = rig_.tet_mesh.tets;
    for (std::int32_t t = 0; t < rig_.tet_mesh.tetCount(); ++t) {
      const auto c = tets.row(t);
      const auto p = [&x](std::int32_t v) {
        return Eigen::Vector3d(x[3 * static_cast<std::size_t>(v)], x[3 * static_cast<std::size_t>(v) + 1],
                               x[3 * static_cast<std::size_t>(v) + 2]);
      };
      const Eigen::Vector3d p4 = p(c[3]);
      Eigen::Matrix3d e;
      e.col(0) = p(c[0]) - p4;
      e.col(1) = p(c[1]) - p4;
      e.col(2) = p(c[2]) - p4;
      const Eigen::Matrix3d f = e * frames_.edge_inverse[static_cast<std::size_t>(t)];
      const double det = f.determinant();
      if (t < rig_.body_tet_count && det <= 0.0) m.inverted.emplace_back(t, det);
      if (energy) {
        const Eigen::Matrix3d r = tetrig::closestRotation(f).toRotationMatrix();
        const double w = det > 1e-6 ? volume_weight_[static_cast<std::size_t>(t)] : 0.0;  // as the kernel
        const double s = w > 0.0 ? tetrig::unitVolumeShift(f, r) : 0.0;
        const double off = (f - r).norm();
        const double guard =
            tetrig::inversionGuardTerm(guard_[static_cast<std::size_t>(t)], guard_threshold_, det, off, guard_push_cap_).extra;
        m.energy += weights_[static_cast<std::size_t>(t)] * ((1.0 - w) * off * off + guard + 3.0 * w * s * s);
      }
    }
    return m;
  }

  // Enclosed volume of the fine mesh at positions p (#fine*3 floats or doubles, rig units).
  template <class T>
  double fineVolume(const T* p) const {
    return tetrig::enclosedVolume(std::span<const std::int32_t>(rig_.fine_triangles.data(), static_cast<std::size_t>(rig_.fine_triangles.size())), p);
  }
  double fineRestVolume() const { return fine_rest_volume_; }

 private:
  const Rig& rig_;
  tetrig::TetRestFrames frames_;
  std::vector<double> weights_;
  std::vector<double> volume_weight_;  // per tet
  std::vector<double> guard_;          // per tet: the inversion guard's k
  double guard_threshold_ = 0.5;
  bool guard_push_cap_ = true;  // the explicit guard's cap; the implicit guard has none
  double fine_rest_volume_ = 0.0;
};

struct Config {
  std::vector<std::string> clips;
  std::string rig_path;
  std::vector<int> iterations{1, 2, 3, 5};
  int reference_every = 10;
  int max_reference_iterations = 3000;
  double tolerance = 1e-8;
  int first_frame = 0;
  int frame_count = 0;  // 0: to the end
  bool quiet = false;
  tetrig::LiveRigOptions live;  // its solver: the shared flags (tools/solver_flags.hpp); the rest: this tool's experiments
  // --reference-guard-solves: the reference's CG steps per iteration (0 until parsed: then
  // kReferenceGuardSolves, or the live rig's when it takes more).
  int reference_guard_solves = 0;
  const Rig* coarse = nullptr;  // --coarse-rig
};

// The reference's conjugate-gradient steps per iteration of the implicit guard, unless
// --reference-guard-solves says otherwise: each global step of the guarded energy solved further than
// the live rig's one step, so that the reference converges in its iteration cap.
constexpr int kReferenceGuardSolves = 4;

nlohmann::json runOne(const Rig& rig, const Measurer& measurer, const tetrig::drivers::C3DClip& clip,
                      const std::string& clip_name, int k, const Config& cfg) {
  tetrig::drivers::C3DPlaybackOptions options;
  options.pacing = tetrig::drivers::Pacing::kAsFastAsPossible;
  const tetrig::drivers::C3DPlayback playback(clip, options);
  std::vector<std::string> labels(static_cast<std::size_t>(clip.pointCount()));
  for (const int p : playback.selectedPoints()) labels[static_cast<std::size_t>(p)] = clip.labels()[static_cast<std::size_t>(p)];
  tetrig::LiveRig live(rig, cfg.live, cfg.coarse);
  const tetrig::MarkerBindingReport binding = live.bindLabels(labels);
  if (binding.matched == 0) throw std::runtime_error("no rig marker is named in " + clip_name);

  // The reference solver: the rig's own setup without the frame-step aids (the converged pose does
  // not depend on how a frame step gets there), with the live rig's energy (its volume term).
  tetrig::DeformerSetup reference_setup = rig.setup;
  const tetrig::SolverSettings& solver = cfg.live.solver;
  reference_setup.options.volume_weight = solver.volume_weight;  // the same energy as the live rig's
  reference_setup.options.inversion_guard = solver.inversion_guard;
  reference_setup.options.inversion_guard_threshold = solver.inversion_guard_threshold;
  // The same guarded energy; the reference may solve each global step's guarded system further
  // (--reference-guard-solves) than the live rig's frame budget allows.
  reference_setup.options.inversion_guard_solves = cfg.reference_guard_solves;
  reference_setup.guarded_tet_count = rig.body_tet_count;
  // The volume constraint as the live rig keeps it (not on a fine mesh that is not closed).
  const bool keep_volume = solver.volume_constraint && !live.volumeNotKept();
  reference_setup.options.linear_constraint = keep_volume;
  tetrig::Deformer reference(rig.tet_mesh, reference_setup);
  // Keeping the volume (the default), the reference keeps the fine volume too, linearized again every 25
  // iterations (so it converges to the constrained minimum).
  std::unique_ptr<tetrig::FineVolumeConstraint> constraint;
  std::vector<double> constraint_g, constraint_fine;
  if (keep_volume) {
    constraint = std::make_unique<tetrig::FineVolumeConstraint>(
        rig.tet_mesh, rig.body_tet_count,
        std::span<const std::int32_t>(rig.fine_triangles.data(), static_cast<std::size_t>(rig.fine_triangles.size())),
        std::span<const double>(rig.fine_vertices.data(), static_cast<std::size_t>(rig.fine_vertices.size())));
    constraint_g.resize(3 * static_cast<std::size_t>(rig.tet_mesh.vertexCount()));
    constraint_fine.resize(3 * static_cast<std::size_t>(rig.fine_vertices.rows()));
  }
  std::vector<Eigen::Quaterniond> rotations(static_cast<std::size_t>(rig.tet_mesh.tetCount()));

  const double to_mm = 1.0 / rig.alignment.rig_units_per_mm;
  const std::size_t fine_n = static_cast<std::size_t>(live.fineVertexCount()) * 3;
  std::vector<float> fine(fine_n);
  std::vector<double> fine_conv(fine_n);
  const auto b = rig.pose_transfer.view();
  auto frame = std::make_unique<tetrig::MarkerFrame>();

  const std::size_t first = static_cast<std::size_t>(cfg.first_frame);
  const std::size_t end = cfg.frame_count > 0 ? std::min(clip.frameCount(), first + static_cast<std::size_t>(cfg.frame_count))
                                              : clip.frameCount();
  if (first >= end) throw std::runtime_error("--first-frame is past the end of " + clip_name);

  std::vector<double> rms, worst, e_budget, e_conv, volume_budget, volume_conv, ref_iterations;
  std::vector<std::size_t> ref_frame;
  std::vector<std::string> ref_worst_near;
  std::vector<nlohmann::json> ref_regions;  // RegionTally of the budgeted and the converged pose
  const RegionTally regions(rig);
  std::vector<double> ref_region_share;
  // Each body vertex's region: the rig marker nearest to it at rest.
  std::vector<std::int32_t> region(static_cast<std::size_t>(rig.body_vertex_count), -1);
  for (std::int32_t v = 0; v < rig.body_vertex_count; ++v) region[static_cast<std::size_t>(v)] = nearestMarker(rig, rig.tet_mesh.vertices.row(v));
  std::vector<double> region_sum2(rig.markers.size());
  int inverted_budget_max = 0, inverted_conv_max = 0;
  std::size_t inverted_budget_max_frame = 0, inverted_budget_frames = 0;
  std::vector<int> ref_inverted, ref_inverted_conv;
  // Every body tet the budgeted pose inverts in any frame (not only reference frames): its frames,
  // the first and last of them and its lowest det F.
  struct InvertedTet {
    std::size_t frames = 0, first = 0, last = 0;
    double lowest = 0.0;
  };
  std::map<std::int32_t, InvertedTet> inverted_any;
  std::size_t held = 0, predicted = 0, rejected = 0;
  // The skin following the markers: every frame's published pose, and each reference frame's
  // converged one.
  tetrig::rigbuild::TrackingMeasure tracking(rig), tracking_conv(rig);
  std::vector<float> fine_conv_f(fine_n);
  double step_us = 0.0;
  const double rest_volume = measurer.fineRestVolume();
  const auto wall0 = std::chrono::steady_clock::now();
  for (std::size_t f = first; f < end; ++f) {
    playback.fillFrame(f, f, *frame);
    const tetrig::LiveFrameStats s = live.processFrame(*frame, tetrig::StepBudget{k}, fine.data(), nullptr);
    step_us += static_cast<double>(s.step.total_ns) * 1e-3;
    if ((s.flags & tetrig::kLivePoseHeld) != 0) ++held;
    if ((s.flags & tetrig::kLiveMarkersPredicted) != 0) ++predicted;
    if ((s.flags & tetrig::kLivePoseRejected) != 0) ++rejected;  // the live rig reset itself: reported below
    tracking.addFrame(fine, live);
    const std::span<const double> x = live.deformer().positions();
    const bool is_reference = (f - first) % static_cast<std::size_t>(cfg.reference_every) == 0;
    const PoseMeasure mb = measurer.measure(x, is_reference);
    if (mb.invertedBodyTets() > inverted_budget_max) {
      inverted_budget_max = mb.invertedBodyTets();
      inverted_budget_max_frame = f;
    }
    if (!mb.inverted.empty()) ++inverted_budget_frames;
    for (const auto& [t, det] : mb.inverted) {
      InvertedTet& it = inverted_any[t];
      if (it.frames++ == 0) {
        it.first = f;
        it.lowest = det;
      }
      it.last = f;
      it.lowest = std::min(it.lowest, det);
    }
    volume_budget.push_back(measurer.fineVolume(fine.data()) / rest_volume - 1.0);
    if (!is_reference) continue;

    // Converged solve of this frame's targets, from the state the budgeted step ended in.
    for (std::int32_t t = 0; t < rig.tet_mesh.tetCount(); ++t) rotations[static_cast<std::size_t>(t)] = live.deformer().rotation(t);
    reference.setRotations(rotations);
    tetrig::HandleTargets targets;
    targets.vertex_positions = live.vertexTargets();
    targets.region_transforms = live.regionTargets();
    targets.point_positions = live.pointTargets();
    double last = std::numeric_limits<double>::infinity();
    int done = 0;
    while (done < cfg.max_reference_iterations) {
      if (constraint) {
        const std::span<const double> at = done == 0 ? x : reference.positions();
        tetrig::applyPoseTransfer(b, at.data(), constraint_fine.data());
        const double c = constraint->linearize(at, constraint_fine.data(), constraint_g);
        if (!reference.setLinearConstraint(constraint_g, c)) throw std::runtime_error("the volume constraint was refused");
      }
      const tetrig::StepStats rs = reference.step(targets, tetrig::StepBudget{25});
      done += rs.iterations;
      if (std::abs(last - rs.energy) <= cfg.tolerance * std::max(rs.energy, 1e-300)) break;
      last = rs.energy;
    }
    ref_iterations.push_back(done);
    const std::span<const double> xc = reference.positions();
    const PoseMeasure mc = measurer.measure(xc, true);
    inverted_conv_max = std::max(inverted_conv_max, mc.invertedBodyTets());
    ref_inverted.push_back(mb.invertedBodyTets());
    ref_inverted_conv.push_back(mc.invertedBodyTets());
    ref_regions.push_back({{"budgeted", regions.tally(x, 3)}, {"converged", regions.tally(xc, 3)}});
    double sum2 = 0.0, w = 0.0;
    std::int32_t worst_v = 0;
    std::fill(region_sum2.begin(), region_sum2.end(), 0.0);
    for (std::int32_t v = 0; v < rig.body_vertex_count; ++v) {
      const std::size_t i = 3 * static_cast<std::size_t>(v);
      const double d2 = (Eigen::Vector3d(x[i], x[i + 1], x[i + 2]) - Eigen::Vector3d(xc[i], xc[i + 1], xc[i + 2])).squaredNorm();
      sum2 += d2;
      if (region[static_cast<std::size_t>(v)] >= 0) region_sum2[static_cast<std::size_t>(region[static_cast<std::size_t>(v)])] += d2;
      if (d2 > w) {
        w = d2;
        worst_v = v;
      }
    }
    if (!rig.markers.empty()) {
      ref_worst_near.push_back(rig.markers[static_cast<std::size_t>(region[static_cast<std::size_t>(worst_v)])].label);
      ref_region_share.push_back(sum2 > 0 ? region_sum2[static_cast<std::size_t>(region[static_cast<std::size_t>(worst_v)])] / sum2 : 0.0);
    } else {
      ref_worst_near.emplace_back();
      ref_region_share.push_back(0.0);
    }
    rms.push_back(to_mm * std::sqrt(sum2 / rig.body_vertex_count));
    worst.push_back(to_mm * std::sqrt(w));
    e_budget.push_back(mb.energy);
    e_conv.push_back(mc.energy);
    tetrig::applyPoseTransfer(b, xc.data(), fine_conv.data());
    std::copy(fine_conv.begin(), fine_conv.end(), fine_conv_f.begin());
    tracking_conv.addFrame(fine_conv_f, live);
    volume_conv.push_back(measurer.fineVolume(fine_conv.data()) / rest_volume - 1.0);
    ref_frame.push_back(f);
    if (!cfg.quiet) {
      const double s_elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
      std::fprintf(stderr, "\r%s k=%d: frame %zu/%zu  rms %.1f mm  worst %.1f mm  (%.0f s)   ", clip_name.c_str(), k, f - first + 1,
                   end - first, rms.back(), worst.back(), s_elapsed);
    }
  }
  if (!cfg.quiet) std::fprintf(stderr, "\n");

  // Energy excess, leaving out frames whose converged energy is negligible.
  std::vector<double> sorted_conv = e_conv;
  std::sort(sorted_conv.begin(), sorted_conv.end());
  const double median_conv = sorted_conv.empty() ? 0.0 : sorted_conv[sorted_conv.size() / 2];
  std::vector<double> excess;
  std::size_t left_out = 0;
  for (std::size_t i = 0; i < e_conv.size(); ++i) {
    if (e_conv[i] < 1e-6 * median_conv) {
      ++left_out;
      continue;
    }
    excess.push_back((e_budget[i] - e_conv[i]) / e_conv[i]);
  }
  // |V/V_rest - 1| per frame: its percentiles, whose max is the largest change.
  const auto volume_percentiles = [](std::vector<double> v) {
    for (double& d : v) d = std::abs(d);
    return percentiles(std::move(v));
  };
  const Percentiles volume = volume_percentiles(volume_budget);
  nlohmann::json run = {
      {"clip", clip_name},
      {"iterations", k},
      {"frames", end - first},
      {"reference_frames", rms.size()},
      {"tracking_mm", trackingJson(tracking, rig)},
      {"tracking_converged_mm", trackingJson(tracking_conv, rig)},
      {"rms_error_mm", toJson(percentiles(rms))},
      {"max_error_mm", toJson(percentiles(worst))},
      {"energy_excess", toJson(percentiles(excess))},
      {"energy_excess_left_out", left_out},
      {"inverted_body_tets_max", inverted_budget_max},
      {"inverted_body_tets_max_frame", inverted_budget_max_frame},
      {"frames_with_inverted_body_tets", inverted_budget_frames},
      {"inverted_body_tets_any_frame", [&] {
         nlohmann::json list = nlohmann::json::array();
         for (const auto& [t, it] : inverted_any)
           list.push_back({{"tet", t}, {"frames", it.frames}, {"first_frame", it.first}, {"last_frame", it.last},
                           {"lowest_volume_ratio", it.lowest}, {"near", regions.label(t)},
                           {"rest_radius_ratio", tetrig::rigbuild::tetRadiusRatio(rig.tet_mesh, t)}});
         return list;
       }()},
      {"inverted_body_tets_converged_max", inverted_conv_max},
      {"volume_change", toJson(volume)},
      {"volume_change_max", volume.max},
      {"volume_change_converged_max", volume_percentiles(volume_conv).max},
      {"reference_iterations", toJson(percentiles(ref_iterations))},
      {"frames_held", held},
      {"frames_with_predicted_markers", predicted},
      {"rejected_poses", rejected},
      {"step_us_mean", step_us / static_cast<double>(end - first)},
      {"markers_matched", binding.matched},
      {"markers_missing", binding.missing},
      {"volume_not_kept", live.volumeNotKept()},
  };
  nlohmann::json per_frame = nlohmann::json::array();
  for (std::size_t i = 0; i < rms.size(); ++i) {
    per_frame.push_back({{"frame", ref_frame[i]}, {"rms_mm", rms[i]}, {"max_mm", worst[i]}, {"energy", e_budget[i]},
                         {"energy_converged", e_conv[i]}, {"reference_iterations", ref_iterations[i]},
                         {"worst_near", ref_worst_near[i]}, {"worst_region_share", ref_region_share[i]},
                         {"inverted_body_tets", ref_inverted[i]}, {"inverted_body_tets_converged", ref_inverted_conv[i]},
                         {"volume_change", volume_budget[ref_frame[i] - first]}, {"volume_change_converged", volume_conv[i]},
                         {"regions", std::move(ref_regions[i])}});
  }
  run["reference"] = std::move(per_frame);
  return run;
}

std::vector<int> parseIterations(const std::string& s) {
  std::vector<int> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) {
    std::size_t used = 0;
    int k = 0;
    try {
      k = std::stoi(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != item.size() || k < 1 || k > 1000) {
      throw std::runtime_error("--iterations: '" + item + "' is not an iteration count in 1..1000 (give e.g. 1,2,3,5)");
    }
    out.push_back(k);
  }
  if (out.empty()) throw std::runtime_error("--iterations is empty (give e.g. 1,2,3,5)");
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Budgeted live result against the converged pose, on a rig and C3D clips (docs/fidelity.md)"};
  Config cfg;
  std::string iterations = "1,2,3,5", json_path;
  app.add_option("--rig", cfg.rig_path, "Rig file (tetrig build-rig)")->required()->check(CLI::ExistingFile);
  app.add_option("--c3d", cfg.clips, "C3D clip(s) of the rig's marker set")->required()->check(CLI::ExistingFile);
  app.add_option("--iterations", iterations, "Iterations per frame, comma-separated (default 1,2,3,5)");
  app.add_option("--reference-every", cfg.reference_every, "Converged reference every Nth frame (default 10)")
      ->check(CLI::Range(1, 1000000));
  app.add_option("--max-reference-iterations", cfg.max_reference_iterations,
                 "Iteration cap of a converged solve (default 3000)")->check(CLI::Range(25, 1000000));
  app.add_option("--tolerance", cfg.tolerance, "Converged: relative energy change per 25 iterations below this (default 1e-8)")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--first-frame", cfg.first_frame, "First clip frame (default 0)")->check(CLI::NonNegativeNumber);
  app.add_option("--frames", cfg.frame_count, "Frames to play (default: to the end)")->check(CLI::NonNegativeNumber);
  app.add_option("--json", json_path, "Write the results here (JSON)");
  app.add_flag("-q,--quiet", cfg.quiet, "No progress line");
  // The flags every tool shares (tools/solver_flags.hpp), then this tool's experiments.
  tetrig::tools::addSolverFlags(app, cfg.live.solver, "Solver (as tetrig run)");
  const char* kExperiments = "Experiments";
  app.add_option("--extrapolate", cfg.live.solver.rotation_extrapolation,
                 "Temporal prediction: alpha of the rotation extrapolation (0: off, as --no-predict; 1: constant velocity, as "
                 "--predict, the default)")
      ->check(CLI::Range(0.0, 1.0))
      ->group(kExperiments);
  app.add_option("--extrapolate-max-deg", cfg.live.solver.rotation_extrapolation_max_deg,
                 "Temporal prediction: cap of a tet's predicted rotation per frame, degrees (default 5)")
      ->check(CLI::Range(0.001, 180.0))
      ->group(kExperiments);
  std::string coarse_path;
  app.add_option("--coarse-rig", coarse_path,
                 "Coarse level: a rig of the same mesh and markers with fewer tet vertices, solved every frame first")
      ->check(CLI::ExistingFile);
  app.add_option("--coarse-iterations", cfg.live.solver.coarse_iterations, "Coarse level: its iterations per frame (default 2)")
      ->check(CLI::PositiveNumber)
      ->group(kExperiments);
  app.add_option("--volume-weight", cfg.live.solver.volume_weight,
                 "Volume term's share w of each tet's energy, live rig and reference alike (docs/deformation.md; default 0)")
      ->check(CLI::Range(0.0, 0.99))
      ->group(kExperiments);
  app.add_flag_callback(
         "--no-untangle", [&cfg] { cfg.live.solver.untangle = false; },
         "Publish each pose as the frame's iterations leave it: no relaxing of nearly inverted body tets' corners")
      ->group(kExperiments);
  app.add_option("--volume-constraint-refresh", cfg.live.solver.volume_constraint_refresh_frames,
                 "Volume constraint: frames between linearizations of its gradient (default 1: every frame)")
      ->check(CLI::Range(1, 1000))
      ->group(kExperiments);
  app.add_option("--reference-guard-solves", cfg.reference_guard_solves,
                 "Implicit inversion guard: the reference's conjugate-gradient steps per iteration (default 4, or the "
                 "live rig's --inversion-guard-solves when more). The same energy, its global steps solved further")
      ->check(CLI::Range(1, 64));
  CLI11_PARSE(app, argc, argv);
  try {
    tetrig::tools::checkSolverSettings(cfg.live.solver);  // the same checks as tetrig run and tetrig export
    const tetrig::SolverSettings& solver = cfg.live.solver;
    if (cfg.reference_guard_solves > 0 && solver.inversion_guard_solves == 0)
      throw std::invalid_argument("--reference-guard-solves needs the implicit inversion guard: give --inversion-guard-solves too");
    if (cfg.reference_guard_solves == 0 && solver.inversion_guard_solves > 0)
      cfg.reference_guard_solves = std::max(kReferenceGuardSolves, solver.inversion_guard_solves);
    const std::vector<int> ks = parseIterations(iterations);
    const Rig rig = tetrig::loadRigFile(cfg.rig_path);
    if (solver.volume_constraint &&
        !tetrig::closedOrientedSurface(std::span<const std::int32_t>(rig.fine_triangles.data(), static_cast<std::size_t>(rig.fine_triangles.size()))))
      std::fprintf(stderr, "tetrig_fidelity: note: the rig's fine mesh is not closed, so its volume is not kept (the volume constraint "
                           "needs a watertight surface)\n");
    Rig coarse_rig;
    if (!coarse_path.empty()) {
      coarse_rig = tetrig::loadRigFile(coarse_path);
      cfg.coarse = &coarse_rig;
    }
    const Measurer measurer(rig, solver.volume_weight, solver.inversion_guard, solver.inversion_guard_threshold,
                            solver.inversion_guard_solves == 0);
    nlohmann::json out = {{"rig", cfg.rig_path},
                          {"tet_vertices", rig.tet_mesh.vertexCount()},
                          {"tets", rig.tet_mesh.tetCount()},
                          {"body_tets", rig.body_tet_count},
                          {"reference_every", cfg.reference_every},
                          {"solver", tetrig::tools::solverJson(solver)},
                          {"reference_guard_solves", cfg.reference_guard_solves},
                          {"runs", nlohmann::json::array()}};
    // The coarse level the live rig will use: --coarse-rig, else the rig's own unless --no-coarse.
    const Rig* coarse = cfg.coarse != nullptr ? cfg.coarse : solver.use_coarse_level ? rig.coarse.get() : nullptr;
    if (coarse != nullptr) {
      out["coarse_rig"] = cfg.coarse != nullptr ? coarse_path : std::string("(the rig's own)");
      out["coarse_tets"] = coarse->tet_mesh.tetCount();
      out["coarse_iterations"] = solver.coarse_iterations;
    }
    for (const std::string& clip_path : cfg.clips) {
      const auto clip = tetrig::drivers::C3DClip::load(clip_path);
      const std::string name = std::filesystem::path(clip_path).filename().string();
      for (const int k : ks) {
        nlohmann::json run = runOne(rig, measurer, clip, name, k, cfg);
        const auto& r = run;
        std::printf("%-32s k=%d  rms mm median %.2f p99 %.2f | worst mm median %.2f p99 %.2f max %.2f | excess median %.4f p99 %.4f | inverted %d at frame %zu, in %zu frames (conv %d) | volume %.4f (conv %.4f)\n",
                    name.c_str(), k, r["rms_error_mm"]["median"].get<double>(), r["rms_error_mm"]["p99"].get<double>(),
                    r["max_error_mm"]["median"].get<double>(), r["max_error_mm"]["p99"].get<double>(),
                    r["max_error_mm"]["max"].get<double>(), r["energy_excess"]["median"].get<double>(),
                    r["energy_excess"]["p99"].get<double>(), r["inverted_body_tets_max"].get<int>(),
                    r["inverted_body_tets_max_frame"].get<std::size_t>(), r["frames_with_inverted_body_tets"].get<std::size_t>(),
                    r["inverted_body_tets_converged_max"].get<int>(), r["volume_change_max"].get<double>(),
                    r["volume_change_converged_max"].get<double>());
        if (const auto rejected = r["rejected_poses"].get<std::size_t>(); rejected > 0)
          std::printf("%-32s k=%d  WARNING: %zu solved poses were rejected as implausible (the live rig published the last pose "
                      "and restarted from rest): these figures do not describe a working chain\n",
                      name.c_str(), k, rejected);
        std::fflush(stdout);
        out["runs"].push_back(std::move(run));
      }
    }
    if (!json_path.empty()) {
      const std::string text = out.dump(1) + "\n";
      tetrig::rigbuild::writeFileAtomically(json_path, std::span(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()));
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tetrig_fidelity: %s\n", e.what());
    return 1;
  }
  return 0;
}
