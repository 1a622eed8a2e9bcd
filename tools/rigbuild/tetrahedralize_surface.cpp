// Face-constrained Delaunay tetrahedralization through TetGen 1.5 (H. Si, "TetGen, a
// Delaunay-based quality tetrahedral mesh generator", ACM TOMS 41(2), 2015), switches "pq2.0QY"
// by default, with the tet-vertex budget shared between the decimated surface and TetGen's
// interior points.
// TetGen is AGPL-3: this translation unit is part of the offline tools only.
#include "tetrig/rigbuild/tetrahedralize_surface.hpp"

#include "tetrig/rigbuild/repair_self_intersections.hpp"
#include "tetrig/rigbuild/run_in_child_process.hpp"

#include <tetgen.h>

#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <sstream>
#include <vector>

namespace tetrig::rigbuild {
namespace {

constexpr double kBudgetTolerance = 0.03;  // accepted excess of tet vertices over the budget
constexpr int kBudgetRounds = 5;           // decimate-and-tetrahedralize rounds to meet the budget

std::string tetgenCodeMeaning(int code) {
  switch (code) {
    case 1: return "out of memory";
    case 2: return "internal error in TetGen";
    case 3: return "the surface intersects itself (self-intersection)";
    case 4: return "a very small input feature (nearly coincident vertices or edges)";
    case 5: return "two input faces are very close to each other";
    case 10: return "input error (invalid facets)";
    default: return "unknown TetGen error";
  }
}

// TetGen's raw output, as read back from the child process.
struct TetgenOutput {
  int error_code = 0;  // TetGen's thrown code, 0 on success
  int corners = 4;
  int first_number = 0;
  std::vector<double> points;
  std::vector<int> tets;
  std::vector<int> trifaces;  // with switch 'd': the faces found intersecting (3 ints each)
};

// Runs tetrahedralize() in a forked child (runInChildProcess). TetGen 1.5.0 frees its memory
// pools twice when it throws an error code (terminatetetgen() frees them and the unwound
// tetgenmesh destructor frees them again), which crashes the process on exactly the inputs we
// must refuse politely (self-intersections). The child isolates that: a crash becomes an error
// message here. TetGen's printf output is captured into `tetgen_text`.
TetgenOutput runTetgenIsolated(tetgenio& in, const std::string& switch_text, std::string& tetgen_text,
                               int& signal_number) {
  const ChildOutcome child = runInChildProcess(
      [&](int fd) {
        std::vector<char> switches(switch_text.begin(), switch_text.end());
        switches.push_back('\0');
        tetgenio* out = new tetgenio;  // never freed: the child ends with _exit
        int header[6] = {0, 0, 0, 4, 0, 0};
        try {
          tetrahedralize(switches.data(), &in, out);
        } catch (int code) {
          header[0] = code == 0 ? -1 : code;
        } catch (...) {
          header[0] = -2;
        }
        if (header[0] == 0) {
          header[1] = out->pointlist != nullptr ? out->numberofpoints : 0;
          header[2] = out->tetrahedronlist != nullptr ? out->numberoftetrahedra : 0;
          header[3] = out->numberofcorners;
          header[4] = out->firstnumber;
          header[5] = out->trifacelist != nullptr ? out->numberoftrifaces : 0;
        }
        bool ok = writeAllToFd(fd, header, sizeof(header));
        if (ok && header[0] == 0) {
          ok = writeAllToFd(fd, out->pointlist, sizeof(REAL) * 3 * static_cast<size_t>(header[1])) &&
               writeAllToFd(fd, out->tetrahedronlist, sizeof(int) * static_cast<size_t>(header[3]) * static_cast<size_t>(header[2])) &&
               writeAllToFd(fd, out->trifacelist, sizeof(int) * 3 * static_cast<size_t>(header[5]));
        }
        return ok;
      },
      {}, /*capture_stdout=*/true);
  signal_number = child.exited ? 0 : child.signal_number;
  tetgen_text = child.log;
  TetgenOutput result;
  const std::vector<std::uint8_t>& bytes = child.output;
  int header[6] = {0, 0, 0, 0, 0, 0};
  bool complete = bytes.size() >= sizeof(header);
  if (complete) {
    std::memcpy(header, bytes.data(), sizeof(header));
    result.error_code = header[0];
    result.corners = header[3];
    result.first_number = header[4];
    if (header[0] == 0 && header[1] >= 0 && header[2] >= 0 && header[3] >= 4 && header[3] <= 10 && header[5] >= 0) {
      const size_t points = static_cast<size_t>(header[1]) * 3;
      const size_t tets = static_cast<size_t>(header[2]) * static_cast<size_t>(header[3]);
      const size_t trifaces = static_cast<size_t>(header[5]) * 3;
      complete = bytes.size() == sizeof(header) + points * sizeof(double) + (tets + trifaces) * sizeof(int);
      if (complete) {
        const std::uint8_t* p = bytes.data() + sizeof(header);
        result.points.resize(points);
        result.tets.resize(tets);
        result.trifaces.resize(trifaces);
        // An empty part has a null data(): memcpy may not be given one, even for 0 bytes.
        if (points != 0) std::memcpy(result.points.data(), p, points * sizeof(double));
        p += points * sizeof(double);
        if (tets != 0) std::memcpy(result.tets.data(), p, tets * sizeof(int));
        p += tets * sizeof(int);
        if (trifaces != 0) std::memcpy(result.trifaces.data(), p, trifaces * sizeof(int));
      }
    } else if (header[0] == 0) {
      complete = false;
    }
  }
  if (!complete && result.error_code == 0) result.error_code = -3;  // crashed or truncated
  return result;
}

// The last non-empty line TetGen printed (its error messages end up there).
std::string lastLine(const std::string& text) {
  std::string line;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) {
    if (l.find_first_not_of(" \t\r") != std::string::npos) line = l;
  }
  return line;
}

// Fills a TetGen PLC (points + one triangle facet per face); tetgenio's destructor frees it.
void fillTetgenInput(const SurfaceMesh& coarse, tetgenio& in) {
  const std::int32_t nv = coarse.vertexCount();
  const std::int32_t nf = coarse.triangleCount();
  // tetgenio's destructor frees these with delete[].
  in.firstnumber = 0;
  in.numberofpoints = nv;
  in.pointlist = new REAL[static_cast<size_t>(nv) * 3];
  for (std::int32_t v = 0; v < nv; ++v) {
    for (int c = 0; c < 3; ++c) in.pointlist[static_cast<size_t>(v) * 3 + static_cast<size_t>(c)] = coarse.vertices(v, c);
  }
  in.numberoffacets = nf;
  in.facetlist = new tetgenio::facet[static_cast<size_t>(nf)];
  for (std::int32_t f = 0; f < nf; ++f) {
    tetgenio::facet& facet = in.facetlist[f];
    tetgenio::init(&facet);
    facet.numberofpolygons = 1;
    facet.polygonlist = new tetgenio::polygon[1];
    tetgenio::init(&facet.polygonlist[0]);
    facet.polygonlist[0].numberofvertices = 3;
    facet.polygonlist[0].vertexlist = new int[3];
    for (int k = 0; k < 3; ++k) facet.polygonlist[0].vertexlist[k] = coarse.triangles(f, k);
  }

}

}  // namespace

std::vector<std::int32_t> findSelfIntersections(const SurfaceMesh& surface) {
  tetgenio in;
  fillTetgenInput(surface, in);
  std::string tetgen_text;
  int signal_number = 0;
  const TetgenOutput out = runTetgenIsolated(in, "pdQ", tetgen_text, signal_number);
  if (out.error_code != 0) {
    throw RigBuildError("TetGen's self-intersection check failed (" +
                        (signal_number != 0 ? "signal " + std::to_string(signal_number) : "code " + std::to_string(out.error_code)) +
                        ")");
  }
  // Map the reported corner triples back to face indices.
  std::vector<std::pair<std::array<std::int32_t, 3>, std::int32_t>> keyed;
  keyed.reserve(static_cast<size_t>(surface.triangleCount()));
  for (std::int32_t f = 0; f < surface.triangleCount(); ++f) {
    std::array<std::int32_t, 3> k{surface.triangles(f, 0), surface.triangles(f, 1), surface.triangles(f, 2)};
    std::sort(k.begin(), k.end());
    keyed.push_back({k, f});
  }
  std::sort(keyed.begin(), keyed.end());
  std::vector<std::int32_t> faces;
  for (size_t i = 0; i + 2 < out.trifaces.size(); i += 3) {
    std::array<std::int32_t, 3> k{out.trifaces[i], out.trifaces[i + 1], out.trifaces[i + 2]};
    for (auto& c : k) c -= out.first_number;
    std::sort(k.begin(), k.end());
    const auto it = std::lower_bound(keyed.begin(), keyed.end(), std::make_pair(k, std::int32_t{-1}));
    if (it != keyed.end() && it->first == k) faces.push_back(it->second);
  }
  std::sort(faces.begin(), faces.end());
  faces.erase(std::unique(faces.begin(), faces.end()), faces.end());
  return faces;
}

TetrahedralizeResult tetrahedralizeSurface(const SurfaceMesh& coarse, const TetrahedralizeOptions& options) {
  const std::int32_t nv = coarse.vertexCount();
  const std::int32_t nf = coarse.triangleCount();
  if (nv < 4 || nf < 4) {
    throw RigBuildError("tetrahedralization needs a closed surface with at least 4 vertices and 4 faces, got " +
                        std::to_string(nv) + " and " + std::to_string(nf));
  }
  tetgenio in;
  fillTetgenInput(coarse, in);

  std::string tetgen_text;
  int signal_number = 0;
  const TetgenOutput out = runTetgenIsolated(in, options.switches, tetgen_text, signal_number);
  if (out.error_code > 0) {
    throw RigBuildError("TetGen refused the surface (code " + std::to_string(out.error_code) + ": " +
                        tetgenCodeMeaning(out.error_code) + "); repair the input mesh or change the decimation target");
  }
  if (out.error_code < 0) {
    const std::string said = lastLine(tetgen_text);
    const bool intersects = tetgen_text.find("intersect") != std::string::npos;
    throw RigBuildError(std::string("TetGen failed on the surface (") +
                        (signal_number != 0 ? "crashed with signal " + std::to_string(signal_number)
                                            : std::string("no result")) +
                        (said.empty() ? std::string() : ", last message: '" + said + "'") + ")" +
                        (intersects ? ": the surface intersects itself" : std::string()) +
                        "; TetGen 1.5.0 crashes while reporting input errors, most often self-intersections: "
                        "repair the input mesh or change the decimation target");
  }
  const int n_points = static_cast<int>(out.points.size() / 3);
  const int n_corners = out.corners;
  const int n_tets = n_corners > 0 ? static_cast<int>(out.tets.size() / static_cast<size_t>(n_corners)) : 0;
  if (n_points < nv || n_tets <= 0) {
    throw RigBuildError("TetGen produced no tetrahedra (" + std::to_string(n_tets) +
                        "): the surface is probably not closed");
  }

  TetrahedralizeResult result;
  result.mesh.vertices.resize(n_points, 3);
  for (int v = 0; v < n_points; ++v) {
    for (int c = 0; c < 3; ++c) result.mesh.vertices(v, c) = out.points[static_cast<size_t>(v) * 3 + static_cast<size_t>(c)];
  }
  // TetGen keeps the input points first and in order; make sure before relying on it.
  for (std::int32_t v = 0; v < nv; ++v) {
    if (result.mesh.vertices.row(v) != coarse.vertices.row(v)) {
      throw RigBuildError("TetGen moved or reordered input vertex " + std::to_string(v) +
                          " (unexpected with switches '" + options.switches + "')");
    }
  }
  result.tet_to_coarse.resize(static_cast<size_t>(n_points), -1);
  for (std::int32_t v = 0; v < nv; ++v) result.tet_to_coarse[static_cast<size_t>(v)] = v;
  result.interior_vertices = n_points - nv;

  const int base = out.first_number;
  result.mesh.tets.resize(n_tets, 4);
  for (int t = 0; t < n_tets; ++t) {
    for (int k = 0; k < 4; ++k) {
      const int v = out.tets[static_cast<size_t>(t) * static_cast<size_t>(n_corners) + static_cast<size_t>(k)] - base;
      if (v < 0 || v >= n_points) throw RigBuildError("TetGen returned an out-of-range tet corner");
      result.mesh.tets(t, k) = v;
    }
    if (signedVolume(result.mesh, t) < 0.0) {
      std::swap(result.mesh.tets(t, 2), result.mesh.tets(t, 3));
      ++result.flipped_tets;
    }
  }
  const TetMeshReport report = checkTetMesh(result.mesh);
  if (!report.ok()) {
    throw RigBuildError("TetGen's tet mesh failed the check: " + report.summary() +
                        "; change the decimation target or repair the surface");
  }
  return result;
}

void extendSelectionInward(const TetMesh& mesh, const std::vector<std::uint8_t>& is_surface, std::vector<std::uint8_t>& mask) {
  const auto nv = static_cast<std::size_t>(mesh.vertexCount());
  if (is_surface.size() != nv || mask.size() != nv) throw RigBuildError("extendSelectionInward: size mismatch");
  // Tet-edge neighbours (CSR).
  std::vector<std::pair<std::int32_t, std::int32_t>> edges;
  edges.reserve(static_cast<std::size_t>(mesh.tetCount()) * 12);
  for (std::int32_t t = 0; t < mesh.tetCount(); ++t) {
    for (int i = 0; i < 4; ++i) {
      for (int j = 0; j < 4; ++j) {
        if (i != j) edges.emplace_back(mesh.tets(t, i), mesh.tets(t, j));
      }
    }
  }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  std::vector<std::size_t> start(nv + 1, 0);
  for (const auto& e : edges) ++start[static_cast<std::size_t>(e.first) + 1];
  for (std::size_t v = 0; v < nv; ++v) start[v + 1] += start[v];
  // (b) The fourth corner of a tet standing on three selected surface vertices.
  for (std::int32_t t = 0; t < mesh.tetCount(); ++t) {
    int selected_surface = 0;
    std::int32_t apex = -1;
    for (int k = 0; k < 4; ++k) {
      const auto v = static_cast<std::size_t>(mesh.tets(t, k));
      if (is_surface[v]) {
        selected_surface += mask[v] ? 1 : 0;
      } else {
        apex = mesh.tets(t, k);
      }
    }
    if (selected_surface == 3 && apex >= 0) mask[static_cast<std::size_t>(apex)] = 2;  // 2: joins, marked apart for now
  }
  // (a) The largest set of interior vertices whose neighbours are all selected or in the set.
  std::vector<std::uint8_t> in = mask;
  std::vector<std::int32_t> queue;
  for (std::size_t v = 0; v < nv; ++v) {
    if (!is_surface[v]) in[v] = 1;
  }
  // Remove interior vertices with an unselected neighbour, and propagate.
  for (std::size_t v = 0; v < nv; ++v) {
    if (!in[v]) queue.push_back(static_cast<std::int32_t>(v));
  }
  while (!queue.empty()) {
    const auto u = static_cast<std::size_t>(queue.back());
    queue.pop_back();
    for (std::size_t k = start[u]; k < start[u + 1]; ++k) {
      const auto w = static_cast<std::size_t>(edges[k].second);
      if (!is_surface[w] && in[w] && !mask[w]) {
        in[w] = 0;
        queue.push_back(static_cast<std::int32_t>(w));
      }
    }
  }
  for (std::size_t v = 0; v < nv; ++v) {
    if (!is_surface[v] && in[v]) mask[v] = 1;
    if (mask[v] == 2) mask[v] = 1;
  }
}

CoarseRig buildCoarseTetMesh(const SurfaceMesh& fine, const DecimateOptions& decimate,
                             const TetrahedralizeOptions& tetrahedralize, int retries,
                             const SelfIntersectionOptions& intersections) {
  CoarseRig rig;
  const double base = decimate.target_vertices;
  for (int attempt = 0; attempt <= std::max(0, retries); ++attempt) {
    // 0, +3 %, -3 %, +6 %, -6 %, ...
    const int step = (attempt + 1) / 2;
    const double sign = attempt % 2 == 1 ? 1.0 : -1.0;
    const auto total_target = static_cast<std::int32_t>(std::lround(base * (1.0 + sign * 0.03 * step)));
    std::int32_t surface_target = total_target;
    try {
      if (total_target < 4) throw RigBuildError("a tet-vertex budget of " + std::to_string(total_target) + " is below 4");
      SurfaceDecimator decimator(fine, decimate);
      for (int round = 1;; ++round) {
        rig.decimation = decimator.decimateTo(surface_target);
        rig.repair = repairSelfIntersections(rig.decimation.coarse, intersections);
        if (!rig.repair.repaired()) {
          throw RigBuildError(std::to_string(rig.repair.remaining_faces) + " of the decimated surface's faces still intersect "
                              "after " + std::to_string(rig.repair.rounds) + " smoothing rounds (" +
                              std::to_string(rig.repair.initial_faces) + " before)");
        }
        rig.tets = tetrahedralizeSurface(rig.decimation.coarse, tetrahedralize);
        rig.budget_rounds = round;
        const std::int32_t total = rig.tets.mesh.vertexCount();
        if (total <= std::lround(total_target * (1.0 + kBudgetTolerance)) || round >= kBudgetRounds) break;
        // TetGen's interior points took part of the budget: shrink the surface's share by the
        // ratio found (the interior grows with the surface, so a few rounds settle it).
        const auto next = static_cast<std::int32_t>(std::lround(static_cast<double>(surface_target) * total_target / total));
        const std::int32_t kept = rig.decimation.coarse.vertexCount();
        surface_target = std::max<std::int32_t>(4, std::min(next, std::min(surface_target, kept) - 1));
      }
      rig.used_target = total_target;
      rig.surface_target = surface_target;
      rig.tet_to_fine.assign(rig.tets.tet_to_coarse.size(), -1);
      for (size_t v = 0; v < rig.tet_to_fine.size(); ++v) {
        const std::int32_t c = rig.tets.tet_to_coarse[v];
        if (c >= 0) rig.tet_to_fine[v] = rig.decimation.coarse_to_fine[static_cast<size_t>(c)];
      }
      return rig;
    } catch (const RigBuildError& e) {
      rig.failed_attempts.push_back("target " + std::to_string(total_target) + " (surface " + std::to_string(surface_target) + "): " + e.what());
      if (fine.vertexCount() <= surface_target && attempt > 0) break;  // no decimation to vary
    }
  }
  std::ostringstream msg;
  msg << "could not build a tet mesh after " << rig.failed_attempts.size() << " attempts (";
  for (size_t i = 0; i < rig.failed_attempts.size(); ++i) msg << (i ? " | " : "") << rig.failed_attempts[i];
  msg << "); the surface probably intersects itself or has parts thinner than the decimated triangles: repair "
         "self-intersections in a mesh editor or choose a larger vertex budget";
  throw TetBudgetError(msg.str());
}

}  // namespace tetrig::rigbuild
