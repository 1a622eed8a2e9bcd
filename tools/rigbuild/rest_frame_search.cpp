// `--frame auto`: the clip frame that best matches the mesh's rest pose (see rest_frame_search.hpp).
#include "tetrig/rigbuild/rest_frame_search.hpp"
#include "tetrig/rigbuild/format_number.hpp"
#include "xyz_kd_tree.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>

namespace tetrig::rigbuild {
namespace {

constexpr int kMaxGridSteps = 64;             // per face edge
constexpr std::size_t kMaxSamples = 4'000'000;  // about 130 MB with the tree

}  // namespace

struct SurfaceSamples::Tree {
  XyzPointCloud cloud;
  XyzKdTree tree;
  explicit Tree(const std::vector<double>* xyz) : cloud{xyz}, tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10)) {}
};

SurfaceSamples::SurfaceSamples(const SurfaceMesh& surface, double spacing) {
  if (surface.triangleCount() == 0) throw RigBuildError("surface samples: the surface has no triangles");
  const Vertices& v = surface.vertices;
  const Triangles& t = surface.triangles;
  if (!(spacing > 0)) spacing = 0.01 * (v.colwise().maxCoeff() - v.colwise().minCoeff()).norm();
  if (!(spacing > 0)) throw RigBuildError("surface samples: the surface has no extent");
  // Vertices with area-weighted normals.
  std::vector<Eigen::Vector3d> vertex_normal(static_cast<std::size_t>(v.rows()), Eigen::Vector3d::Zero());
  std::vector<Eigen::Vector3d> face_normal(static_cast<std::size_t>(t.rows()));
  for (Eigen::Index f = 0; f < t.rows(); ++f) {
    const Eigen::Vector3d a = v.row(t(f, 0)), b = v.row(t(f, 1)), c = v.row(t(f, 2));
    const Eigen::Vector3d n = (b - a).cross(c - a);  // twice the area
    face_normal[static_cast<std::size_t>(f)] = n.norm() > 0 ? Eigen::Vector3d(n.normalized()) : Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) vertex_normal[static_cast<std::size_t>(t(f, k))] += n;
  }
  auto add = [&](const Eigen::Vector3d& p, const Eigen::Vector3d& n, std::int32_t face) {
    xyz_.insert(xyz_.end(), {p.x(), p.y(), p.z()});
    normals_.push_back(n);
    faces_.push_back(face);
  };
  std::vector<std::int32_t> vertex_face(static_cast<std::size_t>(v.rows()), -1);
  for (Eigen::Index f = 0; f < t.rows(); ++f) {
    for (int k = 0; k < 3; ++k) vertex_face[static_cast<std::size_t>(t(f, k))] = static_cast<std::int32_t>(f);
  }
  for (Eigen::Index i = 0; i < v.rows(); ++i) {
    const std::size_t k = static_cast<std::size_t>(i);
    if (vertex_face[k] < 0) continue;  // on no face
    const Eigen::Vector3d n = vertex_normal[k].norm() > 0 ? Eigen::Vector3d(vertex_normal[k].normalized()) : Eigen::Vector3d::Zero();
    add(v.row(i).transpose(), n, vertex_face[k]);
  }
  // Face centres, and a barycentric grid on faces larger than the spacing.
  for (Eigen::Index f = 0; f < t.rows(); ++f) {
    const Eigen::Vector3d a = v.row(t(f, 0)), b = v.row(t(f, 1)), c = v.row(t(f, 2));
    const Eigen::Vector3d& n = face_normal[static_cast<std::size_t>(f)];
    const std::int32_t face = static_cast<std::int32_t>(f);
    add((a + b + c) / 3.0, n, face);
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const int steps = std::min(kMaxGridSteps, static_cast<int>(std::ceil(longest / spacing)));
    if (steps < 2) continue;
    for (int i = 0; i <= steps; ++i) {
      for (int j = 0; i + j <= steps; ++j) {
        const int k = steps - i - j;
        if ((i == steps) || (j == steps) || (k == steps)) continue;  // the corners are vertex samples
        add((i * a + j * b + k * c) / steps, n, face);
      }
    }
    if (normals_.size() > kMaxSamples) {
      throw RigBuildError("surface samples: more than " + std::to_string(kMaxSamples) + " samples at spacing " + formatNumber("%.3g", spacing));
    }
  }
  tree_ = std::make_unique<Tree>(&xyz_);
  tree_->tree.buildIndex();
}

SurfaceSamples::~SurfaceSamples() = default;

ClosestPoint SurfaceSamples::closest(const Eigen::Vector3d& p) const {
  const double q[3] = {p.x(), p.y(), p.z()};
  std::uint32_t index = 0;
  double d2 = 0;
  nanoflann::KNNResultSet<double, std::uint32_t> result(1);
  result.init(&index, &d2);
  tree_->tree.findNeighbors(result, q, nanoflann::SearchParams(10));
  ClosestPoint c;
  c.point = Eigen::Vector3d(xyz_[3 * index], xyz_[3 * index + 1], xyz_[3 * index + 2]);
  c.normal = normals_[index];
  c.distance = std::sqrt(d2);
  c.face = faces_[index];
  return c;
}

RestFrameSearch searchRestFrame(std::int64_t frame_count,
                                const std::function<bool(std::int64_t, std::vector<Eigen::Vector3d>&)>& markers_at,
                                const std::vector<std::string>& labels, const SurfaceMesh& surface, const AlignmentOptions& alignment,
                                const std::string& up_axis, const AlignmentCheckLimits& limits, const RestFrameSearchOptions& options) {
  RestFrameSearch search;
  search.clip_frames = frame_count;
  if (frame_count <= 0) throw RigBuildError("the clip has no frames to search");
  std::vector<std::int64_t> usable;
  std::vector<Eigen::Vector3d> mm;
  for (std::int64_t f = 0; f < frame_count; ++f) {
    if (markers_at(f, mm)) usable.push_back(f);
  }
  search.usable_frames = static_cast<std::int64_t>(usable.size());
  if (usable.empty()) {
    throw RigBuildError("no frame has every selected marker valid: exclude the markers with gaps (markers.exclude) or choose a frame (--frame N)");
  }
  const SurfaceSamples samples(surface);
  const ClosestPointFunction closest = [&samples](const Eigen::Vector3d& p) { return samples.closest(p); };
  AlignmentOptions fast = alignment;
  fast.icp_iterations = std::min(alignment.icp_iterations, std::max(options.icp_iterations, 1));
  fast.progress = nullptr;

  const std::int64_t max_candidates = std::max(options.max_candidates, 1);
  search.stride = std::max<std::int64_t>(1, (search.usable_frames + max_candidates - 1) / max_candidates);
  std::vector<std::size_t> screen;
  for (std::size_t i = 0; i < usable.size(); i += static_cast<std::size_t>(search.stride)) screen.push_back(i);
  const double total = static_cast<double>(screen.size() + static_cast<std::size_t>(std::max(options.refine_candidates, 0)));

  std::vector<std::uint8_t> done(usable.size(), 0);
  std::optional<RestFrameCandidate> best_plausible, best_any;
  std::size_t best_plausible_index = 0;
  std::int64_t scale_ok = 0;
  auto evaluate = [&](std::size_t i) {
    if (done[i]) return;
    done[i] = 1;
    const std::int64_t frame = usable[i];
    (void)markers_at(frame, mm);
    const AlignmentResult r = alignMarkers(mm, surface, fast, closest);
    const AlignmentCheck check = checkAlignment(surface, up_axis, r.rig_positions, r.distances, labels, r.alignment.fit_scale, limits);
    RestFrameCandidate c;
    c.frame = frame;
    c.fit_scale = r.alignment.fit_scale;
    c.mean_distance = r.mean_distance;
    c.median_distance = r.median_distance;
    c.max_distance = r.max_distance;
    c.plausible = check.ok();
    c.failed_checks = static_cast<int>(check.scale_failures.size() + check.pose_failures.size());
    if (check.scale_failures.empty()) ++scale_ok;
    if (!c.plausible) c.failure = !check.scale_failures.empty() ? check.scale_failures.front() : check.pose_failures.front();
    ++search.searched;
    if (c.plausible) ++search.plausible;
    if (c.plausible && (!best_plausible || c.mean_distance < best_plausible->mean_distance)) {
      best_plausible = c;
      best_plausible_index = i;
    }
    // The nearest miss: fewest failed checks first, then the distance.
    if (!best_any || c.failed_checks < best_any->failed_checks ||
        (c.failed_checks == best_any->failed_checks && c.mean_distance < best_any->mean_distance)) {
      best_any = c;
    }
    if (options.progress) options.progress(std::min(1.0, static_cast<double>(search.searched) / total));
  };
  for (const std::size_t i : screen) evaluate(i);
  if (!best_plausible) {
    const RestFrameCandidate& c = *best_any;
    // No frame even reaches a plausible scale: the mesh's unit or the kind of body is wrong, not the pose.
    const std::string todo = scale_ok == 0 && limits.check_scale
                                 ? "no frame reaches a plausible fit scale: check the mesh's unit (--mesh-unit) and that the markers "
                                   "belong to a body like this mesh"
                                 : "build the rig from a calibration clip of the same marker set in the mesh's pose (e.g. a T-pose "
                                   "trial) and play other clips of that marker set with it";
    throw RigBuildError("no frame fits the mesh's rest pose: searched " + std::to_string(search.searched) + " of " +
                        std::to_string(frame_count) + " frames (one in " + std::to_string(search.stride) +
                        " of those with every marker valid); the nearest miss, frame " + std::to_string(c.frame) + " (fit scale " +
                        formatNumber("%.3g", c.fit_scale) + ", median distance " + formatNumber("%.3g", c.median_distance) + "), fails: " + c.failure +
                        ". To fix: " + todo);
  }
  // Refinement around the best screening result, at a finer step.
  const std::size_t centre = best_plausible_index;
  if (search.stride > 1 && options.refine_candidates > 0) {
    const std::int64_t lo = std::max<std::int64_t>(0, static_cast<std::int64_t>(centre) - search.stride + 1);
    const std::int64_t hi = std::min<std::int64_t>(static_cast<std::int64_t>(usable.size()) - 1, static_cast<std::int64_t>(centre) + search.stride - 1);
    const std::int64_t step = std::max<std::int64_t>(1, (hi - lo + 1 + options.refine_candidates - 1) / options.refine_candidates);
    for (std::int64_t i = lo; i <= hi; i += step) evaluate(static_cast<std::size_t>(i));
  }
  search.chosen = *best_plausible;
  search.frame = search.chosen.frame;
  if (options.progress) options.progress(1.0);
  return search;
}

}  // namespace tetrig::rigbuild
