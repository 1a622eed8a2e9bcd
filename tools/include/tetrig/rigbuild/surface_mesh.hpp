// Triangle surface mesh used by the offline rig builder, and the builder's error type.
//
// Conventions: positions are doubles in the file's own unit; triangles are 0-based vertex index
// triples; a closed surface is oriented outward when its signed volume (sum over faces of
// a . (b x c) / 6) is positive, i.e. faces are counter-clockwise seen from outside.
// Offline code only: everything here may allocate and throw.
#pragma once

#include "tetrig/tet_mesh.hpp"

#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>

namespace tetrig::rigbuild {

struct SurfaceMesh {
  Vertices vertices;    // #V by 3
  Triangles triangles;  // #F by 3, 0-based

  std::int32_t vertexCount() const { return static_cast<std::int32_t>(vertices.rows()); }
  std::int32_t triangleCount() const { return static_cast<std::int32_t>(triangles.rows()); }
};

// Any step of the rig builder that refuses its input throws this; what() is one line saying what
// was wrong, where, and what to do about it.
class RigBuildError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The tetrahedralization found no tet mesh of the budget it was given (the surface intersects
// itself once decimated that far, or has parts thinner than its triangles); a larger budget may
// succeed.
class TetBudgetError : public RigBuildError {
 public:
  using RigBuildError::RigBuildError;
};

// Signed volume enclosed by a closed surface (divergence theorem); negative when the faces point
// inward. Meaningless for open surfaces.
double signedVolume(const SurfaceMesh& mesh);

// The file extension in lower case, with its dot (".obj"), which is how the builder picks a
// reader; "" when the path has none.
std::string lowercaseExtension(const std::filesystem::path& path);

}  // namespace tetrig::rigbuild
