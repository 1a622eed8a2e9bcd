// Where an occluded rig marker would be: its rest offset from the body part it is bound to, carried
// by that part's current rigid motion (DESIGN.md 6a; markers as extra tet vertices joined to the
// body by invisible tets, Stoll et al. 2007 section 3.2). The live rig drives an occluded marker's
// handle with this prediction, so occlusion never changes the factor and the marker follows the
// body instead of pulling it toward a stale position (tetrig/live_rig.hpp, docs/live.md "Occlusion").
//
// Anchor of a marker: the body vertices that share a tet with the marker's vertex (for a marker
// bound by invisible tets, the corners of its bound boundary faces), grown by `rings` rings of
// body-tet neighbours (each ring adds the vertices one body tet further; the seeds alone are a
// nearly flat surface patch). Marker vertices are never anchors. Default 3 rings: on the SMPL rig
// of 1541 tet vertices that is 88-288 vertices per marker (median 131), a piece of the limb or
// trunk under the marker; docs/live.md compares 0-3 rings. At load, with p_i the anchor's rest
// positions:
//     c0 = mean_i p_i,   q_i = p_i - c0,   r = m_rest - c0.
// Per frame, from the deformer's current positions x_i (Kabsch: the rotation of the best rigid fit
// of the anchor's rest shape to its current shape, in closed form):
//     c = mean_i x_i,   A = sum_i (x_i - c) q_i^T,
//     R = argmax over rotations of tr(R^T A)   (the orthogonal polar factor of A, det R = +1;
//                                              Horn's quaternion method, tetrig::closestRotation)
//     prediction = c + R r.
// For a rigid motion of the anchor, x_i = Q p_i + t, this is exactly Q m_rest + t. When A is
// degenerate (the anchor collapsed to a point: ||A|| <= 1e-9 sum |q_i|^2) the previous frame's R
// is kept; R starts at the identity.
//
// Threads: the constructor is load time (allocates, throws std::invalid_argument). predict() is
// frame-path code for one thread at a time (it keeps each marker's last rotation): no allocation,
// no lock, no exception, no I/O.
#pragma once

#include "tetrig/tet_mesh.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <span>
#include <vector>

namespace tetrig {

struct MarkerPredictionOptions {
  int rings = 3;  // body-tet rings grown around the seed vertices (0: the seeds alone)
};

class MarkerPredictor {
 public:
  MarkerPredictor() = default;

  // mesh: the rig's tet mesh, body vertices [0, body_vertex_count) first and body tets
  // [0, body_tet_count) first (tetrig::Rig's layout); marker_vertices: the tet vertex of each
  // marker (any vertex of the mesh). Load time: allocates. Throws std::invalid_argument for a
  // count or index out of range, negative rings, or a marker that shares no tet with a body vertex.
  MarkerPredictor(const TetMesh& mesh, std::int32_t body_vertex_count, std::int32_t body_tet_count,
                  std::span<const std::int32_t> marker_vertices, const MarkerPredictionOptions& options = {});

  // predictions[k] = prediction of marker k (rig units) from `positions`, the tet mesh's current
  // vertex positions (#V*3 doubles, mesh order, e.g. Deformer::positions()). Sizes must match
  // (#V*3 and markerCount(); otherwise nothing is written and false is returned). A marker whose
  // anchor has a non-finite position keeps its previous rotation and gets the non-finite
  // prediction; the return value is false then. `skip` (empty, or one flag per marker): markers
  // flagged 1 are not computed (their prediction and rotation keep their previous values).
  // Frame path: no allocation, lock, exception, I/O.
  bool predict(std::span<const double> positions, std::span<Eigen::Vector3d> predictions,
               std::span<const std::uint8_t> skip = {}) noexcept;

  // Every marker's rotation back to the identity (as after construction). No allocation.
  void reset() noexcept;

  std::int32_t markerCount() const noexcept { return static_cast<std::int32_t>(rest_offset_.size()); }
  // The anchor vertices of marker k (sorted ascending) and its last rotation R.
  std::span<const std::int32_t> anchorVertices(std::int32_t marker) const noexcept;
  const Eigen::Quaterniond& anchorRotation(std::int32_t marker) const noexcept { return rotation_[static_cast<std::size_t>(marker)]; }

 private:
  std::int32_t vertex_count_ = 0;
  std::vector<std::int32_t> anchor_start_;       // CSR: marker -> anchor vertices
  std::vector<std::int32_t> anchor_vertex_;
  std::vector<Eigen::Vector3d> anchor_rest_;      // q_i = p_i - c0, one per anchor entry
  std::vector<Eigen::Vector3d> rest_offset_;      // r = m_rest - c0, one per marker
  std::vector<double> degenerate_limit_;          // 1e-9 sum_i |q_i|^2, one per marker
  std::vector<Eigen::Quaterniond> rotation_;      // last R, one per marker
};

}  // namespace tetrig
