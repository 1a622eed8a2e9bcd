// Shape quality of a tet mesh, for the rig builder's report (`tetrig build-rig`, `tetrig inspect`)
// and its tests: the radius ratio rho = 3 r / R (inradius over circumradius, normalised so that a
// regular tet has 1 and a flat or needle tet tends to 0) and the dihedral angles. Tets that are
// flat (slivers, rho near 0 with all edges of similar length) or needles (one long edge) invert
// first when the mesh bends: the deformation-survey cylinder's quadric-decimated tet mesh (min
// rho 1e-3) folded 130-185 of its tets at a 120 degree bend (docs/rig-builder.md).
//
// Offline, any thread, allocates (a sort for the median).
#pragma once

#include "tetrig/tet_mesh.hpp"

#include <cstdint>
#include <string>

namespace tetrig::rigbuild {

struct TetQuality {
  std::int32_t tets = 0;              // tets measured
  double min_radius_ratio = 0.0;      // worst tet
  double median_radius_ratio = 0.0;
  std::int32_t below_0_1 = 0;         // tets with rho < 0.1 (slivers and needles)
  double min_dihedral_degrees = 0.0;  // smallest dihedral angle of any tet
  double max_dihedral_degrees = 0.0;  // largest
  std::string summary() const;        // "radius ratio min 0.031 median 0.52 (12 below 0.1), dihedral 2.1-171 degrees"
};

// Radius ratio 3 r / R of one tet (0 for a degenerate tet).
double tetRadiusRatio(const TetMesh& mesh, std::int32_t t);

// Quality over tets [first, first + count) (count < 0: to the end); all tets by default. The
// rig's invisible marker tets (after body_tet_count) are left out by passing the body range.
TetQuality tetQuality(const TetMesh& mesh, std::int32_t first = 0, std::int32_t count = -1);

}  // namespace tetrig::rigbuild
