// Quadric-error surface decimation (Garland and Heckbert, "Surface Simplification Using Quadric
// Error Metrics", SIGGRAPH 1997) by halfedge collapses through OpenMesh's decimater
// (OpenMesh::Decimater, Debian libopenmesh-dev), driven to a vertex budget, with three guards
// that keep the surface fit for tetrahedralization and deformation (decimate_surface.hpp): an
// edge-length bound (our module below: OpenMesh's ModEdgeLengthT bounds only the collapsed edge,
// not the edges the collapse creates), OpenMesh's aspect-ratio and normal-flipping modules.
#include "tetrig/rigbuild/decimate_surface.hpp"

#include "tetrig/rigbuild/validate_surface.hpp"

#include <Eigen/Geometry>
// OpenMesh's PropertyT<VectorT>::push_back(T()) value-initializes nothing, and GCC 12 at -O1 (the
// sanitizer preset) reports the inlined copy as maybe-uninitialized inside OpenMesh's and the
// standard library's headers. Silenced for this file, which instantiates OpenMesh's templates.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Tools/Decimater/DecimaterT.hh>
#include <OpenMesh/Tools/Decimater/ModAspectRatioT.hh>
#include <OpenMesh/Tools/Decimater/ModNormalFlippingT.hh>
#include <OpenMesh/Tools/Decimater/ModQuadricT.hh>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace tetrig::rigbuild {
namespace {

struct DoubleTraits : public OpenMesh::DefaultTraits {
  using Point = OpenMesh::Vec3d;
  using Normal = OpenMesh::Vec3d;
  VertexAttributes(OpenMesh::Attributes::Status);
  EdgeAttributes(OpenMesh::Attributes::Status);
  HalfedgeAttributes(OpenMesh::Attributes::Status | OpenMesh::Attributes::PrevHalfedge);
  FaceAttributes(OpenMesh::Attributes::Status | OpenMesh::Attributes::Normal);
};
using OmMesh = OpenMesh::TriMesh_ArrayKernelT<DoubleTraits>;

// Binary module: a collapse of v0 into v1 is legal only when every edge it creates (v1 to each
// neighbour of v0) is at most the bound long.
template <class MeshT>
class ModMaxEdgeLengthT : public OpenMesh::Decimater::ModBaseT<MeshT> {
 public:
  DECIMATING_MODULE(ModMaxEdgeLengthT, MeshT, MaxEdgeLength);

  explicit ModMaxEdgeLengthT(MeshT& mesh) : Base(mesh, true), mesh_(mesh) {}

  void setBound(double length) { squared_bound_ = length * length; }

  float collapse_priority(const CollapseInfo& ci) override {
    for (auto vv = mesh_.cvv_iter(ci.v0); vv.is_valid(); ++vv) {
      if (*vv == ci.v1) continue;
      if ((mesh_.point(*vv) - ci.p1).sqrnorm() > squared_bound_) return float(Base::ILLEGAL_COLLAPSE);
    }
    return float(Base::LEGAL_COLLAPSE);
  }

 private:
  MeshT& mesh_;
  double squared_bound_ = std::numeric_limits<double>::infinity();
};

double surfaceArea(const SurfaceMesh& m) {
  double area = 0.0;
  for (std::int32_t f = 0; f < m.triangleCount(); ++f) {
    const Eigen::Vector3d a = m.vertices.row(m.triangles(f, 0)), b = m.vertices.row(m.triangles(f, 1)),
                          c = m.vertices.row(m.triangles(f, 2));
    area += 0.5 * (b - a).cross(c - a).norm();
  }
  return area;
}

}  // namespace

double triangleAspect(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const double longest2 = std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
  const double twice_area = (b - a).cross(c - a).norm();
  return twice_area > 0.0 ? longest2 / twice_area : std::numeric_limits<double>::infinity();
}

struct SurfaceDecimator::State {
  const SurfaceMesh& fine;
  DecimateOptions options;
  double area = 0.0;
  std::int32_t last_target = std::numeric_limits<std::int32_t>::max();
  OmMesh mesh;
  OpenMesh::VPropHandleT<std::int32_t> fine_index;
  std::unique_ptr<OpenMesh::Decimater::DecimaterT<OmMesh>> decimater;
  OpenMesh::Decimater::ModQuadricT<OmMesh>::Handle quadric;
  ModMaxEdgeLengthT<OmMesh>::Handle edge_length;
  OpenMesh::Decimater::ModAspectRatioT<OmMesh>::Handle aspect;
  OpenMesh::Decimater::ModNormalFlippingT<OmMesh>::Handle normals;

  State(const SurfaceMesh& f, const DecimateOptions& o) : fine(f), options(o) {}

  void build() {
    const SurfaceTopology topo = surfaceTopology(fine);
    if (!topo.closedManifold()) {
      throw RigBuildError("decimation needs a closed, manifold, consistently oriented surface (" +
                          std::to_string(topo.boundary_edges) + " boundary, " + std::to_string(topo.non_manifold_edges) +
                          " non-manifold, " + std::to_string(topo.inconsistent_edges) +
                          " inconsistent edges): run validateSurface first");
    }
    mesh.add_property(fine_index);
    std::vector<OmMesh::VertexHandle> handles(static_cast<size_t>(fine.vertexCount()));
    for (std::int32_t v = 0; v < fine.vertexCount(); ++v) {
      const OmMesh::VertexHandle h = mesh.add_vertex(OmMesh::Point(fine.vertices(v, 0), fine.vertices(v, 1), fine.vertices(v, 2)));
      mesh.property(fine_index, h) = v;
      handles[static_cast<size_t>(v)] = h;
    }
    for (std::int32_t f = 0; f < fine.triangleCount(); ++f) {
      const OmMesh::FaceHandle h =
          mesh.add_face(handles[static_cast<size_t>(fine.triangles(f, 0))], handles[static_cast<size_t>(fine.triangles(f, 1))],
                        handles[static_cast<size_t>(fine.triangles(f, 2))]);
      if (!h.is_valid()) {
        throw RigBuildError("decimation: face " + std::to_string(f) + " cannot be added to a manifold mesh (complex vertex or edge): "
                            "run validateSurface first");
      }
    }
    mesh.update_face_normals();
    decimater = std::make_unique<OpenMesh::Decimater::DecimaterT<OmMesh>>(mesh);
    decimater->add(quadric);
    decimater->add(edge_length);
    decimater->add(aspect);
    decimater->add(normals);
    decimater->module(quadric).unset_max_err();
    decimater->module(aspect).set_aspect_ratio(static_cast<float>(options.max_aspect));
    decimater->module(normals).set_max_normal_deviation(options.max_normal_deviation);
    if (!decimater->initialize()) throw RigBuildError("decimation: OpenMesh's decimater did not initialize");
  }

  std::size_t remaining() const {
    std::size_t n = 0;
    for (const auto v : mesh.vertices()) n += mesh.status(v).deleted() ? 0 : 1;
    return n;
  }
};

SurfaceDecimator::SurfaceDecimator(const SurfaceMesh& fine, const DecimateOptions& options)
    : state_(std::make_unique<State>(fine, options)) {
  if (!(options.max_edge_factor > 0.0) || !(options.max_aspect > 1.0) || !(options.max_normal_deviation > 0.0) ||
      options.max_relaxations < 0) {
    throw RigBuildError("decimation guards must be positive (max_edge_factor > 0, max_aspect > 1, max_normal_deviation > 0, "
                        "max_relaxations >= 0)");
  }
  state_->area = surfaceArea(fine);
}

SurfaceDecimator::~SurfaceDecimator() = default;

DecimationResult SurfaceDecimator::decimateTo(std::int32_t target_vertices) {
  State& st = *state_;
  const SurfaceMesh& fine = st.fine;
  const DecimateOptions& options = st.options;
  if (target_vertices < 4) {
    throw RigBuildError("decimation target of " + std::to_string(target_vertices) + " vertices is too small: a closed surface needs at least 4");
  }
  if (target_vertices > st.last_target) {
    throw RigBuildError("decimation cannot grow back from " + std::to_string(st.last_target) + " to " + std::to_string(target_vertices) +
                        " vertices: start a new SurfaceDecimator");
  }
  st.last_target = target_vertices;
  DecimationResult result;
  auto measure = [&result]() {
    const SurfaceMesh& m = result.coarse;
    for (std::int32_t f = 0; f < m.triangleCount(); ++f) {
      const Eigen::Vector3d a = m.vertices.row(m.triangles(f, 0)), b = m.vertices.row(m.triangles(f, 1)),
                            c = m.vertices.row(m.triangles(f, 2));
      result.longest_edge = std::max({result.longest_edge, (b - a).norm(), (c - b).norm(), (a - c).norm()});
      result.worst_aspect = std::max(result.worst_aspect, triangleAspect(a, b, c));
    }
  };
  result.even_edge_length = std::sqrt(2.0 * st.area / (std::sqrt(3.0) * target_vertices));
  if (fine.vertexCount() <= target_vertices) {
    result.coarse = fine;
    result.coarse_to_fine.resize(static_cast<size_t>(fine.vertexCount()));
    for (std::int32_t v = 0; v < fine.vertexCount(); ++v) result.coarse_to_fine[static_cast<size_t>(v)] = v;
    measure();
    return result;
  }
  if (!st.decimater) st.build();

  OmMesh& mesh = st.mesh;
  result.edge_bound = options.max_edge_factor * result.even_edge_length;
  st.decimater->module(st.edge_length).setBound(result.edge_bound);
  // DecimaterT::decimate_to counts the deleted vertices too (the mesh is never compacted here),
  // so the number of collapses is given explicitly.
  const auto target = static_cast<std::size_t>(target_vertices);
  auto collapseTo = [&st, target]() {
    const std::size_t alive = st.remaining();
    if (alive > target) st.decimater->decimate(alive - target);
  };
  collapseTo();
  while (st.remaining() > target && result.relaxations < options.max_relaxations) {
    ++result.relaxations;
    result.edge_bound *= 1.25;
    st.decimater->module(st.edge_length).setBound(result.edge_bound);
    collapseTo();
  }

  // The kept vertices in fine order, and the triangles rewritten onto them (deleted elements
  // skipped: the mesh is not compacted, so that a later call can continue).
  std::vector<std::pair<std::int32_t, int>> kept;  // (fine index, OpenMesh index)
  for (const auto v : mesh.vertices()) {
    if (!mesh.status(v).deleted()) kept.push_back({mesh.property(st.fine_index, v), v.idx()});
  }
  std::sort(kept.begin(), kept.end());
  std::vector<std::int32_t> new_index(mesh.n_vertices(), -1);
  result.coarse.vertices.resize(static_cast<Eigen::Index>(kept.size()), 3);
  for (size_t c = 0; c < kept.size(); ++c) {
    new_index[static_cast<size_t>(kept[c].second)] = static_cast<std::int32_t>(c);
    result.coarse_to_fine.push_back(kept[c].first);
    result.coarse.vertices.row(static_cast<Eigen::Index>(c)) = fine.vertices.row(kept[c].first);
  }
  std::vector<std::array<std::int32_t, 3>> faces;
  for (const auto f : mesh.faces()) {
    if (mesh.status(f).deleted()) continue;
    std::array<std::int32_t, 3> t{-1, -1, -1};
    int k = 0;
    for (auto fv = mesh.cfv_iter(f); fv.is_valid() && k < 3; ++fv, ++k) t[static_cast<size_t>(k)] = new_index[static_cast<size_t>(fv->idx())];
    faces.push_back(t);
  }
  const auto nf = static_cast<Eigen::Index>(faces.size());
  result.coarse.triangles.resize(nf, 3);
  for (Eigen::Index f = 0; f < nf; ++f) {
    for (int k = 0; k < 3; ++k) result.coarse.triangles(f, k) = faces[static_cast<size_t>(f)][static_cast<size_t>(k)];
  }
  const std::int32_t kept_count = static_cast<std::int32_t>(kept.size());

  // Safety net: two triangles folded onto each other (same three corners, both orientations)
  // would give their edges four faces. OpenMesh's link-condition check should never make one;
  // if it does, both faces are removed, which restores two faces per edge.
  {
    std::vector<std::pair<std::array<std::int32_t, 3>, std::int32_t>> keyed;
    for (Eigen::Index f = 0; f < nf; ++f) {
      std::array<std::int32_t, 3> k{result.coarse.triangles(f, 0), result.coarse.triangles(f, 1), result.coarse.triangles(f, 2)};
      std::sort(k.begin(), k.end());
      keyed.push_back({k, static_cast<std::int32_t>(f)});
    }
    std::sort(keyed.begin(), keyed.end());
    std::vector<char> drop(static_cast<size_t>(nf), 0);
    for (size_t i = 0; i < keyed.size();) {
      size_t j = i;
      while (j < keyed.size() && keyed[j].first == keyed[i].first) ++j;
      if (j - i == 2) {
        drop[static_cast<size_t>(keyed[i].second)] = 1;
        drop[static_cast<size_t>(keyed[i + 1].second)] = 1;
        result.removed_folded_faces += 2;
      }
      i = j;
    }
    if (result.removed_folded_faces > 0) {
      Triangles kept_faces(nf - result.removed_folded_faces, 3);
      Eigen::Index out_f = 0;
      std::vector<std::int32_t> used(static_cast<size_t>(kept_count), -1);
      for (Eigen::Index f = 0; f < nf; ++f) {
        if (drop[static_cast<size_t>(f)]) continue;
        kept_faces.row(out_f++) = result.coarse.triangles.row(f);
        for (int k = 0; k < 3; ++k) used[static_cast<size_t>(result.coarse.triangles(f, k))] = 0;
      }
      std::int32_t n_used = 0;
      std::vector<std::int32_t> coarse_to_fine;
      for (std::int32_t c = 0; c < kept_count; ++c) {
        if (used[static_cast<size_t>(c)] == 0) {
          used[static_cast<size_t>(c)] = n_used++;
          coarse_to_fine.push_back(result.coarse_to_fine[static_cast<size_t>(c)]);
        }
      }
      Vertices verts(n_used, 3);
      for (std::int32_t c = 0; c < n_used; ++c) verts.row(c) = fine.vertices.row(coarse_to_fine[static_cast<size_t>(c)]);
      for (Eigen::Index f = 0; f < kept_faces.rows(); ++f) {
        for (int k = 0; k < 3; ++k) kept_faces(f, k) = used[static_cast<size_t>(kept_faces(f, k))];
      }
      result.coarse.vertices = std::move(verts);
      result.coarse.triangles = std::move(kept_faces);
      result.coarse_to_fine = std::move(coarse_to_fine);
    }
  }

  // The decimated surface must still be one closed, manifold, consistently oriented solid.
  SurfaceMesh check = result.coarse;
  ValidateOptions strict;
  strict.weld_tolerance = 0.0;
  const SurfaceReport report = validateSurface(check, strict);
  if (!report.ok() || report.reoriented_faces != 0 || report.flipped_inside_out || report.removed_degenerate_faces != 0 ||
      report.removed_duplicate_faces != 0 || report.welded_vertices != 0) {
    throw RigBuildError("decimation to " + std::to_string(target_vertices) + " vertices broke the surface (" +
                        report.summary() + (report.ok() ? "" : ": " + report.refusals.front()) +
                        "): try a different vertex target");
  }
  measure();
  return result;
}

DecimationResult decimateSurface(const SurfaceMesh& fine, const DecimateOptions& options) {
  SurfaceDecimator decimator(fine, options);
  return decimator.decimateTo(options.target_vertices);
}

}  // namespace tetrig::rigbuild
