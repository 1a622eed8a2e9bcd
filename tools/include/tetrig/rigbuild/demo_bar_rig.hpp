// The project's own demo rig (tetrig demo, the frame-loop and live-path tests): the bar of
// assets/bar_4x4x33 as body and fine mesh (its boundary surface, pose transfer weights of section
// 2.4), 16 markers on four rings just outside its side faces ("BAR0L", "BAR0R", "BAR0F", "BAR0B",
// ... "BAR3B"), bound by invisible tets of stiffness 0.1 (paper section 3.2). Device millimetres map
// to bar units by 0.1 (the bar is 4 x 4 x 33 units: a 40 x 40 x 330 mm bar), axes unchanged.
// Offline, any thread, allocates, throws on failure.
#pragma once

#include "tetrig/rig_file.hpp"
#include "tetrig/tet_mesh.hpp"

namespace tetrig::rigbuild {

Rig makeDemoBarRig(const TetMesh& bar);

}  // namespace tetrig::rigbuild
