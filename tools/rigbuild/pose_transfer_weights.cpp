// Pose-transfer weights of Stoll, de Aguiar, Theobalt and Seidel, "A Volumetric Approach to
// Interactive Shape Editing" (2007), section 2.4, eq. 2.9-2.12: barycentric coordinates with
// respect to every tet whose boundary-face centre lies within r of the vertex, blended with
// Wendland's compactly supported weight phi(d) = (1 - d/r)^4 (4 d/r + 1) (H. Wendland,
// "Piecewise polynomial, positive definite and compactly supported radial functions of minimal
// degree", 1995) and normalised. Neighbour queries use a nanoflann k-d tree.
#include "tetrig/rigbuild/pose_transfer_weights.hpp"
#include "xyz_kd_tree.hpp"

#include "tetrig/rigbuild/surface_mesh.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

namespace tetrig::rigbuild {
namespace {

struct BoundaryFace {
  std::array<std::int32_t, 3> corners;
  std::int32_t tet;
};

// Faces of the tet mesh that belong to exactly one tet.
std::vector<BoundaryFace> boundaryFacesWithTheirTet(const TetMesh& mesh) {
  std::vector<BoundaryFace> all;
  all.reserve(static_cast<size_t>(mesh.tetCount()) * 4);
  for (std::int32_t t = 0; t < mesh.tetCount(); ++t) {
    for (int skip = 0; skip < 4; ++skip) {
      BoundaryFace f{};
      int n = 0;
      for (int k = 0; k < 4; ++k) {
        if (k != skip) f.corners[static_cast<size_t>(n++)] = mesh.tets(t, k);
      }
      std::sort(f.corners.begin(), f.corners.end());
      f.tet = t;
      all.push_back(f);
    }
  }
  std::sort(all.begin(), all.end(), [](const BoundaryFace& a, const BoundaryFace& b) {
    return a.corners != b.corners ? a.corners < b.corners : a.tet < b.tet;
  });
  std::vector<BoundaryFace> boundary;
  for (size_t i = 0; i < all.size();) {
    size_t j = i;
    while (j < all.size() && all[j].corners == all[i].corners) ++j;
    if (j - i == 1) boundary.push_back(all[i]);
    i = j;
  }
  return boundary;
}

double wendland(double d, double r) {
  if (d >= r) return 0.0;
  const double q = 1.0 - d / r;
  return q * q * q * q * (4.0 * d / r + 1.0);
}

}  // namespace

Eigen::SparseMatrix<double, Eigen::RowMajor> poseTransferWeights(const Vertices& fine_vertices, const TetMesh& tets,
                                                                 const PoseTransferOptions& options,
                                                                 PoseTransferStats* stats) {
  if (fine_vertices.rows() == 0) throw RigBuildError("pose-transfer weights: the fine mesh has no vertices");
  if (tets.tetCount() == 0) throw RigBuildError("pose-transfer weights: the tet mesh has no tets");
  const TetMeshReport check = checkTetMesh(tets);
  if (!check.ok()) throw RigBuildError("pose-transfer weights: the tet mesh is invalid: " + check.summary());
  if (!fine_vertices.allFinite()) throw RigBuildError("pose-transfer weights: the fine mesh has non-finite vertices");
  if (options.max_nonzeros_per_row != 0 && options.max_nonzeros_per_row < 4) {
    throw RigBuildError("pose-transfer weights: max_nonzeros_per_row must be 0 (no cap) or at least 4");
  }

  PoseTransferStats st;
  const double r = options.radius_fraction * boundingBoxDiagonal(fine_vertices);
  st.radius = r;
  const std::int32_t n_tet_v = tets.vertexCount();
  const std::int32_t n_tets = tets.tetCount();

  // Per tet: p4 and the inverse of [p1-p4 | p2-p4 | p3-p4] for barycentric coordinates.
  std::vector<Eigen::Matrix3d> inverse(static_cast<size_t>(n_tets));
  std::vector<double> centroids(static_cast<size_t>(n_tets) * 3);
  for (std::int32_t t = 0; t < n_tets; ++t) {
    Eigen::Matrix3d m;
    const Eigen::Vector3d p4 = tets.vertices.row(tets.tets(t, 3)).transpose();
    for (int k = 0; k < 3; ++k) m.col(k) = tets.vertices.row(tets.tets(t, k)).transpose() - p4;
    inverse[static_cast<size_t>(t)] = m.inverse();
    Eigen::Vector3d c = p4;
    for (int k = 0; k < 3; ++k) c += tets.vertices.row(tets.tets(t, k)).transpose();
    c /= 4.0;
    for (int k = 0; k < 3; ++k) centroids[static_cast<size_t>(t) * 3 + static_cast<size_t>(k)] = c[k];
  }
  auto barycentric = [&](std::int32_t t, const Eigen::Vector3d& p) {
    const Eigen::Vector3d l = inverse[static_cast<size_t>(t)] * (p - tets.vertices.row(tets.tets(t, 3)).transpose());
    return Eigen::Vector4d(l[0], l[1], l[2], 1.0 - l.sum());
  };

  const std::vector<BoundaryFace> faces = boundaryFacesWithTheirTet(tets);
  if (faces.empty()) throw RigBuildError("pose-transfer weights: the tet mesh has no boundary faces");
  st.boundary_faces = static_cast<std::int32_t>(faces.size());
  std::vector<double> centres(faces.size() * 3);
  for (size_t f = 0; f < faces.size(); ++f) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (const std::int32_t v : faces[f].corners) c += tets.vertices.row(v).transpose();
    c /= 3.0;
    for (int k = 0; k < 3; ++k) centres[f * 3 + static_cast<size_t>(k)] = c[k];
  }
  XyzPointCloud face_cloud{&centres};
  XyzKdTree face_tree(3, face_cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  face_tree.buildIndex();
  XyzPointCloud centroid_cloud{&centroids};
  XyzKdTree centroid_tree(3, centroid_cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  centroid_tree.buildIndex();

  const auto n_fine = static_cast<std::int32_t>(fine_vertices.rows());
  std::vector<std::int64_t> row_offsets(static_cast<size_t>(n_fine) + 1, 0);
  std::vector<std::int32_t> columns;
  std::vector<double> values;
  columns.reserve(static_cast<size_t>(n_fine) * 32);
  values.reserve(static_cast<size_t>(n_fine) * 32);

  std::vector<std::pair<std::uint32_t, double>> matches;
  std::vector<std::int32_t> tet_stamp(static_cast<size_t>(n_tets), -1);
  std::vector<std::int32_t> column_stamp(static_cast<size_t>(n_tet_v), -1);
  std::vector<double> accum(static_cast<size_t>(n_tet_v), 0.0);
  std::vector<std::pair<std::int32_t, double>> row_tets;  // (tet, phi), nearest first
  std::vector<std::int32_t> touched;
  std::vector<std::pair<std::int32_t, double>> entries;
  const nanoflann::SearchParams sorted_search(32, 0.0f, true);
  constexpr int kContainK = 16;
  std::array<std::uint32_t, kContainK> knn_index{};
  std::array<double, kContainK> knn_dist{};
  double tets_total = 0.0;

  for (std::int32_t i = 0; i < n_fine; ++i) {
    const Eigen::Vector3d p = fine_vertices.row(i).transpose();
    row_tets.clear();
    matches.clear();
    if (r > 0.0) face_tree.radiusSearch(p.data(), r * r, matches, sorted_search);
    for (const auto& [face, d2] : matches) {
      const std::int32_t t = faces[face].tet;
      if (tet_stamp[static_cast<size_t>(t)] == i) continue;  // counted at its nearest boundary face
      tet_stamp[static_cast<size_t>(t)] = i;
      const double phi = wendland(std::sqrt(d2), r);
      if (phi > 0.0) row_tets.push_back({t, phi});
    }
    if (row_tets.empty()) {
      // Fallback: the containing tet, else the tet of the nearest boundary-face centre.
      const size_t k = centroid_tree.knnSearch(p.data(), std::min<size_t>(kContainK, static_cast<size_t>(n_tets)),
                                               knn_index.data(), knn_dist.data());
      std::int32_t chosen = -1;
      for (size_t j = 0; j < k && chosen < 0; ++j) {
        const auto t = static_cast<std::int32_t>(knn_index[j]);
        if (barycentric(t, p).minCoeff() >= -1e-9) chosen = t;
      }
      if (chosen >= 0) {
        ++st.fallback_containing;
      } else {
        std::uint32_t face = 0;
        double d2 = 0.0;
        face_tree.knnSearch(p.data(), 1, &face, &d2);
        chosen = faces[face].tet;
        ++st.fallback_nearest;
      }
      row_tets.push_back({chosen, 1.0});
    }

    // Cap by whole tets, nearest first (row_tets is sorted by distance already).
    if (options.max_nonzeros_per_row > 0 && options.cap_mode == WeightCap::kDropFarTets) {
      size_t kept = 0;
      std::int32_t used_columns = 0;
      touched.clear();
      for (size_t j = 0; j < row_tets.size(); ++j) {
        const std::int32_t t = row_tets[j].first;
        std::int32_t fresh = 0;
        for (int c = 0; c < 4; ++c) fresh += column_stamp[static_cast<size_t>(tets.tets(t, c))] != i ? 1 : 0;
        if (kept > 0 && used_columns + fresh > options.max_nonzeros_per_row) continue;
        for (int c = 0; c < 4; ++c) column_stamp[static_cast<size_t>(tets.tets(t, c))] = i;
        used_columns += fresh;
        row_tets[kept++] = row_tets[j];
      }
      if (kept < row_tets.size()) ++st.capped_rows;
      row_tets.resize(kept);
      // Reset the column stamps for the accumulation below.
      for (const auto& [t, phi] : row_tets) {
        for (int c = 0; c < 4; ++c) column_stamp[static_cast<size_t>(tets.tets(t, c))] = -1;
      }
    }
    tets_total += static_cast<double>(row_tets.size());

    double phi_sum = 0.0;
    for (const auto& rt : row_tets) phi_sum += rt.second;
    touched.clear();
    for (const auto& [t, phi] : row_tets) {
      const Eigen::Vector4d l = barycentric(t, p);
      const double w = phi / phi_sum;
      for (int c = 0; c < 4; ++c) {
        const std::int32_t col = tets.tets(t, c);
        if (column_stamp[static_cast<size_t>(col)] != i) {
          column_stamp[static_cast<size_t>(col)] = i;
          accum[static_cast<size_t>(col)] = 0.0;
          touched.push_back(col);
        }
        accum[static_cast<size_t>(col)] += w * l[c];
      }
    }
    entries.clear();
    for (const std::int32_t col : touched) entries.push_back({col, accum[static_cast<size_t>(col)]});
    if (options.max_nonzeros_per_row > 0 && options.cap_mode == WeightCap::kDropSmallEntries &&
        entries.size() > static_cast<size_t>(options.max_nonzeros_per_row)) {
      std::nth_element(entries.begin(), entries.begin() + options.max_nonzeros_per_row, entries.end(),
                       [](const auto& a, const auto& b) { return std::abs(a.second) > std::abs(b.second); });
      entries.resize(static_cast<size_t>(options.max_nonzeros_per_row));
      double sum = 0.0;
      for (const auto& e : entries) sum += e.second;
      if (std::abs(sum) > 1e-12) {
        for (auto& e : entries) e.second /= sum;
      }
      ++st.capped_rows;
    }
    std::sort(entries.begin(), entries.end());
    for (const auto& [col, v] : entries) {
      columns.push_back(col);
      values.push_back(v);
      st.max_abs_coefficient = std::max(st.max_abs_coefficient, std::abs(v));
    }
    st.max_nonzeros_per_row = std::max(st.max_nonzeros_per_row, static_cast<std::int32_t>(entries.size()));
    row_offsets[static_cast<size_t>(i) + 1] = static_cast<std::int64_t>(columns.size());
  }

  if (columns.size() > static_cast<size_t>(std::numeric_limits<int>::max())) {
    throw RigBuildError("pose-transfer weights: more than 2^31 non-zeros; lower the radius or cap the rows");
  }
  Eigen::SparseMatrix<double, Eigen::RowMajor> b(n_fine, n_tet_v);
  b.resizeNonZeros(static_cast<Eigen::Index>(columns.size()));
  for (std::int32_t i = 0; i <= n_fine; ++i) b.outerIndexPtr()[i] = static_cast<int>(row_offsets[static_cast<size_t>(i)]);
  std::copy(columns.begin(), columns.end(), b.innerIndexPtr());
  std::copy(values.begin(), values.end(), b.valuePtr());
  b.finalize();

  st.nonzeros = static_cast<std::int64_t>(columns.size());
  st.mean_nonzeros_per_row = static_cast<double>(st.nonzeros) / n_fine;
  st.mean_tets_per_row = tets_total / n_fine;
  if (stats != nullptr) *stats = st;
  return b;
}

double restReconstructionError(const Eigen::SparseMatrix<double, Eigen::RowMajor>& b, const Vertices& fine_vertices,
                               const Vertices& tet_vertices) {
  if (b.rows() != fine_vertices.rows() || b.cols() != tet_vertices.rows()) {
    throw RigBuildError("restReconstructionError: B is " + std::to_string(b.rows()) + " by " + std::to_string(b.cols()) +
                        " but the meshes have " + std::to_string(fine_vertices.rows()) + " and " +
                        std::to_string(tet_vertices.rows()) + " vertices");
  }
  const Eigen::MatrixXd reconstructed = b * tet_vertices;
  const double diagonal = boundingBoxDiagonal(fine_vertices);
  const double worst = (reconstructed - Eigen::MatrixXd(fine_vertices)).rowwise().norm().maxCoeff();
  return diagonal > 0.0 ? worst / diagonal : worst;
}

}  // namespace tetrig::rigbuild
