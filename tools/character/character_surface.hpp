// The default character's skin as tetrig publishes it against its true skin in the same pose
// (docs/fidelity.md, "The default character").
//
// The character's skin is known in every pose: drivers::characterPosedSkinField(), the capsules of
// its skin carried by their bones. A fine vertex x (rig units: the OBJ's metres) is taken to the
// device's millimetres by the assets' own axes (characterDeviceFromObj, the map the OBJ was made
// with, not the rig's fitted alignment: a misfit alignment shows as error) and measured as |f(p)|,
// the posed skin field there (close to the distance from the true skin, in mm; the smooth union
// lowers it a little inside the joints' blends). The rest mesh has its own error, the meshing and
// decimation of the T-pose field (assets/character/character.obj): restSurface() is that floor, the
// same measure on the rig's rest fine vertices in the T-pose.
//
// Offline (tools, benchmarks): allocates; addFrame appends one sample per fine vertex.
#pragma once

#include "tetrig/drivers/character_performance.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/tracking_measure.hpp"

#include <Eigen/Dense>
#include <span>
#include <vector>

namespace tetrig::character {

class CharacterSurfaceMeasure {
 public:
  // `rig`: a rig of the default character (built from assets/character/character.obj).
  explicit CharacterSurfaceMeasure(const Rig& rig);

  // One frame: the fine mesh as published (#fine * 3 floats, rig units) and the character's pose
  // at that frame's time.
  void addFrame(std::span<const float> fine_positions, const drivers::CharacterPose& pose);

  [[nodiscard]] rigbuild::Percentiles all() const;  // |f| over every fine vertex of every frame, mm
  [[nodiscard]] rigbuild::Percentiles restSurface() const { return rest_; }
  [[nodiscard]] std::size_t frames() const { return frames_; }


 private:
  rigbuild::Percentiles rest_;
  std::vector<float> samples_;
  std::size_t frames_ = 0;
};

}  // namespace tetrig::character
