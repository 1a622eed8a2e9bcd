// A short clip for the small block rig (small_rig.hpp): its five markers moving for a few frames
// (device mm, y up, 100 Hz) - TOP rises 3 mm per frame, RIGHT moves out 2 mm per frame and is
// occluded in frames 4..7, FRONT sways. Used by the export and Blender tests.
#pragma once

#include "small_rig.hpp"

#include <cmath>
#include <cstdint>
#include <vector>

namespace tetrig::test {

inline constexpr float kMovingClipRate = 100.0f;

// `frames` frames; with all_invalid_after_8 every marker is invalid from frame 8 on.
inline std::vector<std::uint8_t> movingClip(std::size_t frames = 12, bool all_invalid_after_8 = false) {
  TestC3DSpec spec;
  spec.floating = true;
  spec.scale = 1.0f;
  spec.rate = kMovingClipRate;
  spec.frames = frames;
  spec.labels = {"TOP", "LEFT", "RIGHT", "FRONT", "BACK"};
  const auto rest = smallMarkerPositionsMm();
  for (std::size_t f = 0; f < frames; ++f) {
    const float t = static_cast<float>(f);
    for (std::size_t m = 0; m < rest.size(); ++m) {
      auto p = rest[m];
      if (m == 0) p[1] += 3.0f * t;
      if (m == 2) p[0] += 2.0f * t;
      if (m == 3) p[0] += 6.0f * std::sin(0.7f * t);
      spec.xyz.push_back(p);
      spec.valid.push_back(!(m == 2 && f >= 4 && f <= 7) && !(all_invalid_after_8 && f >= 8));
    }
  }
  return writeTestC3D(spec);
}

// The small rig and the moving clip written once into a private directory (removed at exit): the
// scene of the export and C API tests. `movingScene()` builds it on first use.
struct MovingScene {
  MovingScene() : rig(buildSmallRig(dir)) {
    rig_path = dir.writeBytes("small.rig", serializeRig(rig));
    clip_path = dir.writeBytes("moving.c3d", movingClip());
  }
  TempDir dir;
  Rig rig;
  std::filesystem::path rig_path, clip_path;
};
inline const MovingScene& movingScene() {
  static const MovingScene s;
  return s;
}

}  // namespace tetrig::test
