#include "tetrig/tet_mesh.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>
#include <vector>

namespace tetrig {

double signedVolume(const TetMesh& mesh, std::int32_t t) {
  const auto& tet = mesh.tets.row(t);
  const Eigen::Vector3d a = mesh.vertices.row(tet[0]).transpose();
  Eigen::Matrix3d e;
  e.col(0) = mesh.vertices.row(tet[1]).transpose() - a;
  e.col(1) = mesh.vertices.row(tet[2]).transpose() - a;
  e.col(2) = mesh.vertices.row(tet[3]).transpose() - a;
  return e.determinant() / 6.0;
}

Triangles boundaryFaces(const TetMesh& mesh, std::int32_t tet_count) {
  const std::int32_t n = tet_count < 0 ? mesh.tetCount() : tet_count;
  // Face k of a positively oriented tet (the one opposite corner k), outward.
  static constexpr int kFace[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
  struct Face {
    std::array<std::int32_t, 3> key, corners;  // sorted, and in outward order
  };
  std::vector<Face> faces;
  faces.reserve(4 * static_cast<std::size_t>(n));
  for (std::int32_t t = 0; t < n; ++t) {
    const bool positive = signedVolume(mesh, t) >= 0.0;
    for (const auto& f : kFace) {
      Face face{{}, {mesh.tets(t, f[0]), mesh.tets(t, f[1]), mesh.tets(t, f[2])}};
      if (!positive) std::swap(face.corners[1], face.corners[2]);
      face.key = face.corners;
      std::sort(face.key.begin(), face.key.end());
      faces.push_back(face);
    }
  }
  std::sort(faces.begin(), faces.end(), [](const Face& x, const Face& y) { return x.key < y.key; });
  std::vector<std::array<std::int32_t, 3>> once;
  for (std::size_t i = 0; i < faces.size();) {
    std::size_t j = i + 1;
    while (j < faces.size() && faces[j].key == faces[i].key) ++j;
    if (j == i + 1) once.push_back(faces[i].corners);
    i = j;
  }
  Triangles out(static_cast<Eigen::Index>(once.size()), 3);
  for (std::size_t f = 0; f < once.size(); ++f)
    for (int k = 0; k < 3; ++k) out(static_cast<Eigen::Index>(f), k) = once[f][static_cast<std::size_t>(k)];
  return out;
}

double boundingBoxDiagonal(const Vertices& vertices) {
  if (vertices.rows() == 0) return 0.0;
  return (vertices.colwise().maxCoeff() - vertices.colwise().minCoeff()).norm();
}

TetMeshReport checkTetMesh(const TetMesh& mesh, double degenerate_eps) {
  TetMeshReport report;
  const std::int32_t nv = mesh.vertexCount();
  std::vector<char> used(static_cast<size_t>(nv), 0);
  auto note = [&report](std::int32_t t) {
    if (report.first_bad_tets.size() < 16) report.first_bad_tets.push_back(t);
  };
  for (std::int32_t v = 0; v < nv; ++v) {
    if (!mesh.vertices.row(v).allFinite()) ++report.non_finite_vertices;
  }
  for (std::int32_t t = 0; t < mesh.tetCount(); ++t) {
    const auto tet = mesh.tets.row(t);
    bool in_range = true;
    for (int k = 0; k < 4; ++k) in_range = in_range && tet[k] >= 0 && tet[k] < nv;
    if (!in_range) {
      ++report.out_of_range_indices;
      note(t);
      continue;
    }
    for (int k = 0; k < 4; ++k) used[static_cast<size_t>(tet[k])] = 1;
    bool repeated = false;
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b) repeated = repeated || tet[a] == tet[b];
    if (repeated) {
      ++report.repeated_corner_tets;
      note(t);
      continue;
    }
    double longest = 0.0;
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b)
        longest = std::max(longest, (mesh.vertices.row(tet[a]) - mesh.vertices.row(tet[b])).norm());
    const double vol = signedVolume(mesh, t);
    if (std::abs(vol) <= degenerate_eps * longest * longest * longest) {
      ++report.degenerate_tets;
      note(t);
    } else if (vol < 0.0) {
      ++report.inverted_tets;
      note(t);
    }
  }
  report.unused_vertices = static_cast<std::int32_t>(std::count(used.begin(), used.end(), 0));
  return report;
}

std::string TetMeshReport::summary() const {
  std::ostringstream out;
  bool first = true;
  auto item = [&](std::int32_t count, const char* what) {
    if (count == 0) return;
    out << (first ? "" : ", ") << count << ' ' << what;
    first = false;
  };
  item(out_of_range_indices, "tets with out-of-range vertex indices");
  item(repeated_corner_tets, "tets with a repeated corner");
  item(inverted_tets, "inverted tets");
  item(degenerate_tets, "zero-volume tets");
  item(non_finite_vertices, "non-finite vertices");
  item(unused_vertices, "unused vertices");
  if (first) return "ok";
  if (!first_bad_tets.empty()) {
    out << " (first bad tets:";
    for (auto t : first_bad_tets) out << ' ' << t;
    out << ')';
  }
  return out.str();
}

}  // namespace tetrig
