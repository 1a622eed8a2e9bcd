// Matching of imported vertices to a file's vertex list: a hash of float-rounded coordinates for
// the exact matches, then, for the rest, a radius query in a nanoflann k-d tree over the file
// vertices (built on the first miss) and the nearest candidate, ties to the lowest index.
#include "tetrig/rigbuild/match_file_vertices.hpp"

#include "tetrig/rigbuild/cell_key.hpp"

#include <nanoflann.hpp>

#include <bit>
#include <cfloat>
#include <cstddef>
#include <limits>
#include <memory>
#include <unordered_map>
#include <utility>

namespace tetrig::rigbuild {
namespace {

// assimp keeps single precision: a file vertex is found by its coordinates rounded to float
// (-0 and +0 alike: adding +0.0f turns -0 into +0).
CellKey floatKey(const Eigen::RowVector3d& p) {
  auto bits = [](double x) -> std::int64_t { return std::bit_cast<std::uint32_t>(static_cast<float>(x) + 0.0f); };
  return CellKey{bits(p[0]), bits(p[1]), bits(p[2])};
}

// nanoflann dataset adaptor over the rows of a Vertices matrix (row-major #V by 3).
struct VertexCloud {
  const Vertices* vertices = nullptr;
  size_t kdtree_get_point_count() const { return static_cast<size_t>(vertices->rows()); }
  double kdtree_get_pt(size_t idx, size_t dim) const {
    return (*vertices)(static_cast<Eigen::Index>(idx), static_cast<Eigen::Index>(dim));
  }
  template <class Box>
  bool kdtree_get_bbox(Box& /*box*/) const {
    return false;
  }
};
using KdTree =
    nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, VertexCloud>, VertexCloud, 3, std::uint32_t>;

}  // namespace

std::optional<std::vector<std::int32_t>> matchFileVertices(const Vertices& imported, const Vertices& file) {
  if (file.rows() > std::numeric_limits<std::int32_t>::max()) return std::nullopt;
  std::unordered_map<CellKey, std::int32_t, CellHash> exact;
  exact.reserve(static_cast<std::size_t>(file.rows()));
  for (Eigen::Index i = 0; i < file.rows(); ++i) {
    if (!file.row(i).allFinite()) return std::nullopt;
    exact.emplace(floatKey(file.row(i)), static_cast<std::int32_t>(i));  // emplace keeps the earliest
  }
  const double max_abs = file.rows() > 0 ? file.cwiseAbs().maxCoeff() : 0.0;
  const double tolerance = 1e-6 * boundingBoxDiagonal(file) + 8.0 * FLT_EPSILON * max_abs;
  // nanoflann's radius is a squared distance and exclusive (dist < radius), and it sums the squares
  // in its own order: query a slightly larger ball, then accept exactly |file_i - p| <= tolerance.
  const double query_radius_sq = tolerance * tolerance * (1.0 + 1e-9) + std::numeric_limits<double>::min();
  VertexCloud cloud{&file};
  std::unique_ptr<KdTree> tree;  // built on the first miss
  std::vector<std::pair<std::uint32_t, double>> candidates;
  const nanoflann::SearchParams unsorted(32, 0.0f, false);

  std::vector<std::int32_t> out(static_cast<std::size_t>(imported.rows()), -1);
  for (Eigen::Index v = 0; v < imported.rows(); ++v) {
    const Eigen::RowVector3d p = imported.row(v);
    if (const auto it = exact.find(floatKey(p)); it != exact.end()) {
      out[static_cast<std::size_t>(v)] = it->second;
      continue;
    }
    if (!(tolerance > 0.0) || !p.allFinite()) return std::nullopt;
    if (!tree) {
      tree = std::make_unique<KdTree>(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
      tree->buildIndex();
    }
    tree->radiusSearch(p.data(), query_radius_sq, candidates, unsorted);
    std::int32_t best = -1;
    double best_d = std::numeric_limits<double>::infinity();
    for (const auto& candidate : candidates) {  // (index, nanoflann's squared distance), unordered
      const auto i = static_cast<std::int32_t>(candidate.first);
      const double d = (file.row(i) - p).norm();
      if (d > tolerance) continue;
      if (d < best_d || (d == best_d && i < best)) {
        best_d = d;
        best = i;
      }
    }
    if (best < 0) return std::nullopt;
    out[static_cast<std::size_t>(v)] = best;
  }
  return out;
}

}  // namespace tetrig::rigbuild
