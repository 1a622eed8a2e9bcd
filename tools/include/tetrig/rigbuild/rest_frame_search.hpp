// `--frame auto`: which frame of a clip shows the markers in the mesh's rest pose? Clips usually
// start in some pose (a T-pose, arms down, mid-motion); binding markers from a frame in another
// pose than the mesh's gives a wrong rig (alignment_checks.hpp). This aligns the markers of many
// frames to the mesh and picks the one that fits best among those that pass the plausibility
// checks:
//   1. usable frames: every selected marker valid;
//   2. screening: at most max_candidates of them, evenly spaced, each aligned automatically
//      (align_markers.hpp, fewer ICP iterations) against an approximate closest-point query
//      (nearest of dense surface samples: the vertices, face centres and a grid on large faces;
//      a nanoflann k-d tree, about 1 us a query against about 50 us for the exact one), then
//      checked (alignment_checks.hpp) with the approximate distances;
//   3. refinement: the frames around the best plausible candidate, at a finer step;
//   4. the winner has the smallest mean marker-to-surface distance among the plausible frames.
// When no frame is plausible the search fails with what the nearest miss got wrong: the clip has
// no frame in the mesh's pose, so the rig has to come from a calibration clip of the same marker
// set, which then plays other clips (or, when no frame reaches a plausible scale, the mesh's unit
// or body is wrong). Checks switched off in the limits let every frame through: the smallest mean
// distance wins. The caller aligns the chosen frame again exactly.
//
// Offline, any thread, allocates, throws RigBuildError.
#pragma once

#include "tetrig/rigbuild/align_markers.hpp"
#include "tetrig/rigbuild/alignment_checks.hpp"
#include "tetrig/rigbuild/surface_mesh.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace tetrig::rigbuild {

// Approximate closest point: the nearest of dense samples of the surface (vertices with
// area-weighted normals, face centres, and for faces with an edge longer than `spacing` a
// barycentric grid of that spacing). Error at most about half the sample spacing.
class SurfaceSamples {
 public:
  // spacing <= 0: 1 % of the bounding-box diagonal.
  explicit SurfaceSamples(const SurfaceMesh& surface, double spacing = 0.0);
  ~SurfaceSamples();
  SurfaceSamples(const SurfaceSamples&) = delete;
  SurfaceSamples& operator=(const SurfaceSamples&) = delete;
  ClosestPoint closest(const Eigen::Vector3d& p) const;
  std::size_t sampleCount() const { return normals_.size(); }

 private:
  struct Tree;
  std::vector<double> xyz_;
  std::vector<Eigen::Vector3d> normals_;
  std::vector<std::int32_t> faces_;
  std::unique_ptr<Tree> tree_;
};

struct RestFrameSearchOptions {
  int max_candidates = 200;      // frames aligned in the screening pass
  int refine_candidates = 12;    // frames around the best one aligned in the refinement pass
  int icp_iterations = 30;       // per heading candidate and for the similarity phase
  std::function<void(double)> progress;  // fraction done, may be empty
};

struct RestFrameCandidate {
  std::int64_t frame = -1;
  double fit_scale = 0, mean_distance = 0, median_distance = 0, max_distance = 0;  // approximate distances
  bool plausible = false;
  int failed_checks = 0;
  std::string failure;           // first failed check ("" when plausible)
};

struct RestFrameSearch {
  std::int64_t frame = -1;                 // the chosen frame
  RestFrameCandidate chosen;               // its screening numbers
  std::int64_t clip_frames = 0, usable_frames = 0, searched = 0, plausible = 0;
  std::int64_t stride = 1;                 // screening step in usable frames
};

// markers_at(frame, out): fills `out` with the selected markers of `frame` in device mm (same
// order and count as `labels`) and returns true, or returns false when one is not valid there.
// `limits` decide plausibility as for a fixed frame; `up_axis` is the mesh's up axis.
RestFrameSearch searchRestFrame(std::int64_t frame_count,
                                const std::function<bool(std::int64_t, std::vector<Eigen::Vector3d>&)>& markers_at,
                                const std::vector<std::string>& labels, const SurfaceMesh& surface, const AlignmentOptions& alignment,
                                const std::string& up_axis, const AlignmentCheckLimits& limits, const RestFrameSearchOptions& options = {});

}  // namespace tetrig::rigbuild
