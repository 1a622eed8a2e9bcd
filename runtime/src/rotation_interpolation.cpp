// Harmonic interpolation of relative rotations: Stoll et al. 2007 (2.3.2) after Zayer et al. 2005.
#include "tetrig/rotation_interpolation.hpp"

#include <Eigen/SparseCholesky>

#include "multiversion.hpp"
#include "vector_lanes.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace tetrig {

std::vector<double> harmonicTetWeights(const TetMesh& mesh, std::span<const std::vector<std::int32_t>> handle_tets,
                                       std::span<const std::int32_t> zero_tets) {
  const std::int32_t m = mesh.tetCount();
  const auto handles = static_cast<std::int32_t>(handle_tets.size());
  std::vector<double> weights(static_cast<size_t>(handles) * static_cast<size_t>(m), 0.0);
  if (handles == 0) return weights;

  // Boundary label: -1 free, h for handle h, handles for "zero".
  std::vector<std::int32_t> label(static_cast<size_t>(m), -1);
  for (std::int32_t h = 0; h < handles; ++h)
    for (auto t : handle_tets[static_cast<size_t>(h)]) label[static_cast<size_t>(t)] = h;
  for (auto t : zero_tets)
    if (label[static_cast<size_t>(t)] < 0) label[static_cast<size_t>(t)] = handles;

  // Face adjacency: sort (sorted face, tet) records and pair equal faces.
  std::vector<std::pair<std::array<std::int32_t, 3>, std::int32_t>> faces;
  faces.reserve(static_cast<size_t>(m) * 4);
  for (std::int32_t t = 0; t < m; ++t) {
    for (int skip = 0; skip < 4; ++skip) {
      std::array<std::int32_t, 3> face{};
      int n = 0;
      for (int c = 0; c < 4; ++c)
        if (c != skip) face[static_cast<size_t>(n++)] = mesh.tets(t, c);
      std::sort(face.begin(), face.end());
      faces.emplace_back(face, t);
    }
  }
  std::sort(faces.begin(), faces.end());
  std::vector<std::pair<std::int32_t, std::int32_t>> edges;
  for (size_t i = 0; i + 1 < faces.size(); ++i) {
    if (faces[i].first == faces[i + 1].first) edges.emplace_back(faces[i].second, faces[i + 1].second);
  }

  // Unknowns: free tets.
  std::vector<std::int32_t> unknown(static_cast<size_t>(m), -1);
  std::int32_t free_count = 0;
  for (std::int32_t t = 0; t < m; ++t)
    if (label[static_cast<size_t>(t)] < 0) unknown[static_cast<size_t>(t)] = free_count++;
  for (std::int32_t h = 0; h < handles; ++h)
    for (auto t : handle_tets[static_cast<size_t>(h)])
      weights[static_cast<size_t>(h) * static_cast<size_t>(m) + static_cast<size_t>(t)] = 1.0;
  if (free_count == 0) return weights;

  std::vector<Eigen::Triplet<double>> triplets;
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(free_count, handles);
  std::vector<double> degree(static_cast<size_t>(free_count), 0.0);
  for (auto [a, b] : edges) {
    for (int side = 0; side < 2; ++side) {
      const std::int32_t t = side == 0 ? a : b, o = side == 0 ? b : a;
      const std::int32_t i = unknown[static_cast<size_t>(t)];
      if (i < 0) continue;
      degree[static_cast<size_t>(i)] += 1.0;
      const std::int32_t j = unknown[static_cast<size_t>(o)];
      if (j >= 0) {
        triplets.emplace_back(i, j, -1.0);
      } else if (label[static_cast<size_t>(o)] < handles) {
        rhs(i, label[static_cast<size_t>(o)]) += 1.0;
      }
    }
  }
  // A tiny diagonal shift keeps parts with no boundary tet solvable (their weights go to 0).
  for (std::int32_t i = 0; i < free_count; ++i) triplets.emplace_back(i, i, degree[static_cast<size_t>(i)] + 1e-10);
  Eigen::SparseMatrix<double> k(free_count, free_count);
  k.setFromTriplets(triplets.begin(), triplets.end());
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(k);
  if (ldlt.info() != Eigen::Success) throw std::runtime_error("rotation interpolation: dual-graph Laplacian factorization failed");
  const Eigen::MatrixXd solution = ldlt.solve(rhs);
  for (std::int32_t t = 0; t < m; ++t) {
    const std::int32_t i = unknown[static_cast<size_t>(t)];
    if (i < 0) continue;
    for (std::int32_t h = 0; h < handles; ++h)
      weights[static_cast<size_t>(h) * static_cast<size_t>(m) + static_cast<size_t>(t)] =
          std::clamp(solution(i, h), 0.0, 1.0);
  }
  return weights;
}

// Half a block (8 slots) at a time, in double (vector extensions; was scalar and 19 % of a demo frame).
TETRIG_MULTIVERSION
void applyRotationIncrements(std::span<const double> weights, std::span<const Eigen::Quaterniond> increments,
                             TetBlock* blocks, std::int32_t slot_count) {
  using lanes::kLanes;
  using lanes::Lanes;
  using lanes::load;
  using lanes::loadHalf;
  using lanes::storeHalf;
  const auto handles = static_cast<std::int32_t>(increments.size());
  const std::int32_t half_count = slot_count / kLanes;
  for (std::int32_t hb = 0; hb < half_count; ++hb) {
    Lanes iw{}, ix{}, iy{}, iz{}, total{};
    for (std::int32_t h = 0; h < handles; ++h) {
      const Lanes w = load(&weights[static_cast<size_t>(h) * static_cast<size_t>(slot_count) +
                                    static_cast<size_t>(hb) * kLanes]);
      const Eigen::Quaterniond& q = increments[static_cast<size_t>(h)];
      iw += w * q.w();
      ix += w * q.x();
      iy += w * q.y();
      iz += w * q.z();
      total += w;
    }
    const Lanes rest = 1.0 - total;
    iw += rest > 0.0 ? rest : Lanes{};
    const Lanes norm2 = iw * iw + ix * ix + iy * iy + iz * iz;
    // 1 / |blend| in vectors (a lane-by-lane test, sqrt and divide took half the pass): a vanished
    // blend's lane takes 1 under the root and 0 after.
    const auto blended = norm2 > 1e-24;
    Lanes root = blended ? norm2 : Lanes{} + 1.0;
    for (int l = 0; l < kLanes; ++l) root[l] = __builtin_sqrt(root[l]);  // -fno-math-errno: one vector sqrt
    const Lanes inv = blended ? 1.0 / root : Lanes{};
    TetBlock& block = blocks[hb / 2];
    const int lane0 = kLanes * (hb % 2);
    float* rw = block.rotation[0] + lane0;
    float* rx = block.rotation[1] + lane0;
    float* ry = block.rotation[2] + lane0;
    float* rz = block.rotation[3] + lane0;
    const Lanes w0 = loadHalf(rw), x0 = loadHalf(rx), y0 = loadHalf(ry), z0 = loadHalf(rz);
    iw *= inv;
    ix *= inv;
    iy *= inv;
    iz *= inv;
    // Hamilton product inc * q; a slot whose blend vanished (norm <= 1e-12) keeps its rotation.
    const auto keep = inv == 0.0;
    storeHalf(rw, keep ? w0 : iw * w0 - ix * x0 - iy * y0 - iz * z0);
    storeHalf(rx, keep ? x0 : iw * x0 + ix * w0 + iy * z0 - iz * y0);
    storeHalf(ry, keep ? y0 : iw * y0 - ix * z0 + iy * w0 + iz * x0);
    storeHalf(rz, keep ? z0 : iw * z0 + ix * y0 - iy * x0 + iz * w0);
  }
}

}  // namespace tetrig
