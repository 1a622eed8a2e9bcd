// Tetrahedral mesh: the volume the deformation runs on.
//
// Conventions (see ARCHITECTURE.md): positions are doubles in the rig's unit (metres for rigs
// built from markers); a tet (a, b, c, d) is positively oriented when
// det[b-a, c-a, d-a] > 0, i.e. its signed volume (1/6 of that determinant) is positive.
#pragma once

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <vector>

namespace tetrig {

using Vertices = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;      // #V by 3
using Tets = Eigen::Matrix<std::int32_t, Eigen::Dynamic, 4, Eigen::RowMajor>;    // #T by 4, 0-based
using Triangles = Eigen::Matrix<std::int32_t, Eigen::Dynamic, 3, Eigen::RowMajor>;

struct TetMesh {
  Vertices vertices;  // #V by 3
  Tets tets;          // #T by 4, 0-based vertex indices

  std::int32_t vertexCount() const { return static_cast<std::int32_t>(vertices.rows()); }
  std::int32_t tetCount() const { return static_cast<std::int32_t>(tets.rows()); }
};

// Signed volume of tet t: det[b-a, c-a, d-a] / 6.
double signedVolume(const TetMesh& mesh, std::int32_t t);

// What is wrong with a mesh, if anything. Index ranges are checked first; volumes only when
// every index is in range.
struct TetMeshReport {
  std::int32_t out_of_range_indices = 0;   // tets referencing a vertex >= #V or < 0
  std::int32_t repeated_corner_tets = 0;   // tets naming one vertex twice
  std::int32_t inverted_tets = 0;          // signed volume < 0
  std::int32_t degenerate_tets = 0;        // |signed volume| <= eps * (longest edge)^3
  std::int32_t unused_vertices = 0;        // vertices no tet references
  std::int32_t non_finite_vertices = 0;
  std::vector<std::int32_t> first_bad_tets;  // up to 16 offending tet indices, for messages
  bool ok() const {
    return out_of_range_indices == 0 && repeated_corner_tets == 0 && inverted_tets == 0 &&
           degenerate_tets == 0 && non_finite_vertices == 0;
  }
  std::string summary() const;  // one line, e.g. "3 inverted tets (first: 12, 40, 77)"
};

TetMeshReport checkTetMesh(const TetMesh& mesh, double degenerate_eps = 1e-12);

// The boundary of the first tet_count tets (all of them with -1): the faces that belong to exactly
// one of them, each oriented away from its tet's fourth corner (counter-clockwise seen from outside,
// whichever the tet's own orientation), in order of their sorted corners. #B by 3. Load time;
// allocates; the tets' indices must be in range.
Triangles boundaryFaces(const TetMesh& mesh, std::int32_t tet_count = -1);

// Axis-aligned bounding box diagonal length (0 for an empty mesh).
double boundingBoxDiagonal(const Vertices& vertices);

}  // namespace tetrig
