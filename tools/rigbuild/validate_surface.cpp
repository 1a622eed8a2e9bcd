// Surface validation and safe repair: welding, removal of degenerate/duplicate faces and unused
// vertices, connected components (union-find over vertices), edge manifoldness (sorted half-edge
// list), vertex manifoldness (union-find of face corners across manifold edges), consistent
// orientation (breadth-first flood fill across manifold edges) and outward orientation (signed
// volume by the divergence theorem).
#include "tetrig/rigbuild/validate_surface.hpp"

#include "tetrig/rigbuild/weld_vertices.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <queue>
#include <sstream>

namespace tetrig::rigbuild {
namespace {

class UnionFind {
 public:
  explicit UnionFind(size_t n) : parent_(n) { std::iota(parent_.begin(), parent_.end(), 0u); }
  std::uint32_t find(std::uint32_t a) {
    while (parent_[a] != a) {
      parent_[a] = parent_[parent_[a]];
      a = parent_[a];
    }
    return a;
  }
  void unite(std::uint32_t a, std::uint32_t b) {
    a = find(a);
    b = find(b);
    if (a != b) parent_[std::max(a, b)] = std::min(a, b);
  }

 private:
  std::vector<std::uint32_t> parent_;
};

struct HalfEdge {
  std::uint64_t key;   // (min << 32) | max
  std::int32_t face;
  std::int8_t corner;  // the edge runs from corner k to corner (k+1)%3 of the face
  bool forward;        // true when it runs min -> max
};

std::vector<HalfEdge> sortedHalfEdges(const SurfaceMesh& mesh) {
  std::vector<HalfEdge> h;
  h.reserve(static_cast<size_t>(mesh.triangleCount()) * 3);
  for (std::int32_t f = 0; f < mesh.triangleCount(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const auto a = static_cast<std::uint32_t>(mesh.triangles(f, k));
      const auto b = static_cast<std::uint32_t>(mesh.triangles(f, (k + 1) % 3));
      const std::uint64_t lo = std::min(a, b);
      const std::uint64_t hi = std::max(a, b);
      h.push_back({(lo << 32) | hi, f, static_cast<std::int8_t>(k), a < b});
    }
  }
  std::sort(h.begin(), h.end(), [](const HalfEdge& x, const HalfEdge& y) {
    return x.key != y.key ? x.key < y.key : x.face < y.face;
  });
  return h;
}

// Keeps the faces with keep[f] and the vertices they use (order preserved); returns old vertex ->
// new vertex (-1 when removed).
std::vector<std::int32_t> compact(SurfaceMesh& mesh, const std::vector<char>& keep_face) {
  std::int32_t nf = 0;
  for (std::int32_t f = 0; f < mesh.triangleCount(); ++f) {
    if (keep_face[static_cast<size_t>(f)]) mesh.triangles.row(nf++) = mesh.triangles.row(f);
  }
  mesh.triangles.conservativeResize(nf, 3);
  std::vector<std::int32_t> index(static_cast<size_t>(mesh.vertexCount()), -1);
  for (std::int32_t f = 0; f < nf; ++f) {
    for (int k = 0; k < 3; ++k) index[static_cast<size_t>(mesh.triangles(f, k))] = 0;
  }
  std::int32_t nv = 0;
  for (std::int32_t v = 0; v < mesh.vertexCount(); ++v) {
    if (index[static_cast<size_t>(v)] == 0) {
      index[static_cast<size_t>(v)] = nv;
      mesh.vertices.row(nv++) = mesh.vertices.row(v);
    }
  }
  mesh.vertices.conservativeResize(nv, 3);
  for (std::int32_t f = 0; f < nf; ++f) {
    for (int k = 0; k < 3; ++k) mesh.triangles(f, k) = index[static_cast<size_t>(mesh.triangles(f, k))];
  }
  return index;
}

// map[i] = step[map[i]] (removed stays removed).
void composeMap(std::vector<std::int32_t>& map, const std::vector<std::int32_t>& step) {
  for (std::int32_t& m : map) m = m >= 0 ? step[static_cast<size_t>(m)] : -1;
}

void flipFace(SurfaceMesh& mesh, std::int32_t f) { std::swap(mesh.triangles(f, 1), mesh.triangles(f, 2)); }

}  // namespace

SurfaceTopology surfaceTopology(const SurfaceMesh& mesh) {
  SurfaceTopology topo;
  const std::vector<HalfEdge> h = sortedHalfEdges(mesh);
  for (size_t i = 0; i < h.size();) {
    size_t j = i;
    while (j < h.size() && h[j].key == h[i].key) ++j;
    ++topo.edges;
    if (j - i == 1) {
      ++topo.boundary_edges;
    } else if (j - i > 2) {
      ++topo.non_manifold_edges;
    } else if (h[i].forward == h[i + 1].forward) {
      ++topo.inconsistent_edges;
    }
    i = j;
  }
  return topo;
}

namespace {

// Refuses a mesh with a non-finite coordinate or a corner naming no vertex; true when it did.
bool refuseCorruptInput(const SurfaceMesh& mesh, SurfaceReport& r) {
  for (std::int32_t v = 0; v < mesh.vertexCount(); ++v) {
    if (!mesh.vertices.row(v).allFinite()) ++r.non_finite_vertices;
  }
  if (r.non_finite_vertices > 0) {
    r.refusals.push_back(std::to_string(r.non_finite_vertices) +
                         " vertices have NaN or infinite coordinates: fix or re-export the mesh");
    return true;
  }
  for (std::int32_t f = 0; f < mesh.triangleCount(); ++f) {
    for (int k = 0; k < 3; ++k) {
      if (mesh.triangles(f, k) < 0 || mesh.triangles(f, k) >= mesh.vertexCount()) {
        r.refusals.push_back("face " + std::to_string(f) + " references vertex " + std::to_string(mesh.triangles(f, k)) +
                             ", which does not exist (" + std::to_string(mesh.vertexCount()) +
                             " vertices): the mesh is corrupt");
        return true;
      }
    }
  }
  return false;
}

// The faces to keep: not those with a repeated corner, nor a second face with the same corner set.
std::vector<char> facesToKeep(const SurfaceMesh& mesh, SurfaceReport& r) {
  std::vector<char> keep(static_cast<size_t>(mesh.triangleCount()), 1);
  for (std::int32_t f = 0; f < mesh.triangleCount(); ++f) {
    const auto t = mesh.triangles.row(f);
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) {
      keep[static_cast<size_t>(f)] = 0;
      ++r.removed_degenerate_faces;
    }
  }
  std::vector<std::pair<std::array<std::int32_t, 3>, std::int32_t>> sorted_faces;
  sorted_faces.reserve(static_cast<size_t>(mesh.triangleCount()));
  for (std::int32_t f = 0; f < mesh.triangleCount(); ++f) {
    if (!keep[static_cast<size_t>(f)]) continue;
    std::array<std::int32_t, 3> c{mesh.triangles(f, 0), mesh.triangles(f, 1), mesh.triangles(f, 2)};
    std::sort(c.begin(), c.end());
    sorted_faces.push_back({c, f});
  }
  std::sort(sorted_faces.begin(), sorted_faces.end());
  for (size_t i = 1; i < sorted_faces.size(); ++i) {
    if (sorted_faces[i].first == sorted_faces[i - 1].first) {
      keep[static_cast<size_t>(sorted_faces[i].second)] = 0;
      ++r.removed_duplicate_faces;
    }
  }
  return keep;
}

// Counts the connected components (faces sharing a vertex are connected); keeps the largest or
// refuses several.
void checkComponents(SurfaceMesh& mesh, SurfaceReport& r, const ValidateOptions& options) {
  UnionFind uf(static_cast<size_t>(mesh.vertexCount()));
  for (std::int32_t f = 0; f < mesh.triangleCount(); ++f) {
    uf.unite(static_cast<std::uint32_t>(mesh.triangles(f, 0)), static_cast<std::uint32_t>(mesh.triangles(f, 1)));
    uf.unite(static_cast<std::uint32_t>(mesh.triangles(f, 0)), static_cast<std::uint32_t>(mesh.triangles(f, 2)));
  }
  std::vector<std::int32_t> faces_of_root(static_cast<size_t>(mesh.vertexCount()), 0);
  for (std::int32_t f = 0; f < mesh.triangleCount(); ++f) {
    ++faces_of_root[uf.find(static_cast<std::uint32_t>(mesh.triangles(f, 0)))];
  }
  std::vector<std::pair<std::int32_t, std::uint32_t>> comps;  // (faces, root)
  for (std::int32_t v = 0; v < mesh.vertexCount(); ++v) {
    if (faces_of_root[static_cast<size_t>(v)] > 0) comps.push_back({faces_of_root[static_cast<size_t>(v)], static_cast<std::uint32_t>(v)});
  }
  std::sort(comps.begin(), comps.end(), std::greater<>());
  r.components = static_cast<std::int32_t>(comps.size());
  if (comps.size() > 1) {
    if (options.keep_largest_component) {
      std::vector<char> keep_largest(static_cast<size_t>(mesh.triangleCount()), 1);
      for (std::int32_t f = 0; f < mesh.triangleCount(); ++f) {
        if (uf.find(static_cast<std::uint32_t>(mesh.triangles(f, 0))) != comps[0].second) {
          keep_largest[static_cast<size_t>(f)] = 0;
          ++r.dropped_component_faces;
        }
      }
      r.dropped_components = r.components - 1;
      r.components = 1;
      composeMap(r.vertex_map, compact(mesh, keep_largest));
    } else {
      std::ostringstream s;
      s << "the surface has " << comps.size() << " separate components (faces per component: ";
      for (size_t i = 0; i < std::min<size_t>(comps.size(), 5); ++i) s << (i ? ", " : "") << comps[i].first;
      if (comps.size() > 5) s << ", ...";
      s << "): a rig needs one closed surface; join the parts into one watertight mesh (boolean union) "
           "or allow dropping all but the largest (keep_largest_component)";
      r.refusals.push_back(s.str());
    }
  }
}

// Counts the edges, boundary and non-manifold ones; the manifold edges' half-edge pairs go to
// adjacency_pairs. Returns the edge count.
std::int64_t classifyEdges(const std::vector<HalfEdge>& h, SurfaceReport& r, std::vector<std::pair<std::int32_t, std::int32_t>>& adjacency_pairs) {
  std::int64_t edge_count = 0;
  for (size_t i = 0; i < h.size();) {
    size_t j = i;
    while (j < h.size() && h[j].key == h[i].key) ++j;
    ++edge_count;
    if (j - i == 1) {
      ++r.boundary_edges;
    } else if (j - i > 2) {
      ++r.non_manifold_edges;
    } else {
      adjacency_pairs.push_back({static_cast<std::int32_t>(i), static_cast<std::int32_t>(i + 1)});
    }
    i = j;
  }
  return edge_count;
}

// Counts the vertices whose corners form more than one fan across manifold edges.
void countNonManifoldVertices(const SurfaceMesh& mesh, const std::vector<HalfEdge>& h, const std::vector<std::pair<std::int32_t, std::int32_t>>& adjacency_pairs,
                              SurfaceReport& r) {
  const auto nf = static_cast<size_t>(mesh.triangleCount());
  UnionFind corners(nf * 3);
  auto cornerOf = [&mesh](std::int32_t f, std::int32_t v) {
    for (std::uint32_t k = 0; k < 3; ++k) {
      if (mesh.triangles(f, k) == v) return static_cast<std::uint32_t>(f) * 3u + k;
    }
    return static_cast<std::uint32_t>(f) * 3u;
  };
  for (const auto& [i, j] : adjacency_pairs) {
    const HalfEdge& a = h[static_cast<size_t>(i)];
    const HalfEdge& b = h[static_cast<size_t>(j)];
    const auto v0 = static_cast<std::int32_t>(a.key >> 32);
    const auto v1 = static_cast<std::int32_t>(a.key & 0xffffffffu);
    corners.unite(cornerOf(a.face, v0), cornerOf(b.face, v0));
    corners.unite(cornerOf(a.face, v1), cornerOf(b.face, v1));
  }
  std::vector<std::int64_t> root_of_vertex(static_cast<size_t>(mesh.vertexCount()), -1);
  std::vector<char> counted(static_cast<size_t>(mesh.vertexCount()), 0);
  for (std::int32_t f = 0; f < mesh.triangleCount(); ++f) {
    for (std::uint32_t k = 0; k < 3; ++k) {
      const auto v = static_cast<size_t>(mesh.triangles(f, k));
      const std::int64_t root = corners.find(static_cast<std::uint32_t>(f) * 3u + k);
      if (root_of_vertex[v] < 0) {
        root_of_vertex[v] = root;
      } else if (root_of_vertex[v] != root && !counted[v]) {
        counted[v] = 1;
        ++r.non_manifold_vertices;
      }
    }
  }
}

// Refuses an open surface, non-manifold edges and non-manifold vertices.
void refuseNonManifold(SurfaceReport& r) {
  if (r.boundary_edges > 0) {
    r.refusals.push_back("the surface is open: " + std::to_string(r.boundary_edges) +
                         " boundary edges (holes); close the holes (e.g. MeshLab 'Close Holes', Blender "
                         "'Fill Holes') and export a watertight mesh");
  }
  if (r.non_manifold_edges > 0) {
    r.refusals.push_back(std::to_string(r.non_manifold_edges) +
                         " non-manifold edges (shared by three or more faces): make every edge belong to exactly "
                         "two faces (e.g. MeshLab 'Repair non Manifold Edges') or remesh the surface");
  }
  if (r.non_manifold_vertices > 0) {
    r.refusals.push_back(std::to_string(r.non_manifold_vertices) +
                         " non-manifold vertices (surface parts touching at a single point): separate or merge "
                         "them (e.g. MeshLab 'Repair non Manifold Vertices')");
  }
}

// Orients each edge-connected patch consistently (its minority of faces flipped); refuses a
// non-orientable surface.
void orientConsistently(SurfaceMesh& mesh, const std::vector<HalfEdge>& h, const std::vector<std::pair<std::int32_t, std::int32_t>>& adjacency_pairs, SurfaceReport& r) {
  const auto nf = static_cast<size_t>(mesh.triangleCount());
  std::vector<std::vector<std::pair<std::int32_t, bool>>> neighbours(nf);  // (face, same direction)
  for (const auto& [i, j] : adjacency_pairs) {
    const HalfEdge& a = h[static_cast<size_t>(i)];
    const HalfEdge& b = h[static_cast<size_t>(j)];
    const bool same = a.forward == b.forward;  // consistent neighbours traverse the edge oppositely
    neighbours[static_cast<size_t>(a.face)].push_back({b.face, same});
    neighbours[static_cast<size_t>(b.face)].push_back({a.face, same});
  }
  std::vector<std::int8_t> flip(nf, -1);
  std::vector<std::int32_t> component_faces;
  for (size_t seed = 0; seed < nf; ++seed) {
    if (flip[seed] >= 0) continue;
    component_faces.clear();
    flip[seed] = 0;
    std::queue<std::int32_t> todo;
    todo.push(static_cast<std::int32_t>(seed));
    while (!todo.empty()) {
      const std::int32_t f = todo.front();
      todo.pop();
      component_faces.push_back(f);
      for (const auto& [g, same] : neighbours[static_cast<size_t>(f)]) {
        const std::int8_t want = static_cast<std::int8_t>(flip[static_cast<size_t>(f)] ^ (same ? 1 : 0));
        if (flip[static_cast<size_t>(g)] < 0) {
          flip[static_cast<size_t>(g)] = want;
          todo.push(g);
        } else if (flip[static_cast<size_t>(g)] != want) {
          r.non_orientable = true;
        }
      }
    }
    // Flip the minority within this edge-connected patch.
    const auto flips = static_cast<size_t>(std::count_if(component_faces.begin(), component_faces.end(),
                                                         [&flip](std::int32_t f) { return flip[static_cast<size_t>(f)] == 1; }));
    const bool invert = flips * 2 > component_faces.size();
    for (const std::int32_t f : component_faces) {
      if ((flip[static_cast<size_t>(f)] == 1) != invert) {
        flipFace(mesh, f);
        ++r.reoriented_faces;
      }
    }
  }
  if (r.non_orientable) {
    r.refusals.push_back("the surface is not orientable (like a Moebius strip or Klein bottle): no consistent "
                         "inside/outside exists; remesh it as a closed solid");
  }
}

// Measures the volume and, for a surface not yet refused, turns it outward (or refuses it when it
// encloses none) and computes its genus.
void orientOutward(SurfaceMesh& mesh, SurfaceReport& r, std::int64_t edge_count) {
  r.volume = signedVolume(mesh);
  const double diag3 = r.bbox_diagonal * r.bbox_diagonal * r.bbox_diagonal;
  if (r.ok()) {
    if (std::abs(r.volume) <= 1e-12 * diag3) {
      r.refusals.push_back("the surface encloses no volume (signed volume " + std::to_string(r.volume) +
                           "): it is flat or folded onto itself; a rig needs a solid");
    } else if (r.volume < 0.0) {
      for (std::int32_t f = 0; f < mesh.triangleCount(); ++f) flipFace(mesh, f);
      r.flipped_inside_out = true;
      r.volume = -r.volume;
    }
    const std::int64_t chi = mesh.vertexCount() - edge_count + mesh.triangleCount();
    r.genus = static_cast<std::int32_t>((2 - chi) / 2);
  }
}

// Counts the zero-area faces with distinct corners (reported only).
void countZeroAreaFaces(const SurfaceMesh& mesh, SurfaceReport& r, const ValidateOptions& options) {
  const double area_eps = options.zero_area_tolerance * r.bbox_diagonal * r.bbox_diagonal;
  for (std::int32_t f = 0; f < mesh.triangleCount(); ++f) {
    const Eigen::Vector3d a = mesh.vertices.row(mesh.triangles(f, 0)).transpose();
    const Eigen::Vector3d b = mesh.vertices.row(mesh.triangles(f, 1)).transpose();
    const Eigen::Vector3d c = mesh.vertices.row(mesh.triangles(f, 2)).transpose();
    if (0.5 * (b - a).cross(c - a).norm() <= area_eps) ++r.zero_area_faces;
  }
}

}  // namespace

SurfaceReport validateSurface(SurfaceMesh& mesh, const ValidateOptions& options) {
  SurfaceReport r;
  r.input_vertices = mesh.vertexCount();
  r.input_triangles = mesh.triangleCount();
  r.vertex_map.resize(static_cast<size_t>(mesh.vertexCount()));
  std::iota(r.vertex_map.begin(), r.vertex_map.end(), 0);
  auto finish = [&r, &mesh]() {
    r.vertices = mesh.vertexCount();
    r.triangles = mesh.triangleCount();
    return r;
  };

  // A non-finite coordinate or a corner naming no vertex: refused as it is.
  if (refuseCorruptInput(mesh, r)) return finish();
  r.bbox_diagonal = boundingBoxDiagonal(mesh.vertices);

  // 1. Weld duplicate vertices.
  const std::int32_t before_weld = mesh.vertexCount();
  composeMap(r.vertex_map, weldVertices(mesh, options.weld_tolerance * r.bbox_diagonal));
  r.welded_vertices = before_weld - mesh.vertexCount();

  // 2. Faces with a repeated corner, then duplicate faces (same corner set).
  const std::vector<char> keep = facesToKeep(mesh, r);
  // 3. Unused vertices go with the compaction.
  const std::int32_t before_compact = mesh.vertexCount();
  composeMap(r.vertex_map, compact(mesh, keep));
  r.removed_unused_vertices = before_compact - mesh.vertexCount();

  // 4. Connected components (faces sharing a vertex are connected).
  checkComponents(mesh, r, options);
  if (mesh.vertexCount() < 4 || mesh.triangleCount() < 4) {
    r.refusals.push_back("only " + std::to_string(mesh.vertexCount()) + " vertices and " +
                         std::to_string(mesh.triangleCount()) +
                         " usable triangles remain: a closed surface needs at least 4 and 4");
    return finish();
  }

  // 5. Edges: boundary, non-manifold; manifold edges connect faces for orientation and fans.
  const std::vector<HalfEdge> h = sortedHalfEdges(mesh);
  std::vector<std::pair<std::int32_t, std::int32_t>> adjacency_pairs;  // (half-edge i, j) of manifold edges
  const std::int64_t edge_count = classifyEdges(h, r, adjacency_pairs);
  // 6. Non-manifold vertices: corners around a vertex joined across manifold edges form fans.
  countNonManifoldVertices(mesh, h, adjacency_pairs, r);
  refuseNonManifold(r);

  // 7. Consistent orientation by flood fill across manifold edges.
  orientConsistently(mesh, h, adjacency_pairs, r);

  // 8. Outward orientation and volume.
  orientOutward(mesh, r, edge_count);

  // 9. Zero-area faces with distinct corners (reported only).
  countZeroAreaFaces(mesh, r, options);
  return finish();
}

void requireUsableSurface(const SurfaceReport& report, const std::string& what) {
  if (report.ok()) return;
  std::string message = what + ": surface refused: ";
  for (size_t i = 0; i < report.refusals.size(); ++i) message += (i ? "; " : "") + report.refusals[i];
  throw RigBuildError(message);
}

std::string SurfaceReport::summary() const {
  std::ostringstream s;
  s << vertices << " V / " << triangles << " F";
  if (genus >= 0) s << ", genus " << genus;
  s << ", volume " << volume;
  if (welded_vertices) s << ", welded " << welded_vertices << " duplicate vertices";
  if (removed_degenerate_faces) s << ", removed " << removed_degenerate_faces << " degenerate faces";
  if (removed_duplicate_faces) s << ", removed " << removed_duplicate_faces << " duplicate faces";
  if (removed_unused_vertices) s << ", removed " << removed_unused_vertices << " unused vertices";
  if (reoriented_faces) s << ", re-oriented " << reoriented_faces << " faces";
  if (flipped_inside_out) s << ", flipped inside-out surface";
  if (dropped_components) s << ", dropped " << dropped_components << " small components (" << dropped_component_faces << " faces)";
  if (zero_area_faces) s << ", " << zero_area_faces << " zero-area faces (kept)";
  if (!ok()) s << "; REFUSED (" << refusals.size() << " reasons)";
  return s.str();
}

}  // namespace tetrig::rigbuild
