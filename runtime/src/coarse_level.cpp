// The coarse level (coarse_level.hpp has the method).
#include "tetrig/coarse_level.hpp"

#include "tetrig/clock.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace tetrig {

namespace {

std::vector<Eigen::Vector3d> restCentroids(const TetMesh& mesh) {
  std::vector<Eigen::Vector3d> c(static_cast<std::size_t>(mesh.tetCount()));
  for (std::int32_t t = 0; t < mesh.tetCount(); ++t) {
    Eigen::Vector3d s = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k) s += mesh.vertices.row(mesh.tets(t, k)).transpose();
    c[static_cast<std::size_t>(t)] = 0.25 * s;
  }
  return c;
}

}  // namespace

CoarseLevel::CoarseLevel(const TetMesh& fine_mesh, Deformer& fine, const TetMesh& coarse_mesh,
                         const DeformerSetup& coarse_setup, const CoarseLevelOptions& options)
    : options_(options), fine_(fine), coarse_(coarse_mesh, coarse_setup) {
  if (options_.iterations < 1) throw std::invalid_argument("coarse level: iterations must be at least 1");
  if (coarse_mesh.tetCount() == 0 || fine_mesh.tetCount() == 0) throw std::invalid_argument("coarse level: empty tet mesh");
  // Nearest rest centroid, brute force: load time, O(#fine tets x #coarse tets) (the SMPL rig and a
  // 150-vertex coarse level: 8164 x 388, 3.2 M distances).
  const std::vector<Eigen::Vector3d> fine_c = restCentroids(fine_mesh);
  const std::vector<Eigen::Vector3d> coarse_c = restCentroids(coarse_mesh);
  coarse_of_fine_.assign(fine_c.size(), 0);
  for (std::size_t f = 0; f < fine_c.size(); ++f) {
    double best = std::numeric_limits<double>::infinity();
    for (std::size_t c = 0; c < coarse_c.size(); ++c) {
      const double d = (fine_c[f] - coarse_c[c]).squaredNorm();
      if (d < best) {
        best = d;
        coarse_of_fine_[f] = static_cast<std::int32_t>(c);
      }
    }
  }
  if (!fine.setFrameGuideSources(coarse_of_fine_, coarse_mesh.tetCount())) {
    throw std::invalid_argument("coarse level: the fine deformer takes no frame guide (DeformerOptions::frame_guide) or has " +
                                std::to_string(fine.tetCount()) + " tets, not the fine mesh's " +
                                std::to_string(fine_mesh.tetCount()));
  }
  previous_.assign(4 * coarse_c.size(), 0.0f);
  now_.assign(4 * coarse_c.size(), 0.0f);
  change_.assign(4 * coarse_c.size(), 0.0f);
  reset();
}

void CoarseLevel::reset() noexcept {
  coarse_.reset();
  for (std::size_t c = 0; c < previous_.size(); c += 4) {
    previous_[c] = 1.0f;
    previous_[c + 1] = previous_[c + 2] = previous_[c + 3] = 0.0f;
  }
}

StepStats CoarseLevel::guide(const HandleTargets& coarse_targets) noexcept {
  const std::int64_t t0 = monotonicNowNs();
  StepStats stats = coarse_.step(coarse_targets, StepBudget{options_.iterations});
  // Q_c = R_c,n R_c,n-1^-1 per coarse tet (R^-1 = conj R), in the hemisphere of the identity and
  // normalised, in float (the guide's own precision); R_c,n-1 <- R_c,n.
  coarse_.rotations(now_);
  for (std::size_t i = 0; i < now_.size(); i += 4) {
    const float* n = &now_[i];
    const float* p = &previous_[i];
    const float q[4] = {n[0] * p[0] + n[1] * p[1] + n[2] * p[2] + n[3] * p[3],  //
                  -n[0] * p[1] + n[1] * p[0] - n[2] * p[3] + n[3] * p[2],
                  -n[0] * p[2] + n[1] * p[3] + n[2] * p[0] - n[3] * p[1],
                  -n[0] * p[3] - n[1] * p[2] + n[2] * p[1] + n[3] * p[0]};
    const float scale = (q[0] < 0.0f ? -1.0f : 1.0f) / std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (std::size_t c = 0; c < 4; ++c) change_[i + c] = q[c] * scale;
  }
  std::copy(now_.begin(), now_.end(), previous_.begin());
  fine_.setFrameGuide(change_);  // each fine tet takes its coarse tet's row
  stats.total_ns = monotonicNowNs() - t0;  // the coarse step and the guide made from it
  return stats;
}

}  // namespace tetrig
