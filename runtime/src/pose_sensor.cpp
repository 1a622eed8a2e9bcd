// Pose sensors driving region handles with a clutch or absolutely (the equations are in
// tetrig/pose_sensor.hpp and docs/live.md, "Pose sensors"; region handles: Stoll et al. 2007,
// section 2.3.1).
#include "tetrig/pose_sensor.hpp"

#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

namespace tetrig {

Eigen::Vector3d regionRestCentroid(const TetMesh& mesh, const RegionHandle& region) {
  if (region.tets.empty()) throw std::invalid_argument("regionRestCentroid: the region has no tets");
  std::vector<std::int32_t> corners;
  corners.reserve(region.tets.size() * 4);
  for (const std::int32_t t : region.tets) {
    if (t < 0 || t >= mesh.tetCount()) {
      throw std::invalid_argument("regionRestCentroid: tet " + std::to_string(t) + " is not in the mesh (" +
                                  std::to_string(mesh.tetCount()) + " tets)");
    }
    for (int k = 0; k < 4; ++k) corners.push_back(mesh.tets(t, k));
  }
  std::sort(corners.begin(), corners.end());
  corners.erase(std::unique(corners.begin(), corners.end()), corners.end());
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const std::int32_t v : corners) sum += mesh.vertices.row(v).transpose();
  return sum / static_cast<double>(corners.size());
}

PoseSensorDriver::PoseSensorDriver(const RigPoseSensor& sensor, const RigAlignment& alignment,
                                   const Eigen::Vector3d& region_rest_centroid)
    : sensor_(sensor), linear_(alignment.linear), translation_(alignment.translation), rest_centroid_(region_rest_centroid) {
  const std::string who = "pose sensor '" + sensor.sensor_label + "'";
  if (!linear_.allFinite() || !translation_.allFinite() || !(std::abs(linear_.determinant()) > 0.0)) {
    throw std::invalid_argument(who + ": the alignment is not finite and invertible");
  }
  if (!rest_centroid_.allFinite()) throw std::invalid_argument(who + ": the region's rest centroid is not finite");
  if (!(sensor.translation_scale > 0.0) || !std::isfinite(sensor.translation_scale)) {
    throw std::invalid_argument(who + ": translation_scale must be finite and positive");
  }
  if (sensor.mode != PoseSensorMode::kClutch && sensor.mode != PoseSensorMode::kAbsolute) {
    throw std::invalid_argument(who + ": unknown mode");
  }
  if (sensor.mode == PoseSensorMode::kClutch && sensor.clutch_buttons == 0) {
    throw std::invalid_argument(who + ": clutch mode needs at least one clutch button bit");
  }
  // Q = U V^T, the orthogonal polar factor of A (= A / s for a similarity A = s Q); rotations are
  // conjugated by P = det(Q) Q, a proper rotation with P R P^T = Q R Q^T.
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(linear_, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d q = svd.matrixU() * svd.matrixV().transpose();
  if (q.determinant() < 0.0) q = -q;
  axes_ = Eigen::Quaterniond(q).normalized();
}

void PoseSensorDriver::update(const Marker* marker, RigidTransform& target) noexcept {
  if (marker == nullptr || marker->valid == 0 || marker->has_orientation == 0) return;
  const Eigen::Vector3d p_mm(marker->position_mm[0], marker->position_mm[1], marker->position_mm[2]);
  Eigen::Quaterniond q(marker->orientation[0], marker->orientation[1], marker->orientation[2], marker->orientation[3]);
  const double length2 = q.squaredNorm();
  // Comparisons are false for NaN: a non-finite quaternion is refused here too.
  if (!p_mm.allFinite() || !(length2 > 0.25 && length2 < 4.0)) return;
  q.coeffs() /= std::sqrt(length2);
  const Eigen::Quaterniond r_c = axes_ * q * axes_.conjugate();
  const Eigen::Vector3d p_c = linear_ * p_mm + translation_;

  if (sensor_.mode == PoseSensorMode::kClutch) {
    if ((marker->buttons & sensor_.clutch_buttons) == 0) {
      engaged_ = false;  // released (or never pressed): the region stays where it is
      return;
    }
    if (!engaged_) {
      // Press: anchor on the controller and on the region as it is now; the target is unchanged.
      engaged_ = true;
      anchor_controller_rotation_ = r_c;
      anchor_controller_position_ = p_c;
      const double n2 = target.rotation.squaredNorm();
      anchor_rotation_ = std::isfinite(n2) && n2 > 0.0 ? target.rotation.normalized() : Eigen::Quaterniond::Identity();
      anchor_translation_ = target.translation;
      anchor_centroid_ = anchor_rotation_ * rest_centroid_ + anchor_translation_;
      return;
    }
  } else if (!engaged_) {
    // Absolute: the first valid sample anchors, and the region starts at rest.
    engaged_ = true;
    anchor_controller_rotation_ = r_c;
    anchor_controller_position_ = p_c;
    anchor_rotation_ = Eigen::Quaterniond::Identity();
    anchor_translation_ = Eigen::Vector3d::Zero();
    anchor_centroid_ = rest_centroid_;
    target.rotation = Eigen::Quaterniond::Identity();
    target.translation = Eigen::Vector3d::Zero();
    return;
  }

  const Eigen::Quaterniond d_r = r_c * anchor_controller_rotation_.conjugate();
  Eigen::Quaterniond rotation = (d_r * anchor_rotation_).normalized();
  if (rotation.dot(target.rotation) < 0.0) rotation.coeffs() = -rotation.coeffs();
  target.rotation = rotation;
  target.translation = d_r * (anchor_translation_ - anchor_centroid_) + anchor_centroid_ +
                       sensor_.translation_scale * (p_c - anchor_controller_position_);
}

}  // namespace tetrig
