#include "character/character_surface.hpp"

#include "character/make_character.hpp"

#include <cmath>

namespace tetrig::character {

namespace {

drivers::CharacterVec3 toDevice(const Eigen::Vector3d& rig_point) {
  const Eigen::Vector3d p = characterDeviceFromObj(rig_point);
  return {p.x(), p.y(), p.z()};
}

}  // namespace

CharacterSurfaceMeasure::CharacterSurfaceMeasure(const Rig& rig) {
  std::vector<double> rest;
  rest.reserve(static_cast<std::size_t>(rig.fine_vertices.rows()));
  for (Eigen::Index v = 0; v < rig.fine_vertices.rows(); ++v) {
    rest.push_back(std::abs(drivers::characterSkinField(toDevice(rig.fine_vertices.row(v).transpose()))));
  }
  rest_ = rigbuild::percentilesOf(std::move(rest));
}

void CharacterSurfaceMeasure::addFrame(std::span<const float> fine_positions, const drivers::CharacterPose& pose) {
  for (std::size_t i = 0; i + 2 < fine_positions.size(); i += 3) {
    const Eigen::Vector3d x(fine_positions[i], fine_positions[i + 1], fine_positions[i + 2]);
    samples_.push_back(static_cast<float>(std::abs(drivers::characterPosedSkinField(pose, toDevice(x)))));
  }
  ++frames_;
}

rigbuild::Percentiles CharacterSurfaceMeasure::all() const { return rigbuild::percentilesOf(std::vector<double>(samples_.begin(), samples_.end())); }

}  // namespace tetrig::character
