// Markers bound by invisible tets (Stoll et al. 2007, section 3.2): each marker becomes an extra
// tet vertex joined to its closest boundary faces by "invisible" tets; it is then driven as a
// vertex handle. For a boundary face (a, b, c) (outward) and marker m the tet is (a, b, c, m),
// positively oriented when m lies outside the face's plane. Faces that would give an inverted or
// degenerate tet (m within min_relative_height * longest face edge of the plane, or behind it)
// are skipped. A marker below the skin (behind every nearby face) is joined with the reversed
// faces (a, c, b, m) instead, which are positive too, and reported.
//
// Offline, any thread, allocates, throws RigBuildError naming a marker that cannot be bound.
#pragma once

#include "tetrig/rigbuild/surface_mesh.hpp"
#include "tetrig/tet_mesh.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <vector>

namespace tetrig::rigbuild {

struct MarkerBindOptions {
  int faces_per_marker = 3;          // invisible tets per marker
  int search_faces = 32;             // nearest boundary faces considered
  double min_relative_height = 0.05; // marker height over the face plane / longest face edge
  // 0: the faces_per_marker nearest qualifying faces (adjacent: a marker far from the skin hangs on
  // needles). > 0: a tripod. The nearest qualifying face comes first. Each further face is the
  // qualifying one whose centroid lies farthest from the faces already taken, among those whose
  // centroid lies within face_spread * d of the marker's closest surface point (d: the marker's
  // distance to the surface; at least the nearest face's longest edge), out of the
  // max(search_faces, 128) nearest; when none is left there, the nearest qualifying face not taken.
  double face_spread = 0.0;
  // > 0: a fan instead of faces (for markers above the skin). The marker joins a fan of tets
  // (c, s_i, s_i+1, m) over surface vertices: c the vertex nearest its closest surface point f,
  // s_i the spokes, one per angular sector of the plane normal to m - f, each the farthest vertex
  // within fan_spread * d of f (d as above) whose vertex normal faces the marker. A fan is well
  // shaped where nearest faces make needles, and spreads its load over fan_spokes + 1 vertices.
  // Fewer than 2 good tets: the marker is bound as with face_spread.
  double fan_spread = 0.0;
  int fan_spokes = 6;
  // > 0: the fan's tets share fan_weight times the weight (stiffness * volume) that the
  // faces_per_marker nearest faces' needles would have (MarkerBindResult::invisible_scale), but
  // never more than the fan's own volume gives; 0: the fan's own volume.
  double fan_weight = 1.0;
};

struct MarkerBinding {
  std::int32_t tet_vertex = -1;
  std::int32_t bound_faces = 0;
  bool below_skin = false;
};

struct MarkerBindResult {
  TetMesh mesh;                          // body vertices, then one vertex per marker; body tets, then invisible tets
  std::vector<MarkerBinding> bindings;   // one per marker
  std::int32_t invisible_tets = 0;
  std::vector<double> invisible_scale;   // one per invisible tet: multiplies the invisible stiffness (1 but for fans)
  std::int32_t below_skin = 0;
};

// body: positively oriented tets. positions/labels: one per marker, rig units.
MarkerBindResult bindMarkers(const TetMesh& body, const std::vector<Eigen::Vector3d>& positions,
                             const std::vector<std::string>& labels, const MarkerBindOptions& options = {});

}  // namespace tetrig::rigbuild
