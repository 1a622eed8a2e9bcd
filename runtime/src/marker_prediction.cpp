// Occlusion prediction of rig markers: the marker's rest offset from its anchor (the body vertices
// it is bound to, plus rings of body-tet neighbours) carried by the anchor's best-fit rigid motion
// (Kabsch; the rotation is the orthogonal polar factor of the cross-covariance, by Horn's
// quaternion method). Equations in tetrig/marker_prediction.hpp and docs/live.md, "Occlusion".
#include "tetrig/marker_prediction.hpp"

#include "tetrig/polar.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace tetrig {

MarkerPredictor::MarkerPredictor(const TetMesh& mesh, std::int32_t body_vertex_count, std::int32_t body_tet_count,
                                 std::span<const std::int32_t> marker_vertices, const MarkerPredictionOptions& options) {
  const std::int32_t nv = mesh.vertexCount();
  const std::int32_t nt = mesh.tetCount();
  if (body_vertex_count < 1 || body_vertex_count > nv) {
    throw std::invalid_argument("marker prediction: body vertex count " + std::to_string(body_vertex_count) + " is not in [1, " +
                                std::to_string(nv) + "]");
  }
  if (body_tet_count < 0 || body_tet_count > nt) {
    throw std::invalid_argument("marker prediction: body tet count " + std::to_string(body_tet_count) + " is not in [0, " +
                                std::to_string(nt) + "]");
  }
  if (options.rings < 0) throw std::invalid_argument("marker prediction: rings must be >= 0");
  vertex_count_ = nv;

  // Vertex -> tets (CSR over all tets).
  std::vector<std::int32_t> tet_start(static_cast<std::size_t>(nv) + 1, 0), vertex_tets;
  for (std::int32_t t = 0; t < nt; ++t) {
    for (int c = 0; c < 4; ++c) {
      const std::int32_t v = mesh.tets(t, c);
      if (v < 0 || v >= nv) throw std::invalid_argument("marker prediction: tet " + std::to_string(t) + " names vertex " + std::to_string(v));
      ++tet_start[static_cast<std::size_t>(v) + 1];
    }
  }
  for (std::int32_t v = 0; v < nv; ++v) tet_start[static_cast<std::size_t>(v) + 1] += tet_start[static_cast<std::size_t>(v)];
  vertex_tets.resize(static_cast<std::size_t>(tet_start.back()));
  {
    std::vector<std::int32_t> fill(tet_start.begin(), tet_start.end() - 1);
    for (std::int32_t t = 0; t < nt; ++t)
      for (int c = 0; c < 4; ++c) vertex_tets[static_cast<std::size_t>(fill[static_cast<std::size_t>(mesh.tets(t, c))]++)] = t;
  }

  std::vector<std::uint8_t> in_anchor(static_cast<std::size_t>(nv), 0);
  std::vector<std::int32_t> anchor, frontier, next;
  anchor_start_.push_back(0);
  for (std::size_t k = 0; k < marker_vertices.size(); ++k) {
    const std::int32_t m = marker_vertices[k];
    if (m < 0 || m >= nv) {
      throw std::invalid_argument("marker prediction: marker " + std::to_string(k) + " names tet vertex " + std::to_string(m) + " of " +
                                  std::to_string(nv));
    }
    // Seeds: body vertices sharing any tet (body or invisible) with the marker vertex.
    anchor.clear();
    for (std::int32_t e = tet_start[static_cast<std::size_t>(m)]; e < tet_start[static_cast<std::size_t>(m) + 1]; ++e) {
      const std::int32_t t = vertex_tets[static_cast<std::size_t>(e)];
      for (int c = 0; c < 4; ++c) {
        const std::int32_t v = mesh.tets(t, c);
        if (v == m || v >= body_vertex_count || in_anchor[static_cast<std::size_t>(v)]) continue;
        in_anchor[static_cast<std::size_t>(v)] = 1;
        anchor.push_back(v);
      }
    }
    if (anchor.empty()) {
      throw std::invalid_argument("marker prediction: marker " + std::to_string(k) + " (tet vertex " + std::to_string(m) +
                                  ") shares no tet with a body vertex");
    }
    // Rings through body tets.
    frontier = anchor;
    for (int ring = 0; ring < options.rings; ++ring) {
      next.clear();
      for (const std::int32_t v : frontier) {
        for (std::int32_t e = tet_start[static_cast<std::size_t>(v)]; e < tet_start[static_cast<std::size_t>(v) + 1]; ++e) {
          const std::int32_t t = vertex_tets[static_cast<std::size_t>(e)];
          if (t >= body_tet_count) continue;
          for (int c = 0; c < 4; ++c) {
            const std::int32_t w = mesh.tets(t, c);
            if (w == m || w >= body_vertex_count || in_anchor[static_cast<std::size_t>(w)]) continue;
            in_anchor[static_cast<std::size_t>(w)] = 1;
            anchor.push_back(w);
            next.push_back(w);
          }
        }
      }
      frontier.swap(next);
    }
    std::sort(anchor.begin(), anchor.end());
    Eigen::Vector3d c0 = Eigen::Vector3d::Zero();
    for (const std::int32_t v : anchor) {
      c0 += mesh.vertices.row(v).transpose();
      in_anchor[static_cast<std::size_t>(v)] = 0;
    }
    c0 /= static_cast<double>(anchor.size());
    double spread = 0.0;
    for (const std::int32_t v : anchor) {
      const Eigen::Vector3d q = mesh.vertices.row(v).transpose() - c0;
      anchor_vertex_.push_back(v);
      anchor_rest_.push_back(q);
      spread += q.squaredNorm();
    }
    anchor_start_.push_back(static_cast<std::int32_t>(anchor_vertex_.size()));
    rest_offset_.push_back(mesh.vertices.row(m).transpose() - c0);
    degenerate_limit_.push_back(1e-9 * spread);
  }
  rotation_.assign(marker_vertices.size(), Eigen::Quaterniond::Identity());
}

bool MarkerPredictor::predict(std::span<const double> positions, std::span<Eigen::Vector3d> predictions,
                              std::span<const std::uint8_t> skip) noexcept {
  if (positions.size() != static_cast<std::size_t>(vertex_count_) * 3 || predictions.size() != rest_offset_.size()) return false;
  if (!skip.empty() && skip.size() != rest_offset_.size()) return false;
  bool all_finite = true;
  const double* x = positions.data();
  for (std::size_t k = 0; k < rest_offset_.size(); ++k) {
    if (!skip.empty() && skip[k] != 0) continue;
    const auto begin = static_cast<std::size_t>(anchor_start_[k]), end = static_cast<std::size_t>(anchor_start_[k + 1]);
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (std::size_t e = begin; e < end; ++e) {
      const double* p = x + 3 * static_cast<std::size_t>(anchor_vertex_[e]);
      c += Eigen::Vector3d(p[0], p[1], p[2]);
    }
    c /= static_cast<double>(end - begin);
    Eigen::Matrix3d a = Eigen::Matrix3d::Zero();
    for (std::size_t e = begin; e < end; ++e) {
      const double* p = x + 3 * static_cast<std::size_t>(anchor_vertex_[e]);
      a.noalias() += (Eigen::Vector3d(p[0], p[1], p[2]) - c) * anchor_rest_[e].transpose();
    }
    if (!a.allFinite() || !c.allFinite()) {
      all_finite = false;
      predictions[k] = c + rotation_[k] * rest_offset_[k];  // non-finite: the caller replaces it
      continue;
    }
    if (a.norm() > degenerate_limit_[k]) rotation_[k] = closestRotation(a);
    predictions[k] = c + rotation_[k] * rest_offset_[k];
  }
  return all_finite;
}

void MarkerPredictor::reset() noexcept {
  for (auto& q : rotation_) q = Eigen::Quaterniond::Identity();
}

std::span<const std::int32_t> MarkerPredictor::anchorVertices(std::int32_t marker) const noexcept {
  const auto k = static_cast<std::size_t>(marker);
  return {anchor_vertex_.data() + anchor_start_[k], static_cast<std::size_t>(anchor_start_[k + 1] - anchor_start_[k])};
}

}  // namespace tetrig
