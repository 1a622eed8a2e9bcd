// The rig-building pipeline behind `tetrig build-rig` (see build_rig.hpp).
#include "tetrig/rigbuild/build_rig.hpp"
#include "tetrig/rigbuild/format_number.hpp"

#include "tetrig/drivers/c3d_reader.hpp"
#include "tetrig/rigbuild/bind_markers.hpp"
#include "tetrig/tet_mesh.hpp"
#include "tetrig/rigbuild/import_surface.hpp"
#include "tetrig/rigbuild/obj_surface_attributes.hpp"
#include "tetrig/rigbuild/rigid_marker_groups.hpp"
#include "tetrig/rigbuild/tet_quality.hpp"
#include "tetrig/rigbuild/tetrahedralize_surface.hpp"
#include "tetrig/rigbuild/validate_surface.hpp"
#include "tetrig/tet_mesh_io.hpp"
#include "tetrig/version.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <sstream>
#include <unordered_map>

namespace tetrig::rigbuild {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

std::vector<std::int32_t> readSelFile(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw RigBuildError(path.string() + ": cannot open the selection file");
  std::vector<std::int32_t> out;
  std::string line;
  while (std::getline(in, line)) {
    const std::size_t hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    std::istringstream s(line);
    long v = 0;
    while (s >> v) out.push_back(static_cast<std::int32_t>(v));
    if (!s.eof()) throw RigBuildError(path.string() + ": expected one integer status per vertex, found '" + line + "'");
  }
  return out;
}

struct MarkerSet {
  std::vector<std::string> labels;
  std::vector<Eigen::Vector3d> device_mm;
};

// A clip and the points of it that become markers (markers.labels, or every labelled physical
// marker; minus markers.exclude), named without the subject prefix.
struct MarkerClip {
  std::filesystem::path path;
  drivers::C3DClip clip;
  std::vector<int> points;
  std::vector<std::string> labels;
};

MarkerClip openMarkerClip(const std::filesystem::path& clip_path, const MarkerOptions& options) {
  drivers::C3DReadOptions read;
  read.keep_zero_points = options.keep_zero_points;
  MarkerClip mc{clip_path, drivers::C3DClip::load(clip_path, read), {}, {}};
  const drivers::C3DClip& clip = mc.clip;
  if (clip.frameCount() == 0) throw RigBuildError(clip_path.string() + ": the clip has no frames");
  std::vector<std::string> wanted = options.labels;
  for (int p = 0; p < clip.pointCount(); ++p) {
    std::string label = drivers::c3dPointLabel(clip, p);
    const std::size_t colon = label.rfind(':');
    if (colon != std::string::npos) label = label.substr(colon + 1);
    if (label.empty()) label = "point" + std::to_string(p);  // a label "subject:" names the subject only
    if (!options.labels.empty()) {
      const auto it = std::find(wanted.begin(), wanted.end(), label);
      if (it == wanted.end()) continue;
      wanted.erase(it);
    } else if (clip.pointKind(p) != drivers::C3DPointKind::kMarker) {
      continue;
    }
    if (std::find(options.exclude.begin(), options.exclude.end(), label) != options.exclude.end()) continue;
    if (std::find(mc.labels.begin(), mc.labels.end(), label) != mc.labels.end()) {
      throw RigBuildError(clip_path.string() + ": two markers are labelled " + label + ": exclude one");
    }
    mc.points.push_back(p);
    mc.labels.push_back(label);
  }
  if (!wanted.empty()) throw RigBuildError(clip_path.string() + ": marker " + wanted.front() + " named in markers.labels is not in the clip");
  if (mc.labels.empty()) throw RigBuildError(clip_path.string() + ": no labelled markers to bind");
  return mc;
}

// The selected markers of `frame` in device mm; false (and the first invalid marker's index in
// *invalid) when one is not valid there.
bool markersAt(const MarkerClip& mc, std::int64_t frame, std::vector<Eigen::Vector3d>& out, std::size_t* invalid = nullptr) {
  const std::size_t f = static_cast<std::size_t>(frame);
  const float* pos = mc.clip.positions(f);
  const double k = mc.clip.unitsToMm();
  out.clear();
  for (std::size_t i = 0; i < mc.points.size(); ++i) {
    const int p = mc.points[i];
    if (!mc.clip.isValid(f, p)) {
      if (invalid) *invalid = i;
      return false;
    }
    out.emplace_back(k * pos[3 * p], k * pos[3 * p + 1], k * pos[3 * p + 2]);
  }
  return true;
}

// The performer's height as the markers show it: per frame, the extent of the valid markers
// along the device's up axis (mm); the median over frames (a crouch or a glitch moves it little).
// 0 when no frame has two valid markers.
double medianMarkerHeightMm(const MarkerClip& mc, const Eigen::Vector3d& up) {
  std::vector<double> heights;
  const double k = mc.clip.unitsToMm();
  for (std::size_t f = 0; f < mc.clip.frameCount(); ++f) {
    const float* pos = mc.clip.positions(f);
    double lo = INFINITY, hi = -INFINITY;
    int valid = 0;
    for (const int p : mc.points) {
      if (!mc.clip.isValid(f, p)) continue;
      const double h = k * (up[0] * pos[3 * p] + up[1] * pos[3 * p + 1] + up[2] * pos[3 * p + 2]);
      lo = std::min(lo, h);
      hi = std::max(hi, h);
      ++valid;
    }
    if (valid >= 2) heights.push_back(hi - lo);
  }
  if (heights.empty()) return 0.0;
  std::nth_element(heights.begin(), heights.begin() + static_cast<std::ptrdiff_t>(heights.size() / 2), heights.end());
  return heights[heights.size() / 2];
}

MarkerSet readMarkers(const MarkerClip& mc, std::int64_t frame) {
  if (frame < 0 || static_cast<std::size_t>(frame) >= mc.clip.frameCount()) {
    throw RigBuildError(mc.path.string() + ": rest frame " + std::to_string(frame) + " is outside the clip (0.." +
                        std::to_string(mc.clip.frameCount() - 1) + ")");
  }
  MarkerSet set;
  set.labels = mc.labels;
  std::size_t invalid = 0;
  if (!markersAt(mc, frame, set.device_mm, &invalid)) {
    throw RigBuildError(mc.path.string() + ": marker " + mc.labels[invalid] + " is not valid in rest frame " + std::to_string(frame) +
                        ": choose another frame (--frame) or exclude the marker");
  }
  return set;
}

// Marker positions given directly (BuildRigInputs::marker_positions), checked.
MarkerSet checkedMarkerPositions(const MarkerPositions& given) {
  if (given.labels.empty()) throw RigBuildError(given.what + ": no markers given");
  if (given.labels.size() != given.device_mm.size()) {
    throw RigBuildError(given.what + ": " + std::to_string(given.labels.size()) + " labels but " + std::to_string(given.device_mm.size()) +
                        " positions");
  }
  for (std::size_t i = 0; i < given.labels.size(); ++i) {
    const std::string& label = given.labels[i];
    if (label.empty()) throw RigBuildError(given.what + ": marker " + std::to_string(i) + " has no label");
    if (std::find(given.labels.begin(), given.labels.begin() + static_cast<std::ptrdiff_t>(i), label) != given.labels.begin() + static_cast<std::ptrdiff_t>(i)) {
      throw RigBuildError(given.what + ": two markers are labelled " + label);
    }
    if (!given.device_mm[i].allFinite()) throw RigBuildError(given.what + ": marker " + label + " has a non-finite position");
  }
  return MarkerSet{given.labels, given.device_mm};
}

// Everything a selection can be resolved against.
struct Context {
  const TetMesh* body = nullptr;
  bool tet_input = false;
  std::vector<std::int32_t> file_to_tet;    // tet input: file vertex id -> tet vertex
  std::vector<std::int32_t> file_to_fine;   // surface input: file vertex id -> fine vertex (identity if unknown)
  std::vector<std::int32_t> fine_to_tet;    // surface input: fine vertex -> tet vertex kept by decimation, or -1
  const Vertices* fine = nullptr;
  const std::vector<std::string>* marker_labels = nullptr;
  const std::vector<Eigen::Vector3d>* marker_positions = nullptr;
};

std::int32_t nearestTetVertex(const Context& ctx, const Eigen::Vector3d& p) {
  std::int32_t best = 0;
  double best_d = std::numeric_limits<double>::infinity();
  for (std::int32_t v = 0; v < ctx.body->vertexCount(); ++v) {
    const double d = (ctx.body->vertices.row(v).transpose() - p).squaredNorm();
    if (d < best_d) {
      best_d = d;
      best = v;
    }
  }
  return best;
}

// The tet vertices a selection names (as a mask); none is an error unless may_be_empty.
std::vector<std::uint8_t> resolveVertices(const Context& ctx, const Selection& s, const std::string& what, bool may_be_empty = false) {
  const std::int32_t nv = ctx.body->vertexCount();
  std::vector<std::uint8_t> mask(static_cast<std::size_t>(nv), 0);
  auto inside = [&](auto pred) {
    for (std::int32_t v = 0; v < nv; ++v) {
      if (pred(Eigen::Vector3d(ctx.body->vertices.row(v).transpose()))) mask[static_cast<std::size_t>(v)] = 1;
    }
  };
  std::vector<std::int32_t> ids;
  switch (s.kind) {
    case Selection::Kind::kVertices:
      ids = s.vertices;
      break;
    case Selection::Kind::kSelFile: {
      const std::vector<std::int32_t> status = readSelFile(s.sel_file);
      const std::size_t expected = ctx.tet_input ? ctx.file_to_tet.size() : ctx.file_to_fine.size();
      if (status.size() != expected) {
        throw RigBuildError(what + ": " + s.sel_file.string() + " has " + std::to_string(status.size()) + " statuses but the mesh file has " +
                            std::to_string(expected) + " vertices");
      }
      for (std::size_t i = 0; i < status.size(); ++i) {
        if (std::find(s.sel_values.begin(), s.sel_values.end(), status[i]) != s.sel_values.end()) ids.push_back(static_cast<std::int32_t>(i));
      }
      break;
    }
    case Selection::Kind::kBox:
      inside([&](const Eigen::Vector3d& p) { return (p.array() >= s.min.array()).all() && (p.array() <= s.max.array()).all(); });
      break;
    case Selection::Kind::kSphere:
      inside([&](const Eigen::Vector3d& p) { return (p - s.center).norm() <= s.radius; });
      break;
    case Selection::Kind::kNearMarker: {
      if (ctx.marker_labels == nullptr || ctx.marker_labels->empty()) {
        throw RigBuildError(what + ": near_marker '" + s.marker + "' needs markers (--markers CLIP.c3d)");
      }
      const auto it = std::find(ctx.marker_labels->begin(), ctx.marker_labels->end(), s.marker);
      if (it == ctx.marker_labels->end()) throw RigBuildError(what + ": no marker labelled '" + s.marker + "'");
      const Eigen::Vector3d c = (*ctx.marker_positions)[static_cast<std::size_t>(it - ctx.marker_labels->begin())];
      inside([&](const Eigen::Vector3d& p) { return (p - c).norm() <= s.radius; });
      break;
    }
  }
  if (!ids.empty() || s.kind == Selection::Kind::kVertices || s.kind == Selection::Kind::kSelFile) {
    if (ids.empty()) throw RigBuildError(what + ": the selection names no vertex");
    const std::size_t file_count = ctx.tet_input ? ctx.file_to_tet.size() : ctx.file_to_fine.size();
    std::vector<std::int32_t> unkept;
    for (const std::int32_t id : ids) {
      if (id < 0 || static_cast<std::size_t>(id) >= file_count) {
        throw RigBuildError(what + ": vertex id " + std::to_string(id) + " is out of range (the mesh file has " + std::to_string(file_count) +
                            " vertices)");
      }
      if (ctx.tet_input) {
        const std::int32_t t = ctx.file_to_tet[static_cast<std::size_t>(id)];
        if (t >= 0) mask[static_cast<std::size_t>(t)] = 1;
      } else {
        const std::int32_t f = ctx.file_to_fine[static_cast<std::size_t>(id)];
        const std::int32_t t = f >= 0 ? ctx.fine_to_tet[static_cast<std::size_t>(f)] : -1;
        if (t >= 0) {
          mask[static_cast<std::size_t>(t)] = 1;
        } else if (f >= 0) {
          unkept.push_back(f);
        }
      }
    }
    // Decimation removed every selected vertex: take the nearest tet vertices instead.
    if (std::find(mask.begin(), mask.end(), 1) == mask.end()) {
      for (const std::int32_t f : unkept) mask[static_cast<std::size_t>(nearestTetVertex(ctx, ctx.fine->row(f).transpose()))] = 1;
    }
  }
  if (!may_be_empty && std::find(mask.begin(), mask.end(), 1) == mask.end()) {
    throw RigBuildError(what + ": the selection contains no tet vertex: enlarge it");
  }
  return mask;
}

// The body tets with at least s.min_corners corners in the selection (maybe none, if may_be_empty).
std::vector<std::int32_t> selectTets(const Context& ctx, const Selection& s, const std::string& what, bool may_be_empty) {
  std::vector<std::uint8_t> mask = resolveVertices(ctx, s, what, may_be_empty);
  // A selection of surface vertices reaches TetGen's interior points under it (extendSelectionInward).
  if (!ctx.tet_input && (s.kind == Selection::Kind::kVertices || s.kind == Selection::Kind::kSelFile)) {
    std::vector<std::uint8_t> is_surface(mask.size(), 0);
    for (const std::int32_t t : ctx.fine_to_tet) {
      if (t >= 0) is_surface[static_cast<std::size_t>(t)] = 1;
    }
    extendSelectionInward(*ctx.body, is_surface, mask);
  }
  std::vector<std::int32_t> tets;
  for (std::int32_t t = 0; t < ctx.body->tetCount(); ++t) {
    int corners = 0;
    for (int k = 0; k < 4; ++k) corners += mask[static_cast<std::size_t>(ctx.body->tets(t, k))];
    if (corners >= s.min_corners) tets.push_back(t);
  }
  return tets;
}

std::vector<std::int32_t> resolveTets(const Context& ctx, const Selection& s, const std::string& what) {
  std::vector<std::int32_t> tets = selectTets(ctx, s, what, false);
  if (tets.empty()) {
    throw RigBuildError(what + ": no tet has " + std::to_string(s.min_corners) +
                        " corners in the selection: enlarge it or lower min_corners");
  }
  return tets;
}

// Pose sensors without a marker clip: nothing to fit, so device mm -> rig units comes from the
// description alone: markers.matrix when markers.alignment is "matrix", else ("units", or "auto"
// with no markers to fit) the device up axis turned onto the rig up axis and mm scaled to the rig
// unit, translation 0 (pose sensors use only relative motion: clutch and absolute anchors).
RigAlignment poseSensorAlignment(const MarkerOptions& mopt, const std::string& rig_up, double rig_units_per_mm) {
  RigAlignment a;
  a.rig_units_per_mm = rig_units_per_mm;
  a.device_up = mopt.device_up;
  a.rig_up = rig_up;
  if (mopt.alignment == "matrix") {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) a.linear(r, c) = mopt.matrix[static_cast<std::size_t>(r * 4 + c)];
      a.translation[r] = mopt.matrix[static_cast<std::size_t>(r * 4 + 3)];
    }
    if (!a.linear.allFinite() || std::abs(a.linear.determinant()) < 1e-300) {
      throw RigBuildError("pose sensors: markers.matrix is not invertible");
    }
    a.fit_scale = std::cbrt(std::abs(a.linear.determinant())) / rig_units_per_mm;
    return a;
  }
  a.linear = rig_units_per_mm * upAxisRotation(mopt.device_up, rig_up);
  a.fit_scale = 1.0;
  return a;
}

}  // namespace

bool isTetMeshPath(const std::filesystem::path& path) {
  const std::string ext = lowercaseExtension(path);
  return ext == ".node" || ext == ".ele" || ext == ".mesh";
}

namespace {

// The plausibility limits of a marker alignment: every check measured (all) and those that decide
// whether the build stops (decide: without the ones overridden).
struct AlignmentLimits {
  AlignmentCheckLimits all;
  AlignmentCheckLimits decide;
};

// One build: the inputs, and the state buildRig's steps pass on from one to the next.
struct RigBuilder {
  const BuildRigInputs& inputs;
  const RigDescription& desc;
  const MarkerOptions& mopt;
  Progress& prog;
  BuildRigReport report;
  Rig rig;
  std::int32_t target = 0;
  std::optional<std::filesystem::path> clip;  // the marker clip (--markers or markers.clip), if any
  bool given = false;                         // marker positions given directly
  SurfaceMesh fine;
  TetMesh body;
  TetMesh full;  // body plus the invisible tets binding the markers
  Context ctx;
  Eigen::SparseMatrix<double, Eigen::RowMajor> b;
  std::string unit;
  MarkerSet markers;
  std::vector<RigidMarkerGroup> rigid_groups;  // found in the clip (rigid_marker_groups.hpp)
  std::vector<Eigen::Vector3d> marker_rig;
  std::vector<double> marker_distance;
  std::vector<std::string> vertex_owner;                 // per body vertex: the handle that claimed it
  std::vector<std::vector<std::int32_t>> group_regions;  // per rigid group: its region handle's tets (empty: none)
  std::vector<double> stiffness;
  std::vector<double> volume;

  RigBuilder(const BuildRigInputs& in, Progress& progress) : inputs(in), desc(in.description), mopt(in.description.markers), prog(progress) {}

  // Checks the tet-vertex budgets (--tet-vertices, --coarse-tet-vertices) before any heavy work.
  void checkTetBudgets() {
    target = inputs.tet_vertices.value_or(desc.tet_vertices);
    if (target < 4) throw RigBuildError("--tet-vertices must be at least 4");
    if (inputs.coarse_tet_vertices) {  // checked before any heavy work
      const std::int32_t n = *inputs.coarse_tet_vertices;
      if (n < 4 || n >= target) {
        throw RigBuildError("--coarse-tet-vertices " + std::to_string(n) + " must be at least 4 and below the rig's --tet-vertices (" +
                            std::to_string(target) + ")");
      }
      if (isTetMeshPath(inputs.mesh)) {
        throw RigBuildError("--coarse-tet-vertices needs a surface mesh: a ready tet mesh (" + inputs.mesh.filename().string() +
                            ") is used as it is and cannot be made coarser");
      }
    }
  }

  // Checks that the mesh exists and that something will drive the rig; picks the marker source.
  void checkInputs() {
    if (!std::filesystem::exists(inputs.mesh)) {
      throw RigBuildError(inputs.mesh.string() + ": no such file (--mesh)");
    }
    // Nothing would drive a rig without handles: say so before any heavy work.
    clip = inputs.clip ? inputs.clip : (mopt.clip.empty() ? std::nullopt : std::optional(mopt.clip));
    given = inputs.marker_positions.has_value();
    if (clip && given) {
      throw RigBuildError("markers from both a clip (" + clip->string() + ") and given marker positions (" + inputs.marker_positions->what +
                          "): choose one");
    }
    if (!clip && !given && desc.vertex_handles.empty() && desc.region_handles.empty() && desc.point_handles.empty()) {
      throw RigBuildError("the rig would have no handles, so nothing could move it: add markers (--markers CLIP.c3d) or a rig description "
                          "(--rig RIG.json) with vertex_handles, region_handles or point_handles (docs/rig-format.md)");
    }
  }

  // Tet input: reads the tet mesh and checks its tets name vertices in range.
  TetMesh readRawTetMesh() const {
    TetMesh raw = readTetMesh(inputs.mesh);
    if (raw.tetCount() == 0) throw RigBuildError(inputs.mesh.string() + ": the tet mesh has no tets");
    if (!raw.vertices.allFinite()) throw RigBuildError(inputs.mesh.string() + ": non-finite vertex coordinates");
    for (std::int32_t t = 0; t < raw.tetCount(); ++t) {
      for (int k = 0; k < 4; ++k) {
        if (raw.tets(t, k) < 0 || raw.tets(t, k) >= raw.vertexCount()) {
          throw RigBuildError(inputs.mesh.string() + ": tet " + std::to_string(t) + " names a vertex out of range");
        }
      }
    }
    return raw;
  }

  // Tet input: the body is the raw tet mesh positively oriented (two corners of inverted tets
  // swapped) with its unused vertices removed; returns the body's vertex count.
  std::int32_t orientAndCompact(TetMesh& raw) {
    std::int32_t flipped = 0;
    for (std::int32_t t = 0; t < raw.tetCount(); ++t) {
      if (signedVolume(raw, t) < 0) {
        std::swap(raw.tets(t, 2), raw.tets(t, 3));
        ++flipped;
      }
    }
    const TetMeshReport check = checkTetMesh(raw);
    if (!check.ok()) throw RigBuildError(inputs.mesh.string() + ": unusable tet mesh: " + check.summary());
    ctx.file_to_tet.assign(static_cast<std::size_t>(raw.vertexCount()), -1);
    for (std::int32_t t = 0; t < raw.tetCount(); ++t) {
      for (int k = 0; k < 4; ++k) ctx.file_to_tet[static_cast<std::size_t>(raw.tets(t, k))] = 0;
    }
    std::int32_t nv = 0;
    for (std::int32_t& m : ctx.file_to_tet) m = m == 0 ? nv++ : -1;
    body.vertices.resize(nv, 3);
    for (std::size_t v = 0; v < ctx.file_to_tet.size(); ++v) {
      if (ctx.file_to_tet[v] >= 0) body.vertices.row(ctx.file_to_tet[v]) = raw.vertices.row(static_cast<Eigen::Index>(v));
    }
    body.tets.resize(raw.tetCount(), 4);
    for (std::int32_t t = 0; t < raw.tetCount(); ++t) {
      for (int k = 0; k < 4; ++k) body.tets(t, k) = ctx.file_to_tet[static_cast<std::size_t>(raw.tets(t, k))];
    }
    if (flipped) report.notes.push_back(std::to_string(flipped) + " inverted tets re-oriented");
    if (nv < raw.vertexCount()) report.notes.push_back(std::to_string(raw.vertexCount() - nv) + " unused vertices removed");
    return nv;
  }

  // Tet input: the fine mesh is the body's boundary surface; B picks the boundary vertices.
  // Returns the boundary triangles.
  Triangles boundaryAsFineMesh(std::int32_t nv) {
    const Triangles faces = boundaryFaces(body);
    std::vector<std::int32_t> tet_to_fine(static_cast<std::size_t>(nv), -1);
    for (Eigen::Index f = 0; f < faces.rows(); ++f) {
      for (int k = 0; k < 3; ++k) tet_to_fine[static_cast<std::size_t>(faces(f, k))] = 0;
    }
    std::int32_t nf = 0;
    std::vector<std::int32_t> fine_to_tet;
    for (std::int32_t v = 0; v < nv; ++v) {
      if (tet_to_fine[static_cast<std::size_t>(v)] == 0) {
        tet_to_fine[static_cast<std::size_t>(v)] = nf++;
        fine_to_tet.push_back(v);
      }
    }
    fine.vertices.resize(nf, 3);
    for (std::int32_t i = 0; i < nf; ++i) fine.vertices.row(i) = body.vertices.row(fine_to_tet[static_cast<std::size_t>(i)]);
    fine.triangles.resize(faces.rows(), 3);
    for (Eigen::Index f = 0; f < faces.rows(); ++f) {
      for (int k = 0; k < 3; ++k) fine.triangles(f, k) = tet_to_fine[static_cast<std::size_t>(faces(f, k))];
    }
    b.resize(nf, nv);
    std::vector<Eigen::Triplet<double>> trip;
    for (std::int32_t i = 0; i < nf; ++i) trip.emplace_back(i, fine_to_tet[static_cast<std::size_t>(i)], 1.0);
    b.setFromTriplets(trip.begin(), trip.end());
    report.pose.nonzeros = nf;
    return faces;
  }

  // Tet input: the body, the fine mesh (its boundary) and B from a ready tet mesh.
  void readTetInput() {
    report.tet_input = true;
    ctx.tet_input = true;
    auto t0 = Clock::now();
    prog.begin("reading tet mesh " + inputs.mesh.filename().string());
    TetMesh raw = readRawTetMesh();
    const std::int32_t nv = orientAndCompact(raw);
    const Triangles faces = boundaryAsFineMesh(nv);
    const std::int32_t nf = fine.vertexCount();
    report.import_seconds = since(t0);
    prog.end(std::to_string(nv) + " vertices, " + std::to_string(body.tetCount()) + " tets, boundary " + std::to_string(nf) +
             " vertices / " + std::to_string(faces.rows()) + " triangles");
  }

  // Surface input: maps the file's vertex ids (those selections name) to fine vertices.
  void mapFileVertices(const ImportStats& import_stats, const SurfaceReport& surface_report) {
    // Vertex ids of selections: file order for OBJ, OFF and PLY (importSurface keeps it; welding and
    // the repairs may merge or drop vertices, vertex_map says where each went), else the fine order.
    if (import_stats.file_order) {
      ctx.file_to_fine.resize(import_stats.file_to_vertex.size());
      for (std::size_t i = 0; i < ctx.file_to_fine.size(); ++i) {
        const std::int32_t v = import_stats.file_to_vertex[i];
        ctx.file_to_fine[i] = v >= 0 ? surface_report.vertex_map[static_cast<std::size_t>(v)] : -1;
      }
      std::int32_t identical = 0;
      while (identical < fine.vertexCount() && ctx.file_to_fine[static_cast<std::size_t>(identical)] == identical) ++identical;
      if (identical < import_stats.file_vertices) {
        report.notes.push_back("fine vertex i is file vertex i up to " + std::to_string(identical) + " only: " +
                               std::to_string(import_stats.welded_vertices + surface_report.welded_vertices) + " duplicate and " +
                               std::to_string(surface_report.removed_unused_vertices) +
                               " unused file vertices were merged or removed (later ids shift down)");
      }
    } else {
      ctx.file_to_fine.resize(static_cast<std::size_t>(fine.vertexCount()));
      for (std::int32_t v = 0; v < fine.vertexCount(); ++v) ctx.file_to_fine[static_cast<std::size_t>(v)] = v;
      report.notes.push_back("vertex ids refer to the repaired surface's order (the format has no shared vertex list)");
    }
  }

  // Surface input: imports and repairs the surface (the fine mesh) and maps the file's vertex ids.
  void importSurfaceInput() {
    auto t0 = Clock::now();
    prog.begin("importing " + inputs.mesh.filename().string());
    ImportStats import_stats;
    fine = importSurface(inputs.mesh, {}, &import_stats);
    SurfaceReport surface_report = validateSurface(fine);
    requireUsableSurface(surface_report, inputs.mesh.string());
    report.import_seconds = since(t0);
    prog.end(surface_report.summary());
    mapFileVertices(import_stats, surface_report);
    // An OBJ's texture coordinates and materials, per fine-triangle corner; the fine triangles take
    // the file's face order (obj_surface_attributes.hpp). The coarse level's fine mesh is sorted
    // the same way but carries none (the rig has them).
    if (import_stats.file_order && lowercaseExtension(inputs.mesh) == ".obj") {
      std::string note;
      std::optional<RigSurfaceAttributes> surface = objSurfaceAttributes(inputs.mesh, ctx.file_to_fine, fine.triangles, &note);
      if (!inputs.coarse_level) {
        if (surface) rig.surface = std::move(*surface);
        if (!note.empty()) report.notes.push_back(note);
      }
    }
  }

  // The fine mesh's extent along the mesh's up axis, in its own units.
  double meshHeight() const {
    const Eigen::Vector3d up = axisVector(desc.mesh_up).cwiseAbs();
    return (fine.vertices.colwise().maxCoeff() - fine.vertices.colwise().minCoeff()).dot(up);
  }

  // The rig's unit (the description's, or guessed from the mesh's height) and its default alignment.
  void chooseUnit() {
    unit = desc.mesh_unit;
    if (unit == "auto") {
      const double height = meshHeight();
      const double performer_mm = clip ? medianMarkerHeightMm(openMarkerClip(*clip, mopt), axisVector(mopt.device_up).cwiseAbs()) : 0.0;
      if (performer_mm > 0.0) {
        // The unit that makes the mesh about as tall as the performer's markers (a factor of 10
        // between candidates, so the nearest ratio is unambiguous for any plausible body).
        double best = INFINITY;
        for (const char* candidate : {"m", "cm", "mm"}) {
          const double ratio = std::abs(std::log(height / rigUnitsPerMm(candidate) / performer_mm));
          if (ratio < best) {
            best = ratio;
            unit = candidate;
          }
        }
        report.notes.push_back("mesh unit taken as " + unit + ": the mesh is " + formatNumber("%.4g", height) + " units tall, the performer's markers " +
                               formatNumber("%.0f", performer_mm) + " mm (--mesh-unit to say otherwise)");
      } else {
        unit = height > 100 ? "mm" : height > 10 ? "cm" : "m";
        report.notes.push_back("mesh unit taken as " + unit + " from its height " + formatNumber("%.4g", height) + " (--mesh-unit to say otherwise)");
      }
    }
    rig.unit = unit;
    rig.alignment.rig_units_per_mm = rigUnitsPerMm(unit);
    rig.alignment.linear = rig.alignment.rig_units_per_mm * Eigen::Matrix3d::Identity();
    rig.alignment.rig_up = desc.mesh_up;
    rig.alignment.device_up = mopt.device_up;
  }

  // The options of the marker alignment, from the description's markers section.
  AlignmentOptions alignmentOptions() const {
    AlignmentOptions aopt;
    aopt.device_up = mopt.device_up;
    aopt.rig_up = desc.mesh_up;
    aopt.rig_units_per_mm = rig.alignment.rig_units_per_mm;
    aopt.mode = mopt.alignment;
    aopt.matrix = mopt.matrix;
    aopt.icp_iterations = mopt.icp_iterations;
    aopt.icp_scale = mopt.icp_scale;
    aopt.max_scale_change = mopt.max_scale_change;
    aopt.marker_offset = mopt.marker_offset;
    aopt.fit_power = mopt.fit_power;
    return aopt;
  }

  // The plausibility limits: the description's, the fit scale range of the command line, and the
  // overrides (--accept-implausible-alignment, --accept-pose-mismatch).
  AlignmentLimits alignmentLimits(bool automatic) const {
    AlignmentCheckLimits all_checks = mopt.checks;
    if (inputs.min_fit_scale) all_checks.min_fit_scale = *inputs.min_fit_scale;
    if (inputs.max_fit_scale) all_checks.max_fit_scale = *inputs.max_fit_scale;
    if (!(all_checks.min_fit_scale > 0 && all_checks.min_fit_scale <= all_checks.max_fit_scale)) {
      throw RigBuildError("the fit scale range " + formatNumber("%.4g", all_checks.min_fit_scale) + ".." + formatNumber("%.4g", all_checks.max_fit_scale) +
                          " is empty: --min-fit-scale must be positive and at most --max-fit-scale");
    }
    all_checks.check_scale = automatic;
    all_checks.check_pose = automatic;
    AlignmentCheckLimits limits = all_checks;
    limits.check_scale = automatic && mopt.checks.check_scale && !inputs.accept_implausible_alignment;
    limits.check_pose = automatic && mopt.checks.check_pose && !inputs.accept_implausible_alignment && !inputs.accept_pose_mismatch;
    return {all_checks, limits};
  }

  // --frame auto: searches the clip for the frame that fits the mesh's rest pose; sets frame and
  // frame_text.
  void searchRestFrameOf(const MarkerClip& source, const AlignmentOptions& aopt, const AlignmentCheckLimits& limits, std::int64_t& frame,
                         std::string& frame_text) {
    prog.begin("searching " + clip->filename().string() + " for the frame that fits the mesh's rest pose");
    RestFrameSearchOptions sopt;
    sopt.progress = [this](double f) { prog.update(f); };
    RestFrameSearch found;
    try {
      found = searchRestFrame(
          static_cast<std::int64_t>(source.clip.frameCount()),
          [&source](std::int64_t f, std::vector<Eigen::Vector3d>& out) { return markersAt(source, f, out); }, source.labels, fine, aopt,
          desc.mesh_up, limits, sopt);
    } catch (const RigBuildError& e) {
      throw RigBuildError(clip->string() + ": --frame auto: " + e.what());
    }
    frame = found.frame;
    frame_text = "frame " + std::to_string(frame) + " (chosen by --frame auto)";
    const double rate = source.clip.frameRate();
    const std::string when = rate > 0 ? " (" + formatNumber("%.3f", static_cast<double>(frame) / rate) + " s)" : std::string();
    const std::string line = "--frame auto chose frame " + std::to_string(frame) + when + " of " + std::to_string(found.clip_frames) +
                             ": fit scale " + formatNumber("%.4g", found.chosen.fit_scale) + ", median marker distance about " +
                             formatNumber("%.3g", found.chosen.median_distance) + " " + unit + " (searched " + std::to_string(found.searched) +
                             " frames, " + std::to_string(found.plausible) + " plausible)";
    prog.end("frame " + std::to_string(frame) + when + ", fit scale " + formatNumber("%.4g", found.chosen.fit_scale) + " (" +
             std::to_string(found.plausible) + " of " + std::to_string(found.searched) + " frames searched fit)");
    report.notes.push_back(line);
    report.frame_search = found;
  }

  // The error for an alignment the deciding checks reject: what failed and what to do.
  RigBuildError implausibleAlignment(const AlignmentCheck& decided, const std::string& origin, const std::string& frame_text) const {
    const std::string what = decided.failures();
    std::string todo;
    if (!decided.scale_failures.empty()) {
      const double height = meshHeight();
      const Eigen::Vector3d device_up = axisVector(mopt.device_up).cwiseAbs();
      double lo = std::numeric_limits<double>::infinity(), hi = -lo;
      for (const Eigen::Vector3d& m : markers.device_mm) {
        lo = std::min(lo, m.dot(device_up));
        hi = std::max(hi, m.dot(device_up));
      }
      todo += "check the mesh's unit (taken as " + unit + ": the mesh is " + formatNumber("%.4g", height) + " " + unit + " tall, the markers span " +
              formatNumber("%.4g", hi - lo) + " mm; --mesh-unit) and that the markers belong to a body like this mesh (--min-fit-scale / "
              "--max-fit-scale widen the range)";
    }
    if (!decided.pose_failures.empty()) {
      todo += std::string(todo.empty() ? "" : "; ") + (clip ? "the clip's " + frame_text + " is" : frame_text + " are") +
              " not in the mesh's rest pose (e.g. arms down on a T-pose mesh) or the markers cover only part of the body: choose a "
              "frame in the mesh's pose (--frame N, or --frame auto) or a calibration clip, or pass --accept-pose-mismatch for a "
              "partial marker set";
    }
    return RigBuildError(origin + ": " + frame_text + ": the marker alignment is implausible: " + what + ". To fix: " + todo +
                         " (--accept-implausible-alignment builds anyway)");
  }

  // Plausibility: every check measured; those not overridden decide.
  void judgeAlignment(const AlignmentResult& aligned, const AlignmentLimits& limits, bool automatic, const std::string& origin,
                      const std::string& frame_text) {
    const AlignmentCheck measured =
        checkAlignment(fine, desc.mesh_up, marker_rig, marker_distance, markers.labels, aligned.alignment.fit_scale, limits.all);
    const AlignmentCheck decided =
        checkAlignment(fine, desc.mesh_up, marker_rig, marker_distance, markers.labels, aligned.alignment.fit_scale, limits.decide);
    report.alignment_check = measured;
    if (automatic) report.notes.push_back("alignment checks: " + measured.summary());
    if (!decided.ok()) throw implausibleAlignment(decided, origin, frame_text);
    if (!measured.ok()) report.notes.push_back("implausible alignment accepted as asked: " + measured.failures());
  }

  // Distance limit: explicit (absolute) or a fraction of the mesh's size; a marker beyond it stops
  // the build.
  void checkMarkerDistances() {
    const double diagonal = (fine.vertices.colwise().maxCoeff() - fine.vertices.colwise().minCoeff()).norm();
    const std::optional<double> absolute = inputs.max_marker_distance ? inputs.max_marker_distance : mopt.max_distance;
    const double limit = absolute ? *absolute : mopt.max_distance_fraction * diagonal;
    const std::string limit_text = formatNumber("%.4g", limit) + " " + unit +
                                   (absolute ? std::string() : " (" + formatNumber("%.3g", 100.0 * mopt.max_distance_fraction) + " % of the mesh's diagonal)");
    report.marker_distance_limit = limit;
    std::string far;
    std::size_t worst = 0;
    for (std::size_t i = 0; i < marker_distance.size(); ++i) {
      if (marker_distance[i] > marker_distance[worst]) worst = i;
      if (marker_distance[i] > limit) far += (far.empty() ? "" : ", ") + markers.labels[i] + " (" + formatNumber("%.4g", marker_distance[i]) + ")";
    }
    if (!far.empty()) {
      throw RigBuildError("marker " + markers.labels[worst] + " is " + formatNumber("%.4g", marker_distance[worst]) + " " + unit +
                          " from the surface after alignment, beyond the limit " + limit_text + " (too far: " + far +
                          "); check the clip's rest frame and axes, exclude the marker, or raise --max-marker-distance");
    }
  }

  // Markers that move as one rigid body over the clip drive the skin around them as a region.
  void findRigidGroups(const MarkerClip& mc) {
    const double k = mc.clip.unitsToMm();
    const MarkerFrameReader read = [&mc, k](std::int64_t f, std::vector<Eigen::Vector3d>& x, std::vector<std::uint8_t>& valid) {
      const float* pos = mc.clip.positions(static_cast<std::size_t>(f));
      for (std::size_t i = 0; i < mc.points.size(); ++i) {
        const int p = mc.points[i];
        valid[i] = mc.clip.isValid(static_cast<std::size_t>(f), p);
        if (valid[i]) x[i] = Eigen::Vector3d(k * pos[3 * p], k * pos[3 * p + 1], k * pos[3 * p + 2]);
      }
    };
    std::vector<RigidMarkerGroup> too_large;
    rigid_groups = findRigidMarkerGroups(static_cast<std::int64_t>(mc.clip.frameCount()), mc.points.size(), read, marker_rig, {}, &too_large);
    for (const RigidMarkerGroup& g : too_large) {
      if (inputs.coarse_level) break;
      std::string names;
      for (const std::int32_t m : g.markers) names += (names.empty() ? "" : ", ") + markers.labels[static_cast<std::size_t>(m)];
      report.notes.push_back(std::to_string(g.markers.size()) + " markers (" + names + ") keep their distances over the clip but span " +
                             formatNumber("%.0f", g.extent_mm) + " mm, too much of the body for one part: the clip does not move the joints between "
                             "them, so no rigid groups are taken from it there (build the rig from a clip in which the performer moves)");
    }
  }

  // Markers: rest frame (given or searched), alignment, plausibility and distance checks, all
  // before decimation and TetGen: a clip that does not fit the mesh stops the build in seconds.
  void fitMarkers() {
    auto t0 = Clock::now();
    const std::optional<MarkerClip> source = clip ? std::optional<MarkerClip>(openMarkerClip(*clip, mopt)) : std::nullopt;
    const std::string origin = clip ? clip->string() : inputs.marker_positions->what;
    AlignmentOptions aopt = alignmentOptions();
    // The scale and pose checks judge an automatic fit; "units" and "matrix" are the user's own
    // transform (the distance limit below still applies to them).
    const bool automatic = aopt.mode == "auto";
    const AlignmentLimits limits = alignmentLimits(automatic);

    const bool frame_auto = clip && (inputs.frame_auto || (!inputs.frame && mopt.frame_auto));
    std::int64_t frame = inputs.frame.value_or(mopt.frame);
    std::string frame_text = clip ? "frame " + std::to_string(frame) : std::string("the given positions");
    if (frame_auto) searchRestFrameOf(*source, aopt, limits.decide, frame, frame_text);
    if (clip) {
      report.rest_frame = frame;
      prog.begin("aligning markers of " + clip->filename().string() + " (frame " + std::to_string(frame) + ")");
      markers = readMarkers(*source, frame);
    } else {
      prog.begin("aligning " + origin);
      markers = checkedMarkerPositions(*inputs.marker_positions);
    }
    aopt.progress = [this](double f) { prog.update(f); };
    AlignmentResult aligned = alignMarkers(markers.device_mm, fine, aopt);
    rig.alignment = aligned.alignment;
    marker_rig = aligned.rig_positions;
    marker_distance = aligned.distances;
    report.align_seconds = since(t0);
    prog.end(std::to_string(markers.labels.size()) + " markers, distance to surface median " + formatNumber("%.4g", aligned.median_distance) +
             " max " + formatNumber("%.4g", aligned.max_distance) + " " + unit + ", scale " + formatNumber("%.4f", aligned.alignment.fit_scale));
    report.alignment = aligned;

    judgeAlignment(aligned, limits, automatic, origin, frame_text);
    checkMarkerDistances();
    if (clip && mopt.rigid_regions && desc.region_handles.empty()) findRigidGroups(*source);
  }

  // Surface input: the coarse tet mesh (decimation and TetGen) and the pose-transfer weights B.
  void tetrahedralizeSurface() {
    auto t0 = Clock::now();
    prog.begin("decimating and tetrahedralizing (TetGen) to " + std::to_string(target) + " tet vertices");
    DecimateOptions dec;
    dec.target_vertices = target;
    CoarseRig coarse = buildCoarseTetMesh(fine, dec);
    body = coarse.tets.mesh;
    report.interior_vertices = coarse.tets.interior_vertices;
    ctx.fine_to_tet.assign(static_cast<std::size_t>(fine.vertexCount()), -1);
    for (std::size_t v = 0; v < coarse.tet_to_fine.size(); ++v) {
      if (coarse.tet_to_fine[v] >= 0) ctx.fine_to_tet[static_cast<std::size_t>(coarse.tet_to_fine[v])] = static_cast<std::int32_t>(v);
    }
    for (const std::string& line : coarse.failed_attempts) report.notes.push_back("retried: " + line);
    if (coarse.repair.moved_vertices > 0) {
      report.notes.push_back("self-intersection repair moved " + std::to_string(coarse.repair.moved_vertices) + " coarse vertices (max " +
                             formatNumber("%.4g", coarse.repair.max_displacement) + ")");
    }
    report.tetrahedralize_seconds = since(t0);
    prog.end(std::to_string(body.vertexCount()) + " vertices (" + std::to_string(body.vertexCount() - coarse.tets.interior_vertices) +
             " on the surface), " + std::to_string(body.tetCount()) + " tets; " + tetQuality(body).summary());
    t0 = Clock::now();
    prog.begin("pose-transfer weights B");
    PoseTransferOptions popt;
    popt.radius_fraction = desc.pose_radius_fraction;
    popt.max_nonzeros_per_row = desc.pose_max_nonzeros;
    b = poseTransferWeights(fine.vertices, body, popt, &report.pose);
    report.pose_seconds = since(t0);
    prog.end(std::to_string(report.pose.nonzeros) + " non-zeros, " + formatNumber("%.1f", report.pose.mean_nonzeros_per_row) + " per row");
  }

  // Records the meshes' sizes and points the selection context at the body and the fine mesh.
  void recordMeshes() {
    ctx.body = &body;
    ctx.fine = &fine.vertices;
    report.fine_vertices = fine.vertexCount();
    report.fine_triangles = fine.triangleCount();
    report.body_vertices = body.vertexCount();
    report.body_tets = body.tetCount();
  }

  // Pose sensors without markers: the alignment from the description alone.
  void alignForPoseSensors() {
    rig.alignment = poseSensorAlignment(mopt, desc.mesh_up, rig.alignment.rig_units_per_mm);
    report.notes.push_back(mopt.alignment == "matrix"
                               ? std::string("pose sensors: no marker clip, device mm -> rig units from markers.matrix")
                               : "pose sensors: no marker clip, device mm -> rig units by axes and unit only (device up " +
                                     mopt.device_up + " -> rig up " + desc.mesh_up + ", " + formatNumber("%.4g", rig.alignment.rig_units_per_mm) +
                                     " " + unit + " per mm)");
  }

  // The body vertices of `tets`, each once, ascending.
  std::vector<std::int32_t> cornersOf(const std::vector<std::int32_t>& tets) const {
    std::vector<std::int32_t> corners;
    for (const std::int32_t t : tets) {
      for (int k = 0; k < 4; ++k) corners.push_back(body.tets(t, k));
    }
    std::sort(corners.begin(), corners.end());
    corners.erase(std::unique(corners.begin(), corners.end()), corners.end());
    return corners;
  }

  // Gives tet vertex v to the handle `who`; a vertex of another handle is an error.
  void claim(std::int32_t v, const std::string& who) {
    std::string& owner = vertex_owner[static_cast<std::size_t>(v)];
    if (!owner.empty() && owner != who) {
      throw RigBuildError("tet vertex " + std::to_string(v) + " belongs to both " + owner + " and " + who +
                          ": handles may not overlap; shrink one of the selections");
    }
    owner = who;
  }

  // The description's vertex handles: every tet vertex of each selection.
  void addVertexHandles() {
    DeformerSetup& setup = rig.setup;
    for (std::size_t h = 0; h < desc.vertex_handles.size(); ++h) {
      const NamedSelection& n = desc.vertex_handles[h];
      const std::string who = "vertex handle '" + n.name + "'";
      const std::vector<std::uint8_t> mask = resolveVertices(ctx, n.select, who);
      for (std::int32_t v = 0; v < body.vertexCount(); ++v) {
        if (!mask[static_cast<std::size_t>(v)]) continue;
        claim(v, who);
        setup.vertex_handles.push_back(v);
        rig.vertex_handle_names.push_back(n.name);
      }
    }
  }

  // The description's region handles: the tets of each selection.
  void addRegionHandles() {
    DeformerSetup& setup = rig.setup;
    for (const NamedSelection& n : desc.region_handles) {
      const std::string who = "region handle '" + n.name + "'";
      RegionHandle region;
      region.tets = resolveTets(ctx, n.select, who);
      region.oriented = n.oriented;
      for (const std::int32_t v : cornersOf(region.tets)) claim(v, who);
      setup.region_handles.push_back(std::move(region));
      rig.region_handle_names.push_back(n.name);
    }
  }

  // The region of a rigid marker group (claimed for `who`): the tets wholly in the group's skin
  // (the coarse level, whose tets are larger: with a corner in it); where none is, the one tet
  // nearest the markers' centre: every group drives a region, and both levels have the same
  // regions. No tet when every candidate belongs to another handle.
  RegionHandle rigidGroupRegion(const RigidMarkerGroup& g, const std::string& who) {
    double extent = 0.0;
    for (const std::int32_t ga : g.markers) {
      for (const std::int32_t gb : g.markers) extent = std::max(extent, (marker_rig[static_cast<std::size_t>(ga)] - marker_rig[static_cast<std::size_t>(gb)]).norm());
    }
    const std::vector<std::uint8_t> mask = groupSkinMask(body.vertices, marker_rig, g.markers, extent);
    const auto free_of_others = [&](std::int32_t t) {
      for (int c = 0; c < 4; ++c) {
        const std::string& owner = vertex_owner[static_cast<std::size_t>(body.tets(t, c))];
        if (!owner.empty() && owner != who) return false;
      }
      return true;
    };
    RegionHandle region;
    region.oriented = true;
    const int needed = inputs.coarse_level ? 1 : 4;
    for (std::int32_t t = 0; t < body.tetCount(); ++t) {
      int in = 0;
      for (int c = 0; c < 4; ++c) in += mask[static_cast<std::size_t>(body.tets(t, c))];
      if (in >= needed && free_of_others(t)) {
        region.tets.push_back(t);
        for (int c = 0; c < 4; ++c) claim(body.tets(t, c), who);
      }
    }
    if (region.tets.empty()) {
      Eigen::Vector3d centre = Eigen::Vector3d::Zero();
      for (const std::int32_t m : g.markers) centre += marker_rig[static_cast<std::size_t>(m)] / static_cast<double>(g.markers.size());
      std::int32_t best = -1;
      double best_d = std::numeric_limits<double>::infinity();
      for (std::int32_t t = 0; t < body.tetCount(); ++t) {
        Eigen::Vector3d c = Eigen::Vector3d::Zero();
        for (int k = 0; k < 4; ++k) c += 0.25 * body.vertices.row(body.tets(t, k)).transpose();
        if ((c - centre).norm() < best_d && free_of_others(t)) {
          best_d = (c - centre).norm();
          best = t;
        }
      }
      if (best >= 0) {
        region.tets.push_back(best);
        for (int c = 0; c < 4; ++c) claim(body.tets(best, c), who);
      }
    }
    return region;
  }

  // A region handle per rigid marker group (those with a region), reported with its size.
  void addRigidGroupRegions() {
    DeformerSetup& setup = rig.setup;
    for (const RigidMarkerGroup& g : rigid_groups) {
      std::string name;
      for (const std::int32_t m : g.markers) name += (name.empty() ? "" : "+") + markers.labels[static_cast<std::size_t>(m)];
      const std::string who = "markers:" + name;
      RegionHandle region = rigidGroupRegion(g, who);
      const std::vector<std::int32_t> corners = cornersOf(region.tets);
      report.rigid_groups.push_back({name, g.spread_mm, static_cast<std::int32_t>(corners.size())});
      if (!region.tets.empty() && !inputs.coarse_level) {
        report.notes.push_back("markers " + name + " move as one rigid body over the clip (their distances within " + formatNumber("%.1f", g.spread_mm) +
                               " mm): they drive the skin around them, " + std::to_string(corners.size()) + " tet vertices, as region '" + who +
                               "' (a description's region_handles, or \"markers\": {\"rigid_regions\": false}, turn this off)");
      }
      if (region.tets.empty()) {
        report.notes.push_back("markers " + name + " move rigidly together (distances within " + formatNumber("%.1f", g.spread_mm) +
                               " mm) but no tet lies wholly in the skin around them: they drive no region");
        group_regions.emplace_back();
        continue;
      }
      group_regions.push_back(region.tets);
      setup.region_handles.push_back(std::move(region));
      rig.region_handle_names.push_back("markers:" + name);
    }
  }

  // The description's point handles, each in the tet holding it best.
  void addPointHandles() {
    DeformerSetup& setup = rig.setup;
    for (const PointHandleSpec& p : desc.point_handles) {
      // The tet holding the point best (largest smallest barycentric coordinate).
      PointHandle best;
      double best_min = -std::numeric_limits<double>::infinity();
      for (std::int32_t t = 0; t < body.tetCount(); ++t) {
        Eigen::Matrix3d e;
        const Eigen::Vector3d d = body.vertices.row(body.tets(t, 3));
        for (int k = 0; k < 3; ++k) e.col(k) = body.vertices.row(body.tets(t, k)).transpose() - d;
        const Eigen::Vector3d l = e.partialPivLu().solve(p.position - d);
        const Eigen::Vector4d bary(l[0], l[1], l[2], 1.0 - l.sum());
        if (bary.allFinite() && bary.minCoeff() > best_min) {
          best_min = bary.minCoeff();
          best.tet = t;
          best.barycentric = bary;
        }
      }
      if (best.tet < 0) throw RigBuildError("point handle '" + p.name + "': no tet can carry it");
      setup.point_handles.push_back(best);
      rig.point_handle_names.push_back(p.name);
    }
  }

  // The description's pose sensors, each on its region handle.
  void addPoseSensors() {
    const DeformerSetup& setup = rig.setup;
    // Pose sensors: the description parser resolved each region name to its index in
    // desc.region_handles, which is its index in setup.region_handles (same order, above).
    for (const PoseSensorSpec& p : desc.pose_sensors) {
      if (p.region_index < 0 || static_cast<std::size_t>(p.region_index) >= setup.region_handles.size()) {
        throw RigBuildError(p.where + ": pose sensor " + p.sensor + " names no region handle of this rig");
      }
      RigPoseSensor ps;
      ps.sensor_label = p.sensor;
      ps.region_handle = p.region_index;
      ps.mode = p.mode;
      ps.clutch_buttons = p.clutch_buttons;
      ps.translation_scale = p.translation_scale;
      rig.pose_sensors.push_back(ps);
    }
  }

  // The description's rigid groups; they must be disjoint.
  void addRigidGroups() {
    DeformerSetup& setup = rig.setup;
    std::vector<std::string> group_of(static_cast<std::size_t>(body.tetCount()));
    for (const NamedSelection& n : desc.rigid_groups) {
      RigidGroup g;
      g.tets = resolveTets(ctx, n.select, "rigid group '" + n.name + "'");
      for (const std::int32_t t : g.tets) {
        std::string& owner = group_of[static_cast<std::size_t>(t)];
        if (!owner.empty()) {
          throw RigBuildError("tet " + std::to_string(t) + " is in rigid groups '" + owner + "' and '" + n.name +
                              "': groups must be disjoint; shrink one");
        }
        owner = n.name;
      }
      setup.rigid_groups.push_back(std::move(g));
      rig.rigid_group_names.push_back(n.name);
    }
  }

  // Per body tet: the stiffness and the volume weight of the description's selections.
  void assignStiffnessAndVolume() {
    stiffness.assign(static_cast<std::size_t>(body.tetCount()), 1.0);
    for (const NamedSelection& n : desc.stiffness) {
      for (const std::int32_t t : resolveTets(ctx, n.select, "stiffness '" + n.name + "'")) stiffness[static_cast<std::size_t>(t)] = n.value;
    }
    volume.assign(static_cast<std::size_t>(body.tetCount()), 0.0);  // invisible tets take none
    for (const NamedSelection& n : desc.volume) {
      const std::string who = "volume '" + n.name + "'";
      // The coarse level's few large tets may miss a small region: it then goes without it (the
      // term is a refinement; the fine level has it).
      const std::vector<std::int32_t> tets = inputs.coarse_level ? selectTets(ctx, n.select, who, true) : resolveTets(ctx, n.select, who);
      if (tets.empty()) report.notes.push_back(who + ": no coarse tet has " + std::to_string(n.select.min_corners) +
                                                 " corners in it; the coarse level has no volume term there");
      for (const std::int32_t t : tets) volume[static_cast<std::size_t>(t)] = n.value;
    }
  }

  // Selections onto the body tet mesh: the handles, rigid groups, stiffness and volume weights.
  void resolveSelections() {
    DeformerSetup& setup = rig.setup;
    setup.options.rotation_steps = desc.rotation_steps;
    setup.options.point_handle_weight = desc.point_handle_weight;
    vertex_owner.assign(static_cast<std::size_t>(body.vertexCount()), std::string());
    addVertexHandles();
    addRegionHandles();
    // Regions of the rigid marker groups: the tets whose four corners lie in the group's skin and
    // belong to no other handle.
    addRigidGroupRegions();
    addPointHandles();
    addPoseSensors();
    addRigidGroups();
    assignStiffnessAndVolume();
  }

  // Markers bound by invisible tets: the full tet mesh, a vertex handle per marker.
  void bindMarkersToBody() {
    DeformerSetup& setup = rig.setup;
    full = body;
    if (!markers.labels.empty()) {
      auto t0 = Clock::now();
      prog.begin("binding markers by invisible tets");
      MarkerBindOptions bopt;
      bopt.faces_per_marker = mopt.faces_per_marker;
      bopt.face_spread = mopt.face_spread;
      bopt.fan_spread = mopt.fan_spread;
      bopt.fan_spokes = mopt.fan_spokes;
      bopt.fan_weight = mopt.fan_weight;
      MarkerBindResult bound = bindMarkers(body, marker_rig, markers.labels, bopt);
      full = bound.mesh;
      report.invisible_tets = bound.invisible_tets;
      report.markers_below_skin = bound.below_skin;
      for (std::size_t m = 0; m < markers.labels.size(); ++m) {
        RigMarker rm;
        rm.label = markers.labels[m];
        rm.tet_vertex = bound.bindings[m].tet_vertex;
        rm.vertex_handle = static_cast<std::int32_t>(setup.vertex_handles.size());
        rm.rest_position = marker_rig[m];
        rm.bound_faces = bound.bindings[m].bound_faces;
        rm.surface_distance = marker_distance[m];
        setup.vertex_handles.push_back(rm.tet_vertex);
        rig.vertex_handle_names.push_back("marker:" + rm.label);
        rig.markers.push_back(rm);
      }
      stiffness.resize(static_cast<std::size_t>(full.tetCount()), mopt.invisible_stiffness);
      for (std::size_t i = 0; i < bound.invisible_scale.size(); ++i) {
        stiffness[static_cast<std::size_t>(body.tetCount()) + i] *= bound.invisible_scale[i];
      }
      report.bind_seconds = since(t0);
      prog.end(std::to_string(bound.invisible_tets) + " invisible tets" +
               (bound.below_skin ? ", " + std::to_string(bound.below_skin) + " markers below the skin" : std::string()));
    }
    report.markers = static_cast<std::int32_t>(markers.labels.size());
    report.marker_labels = markers.labels;
  }

  // Regions driven by marker clusters (region_handles[i].markers, by label) and by the rigid
  // marker groups.
  void addMarkerRegions() {
    for (std::size_t h = 0; h < desc.region_handles.size(); ++h) {
      const NamedSelection& n = desc.region_handles[h];
      if (n.markers.empty()) continue;
      RigMarkerRegion mr;
      mr.region_handle = static_cast<std::int32_t>(h);
      for (const std::string& label : n.markers) {
        std::int32_t found = -1;
        for (std::size_t m = 0; m < rig.markers.size(); ++m) {
          if (rig.markers[m].label == label) found = static_cast<std::int32_t>(m);
        }
        if (found < 0) {
          throw RigBuildError("region handle '" + n.name + "': marker '" + label + "' is not a marker of this rig" +
                              (rig.markers.empty() ? std::string(" (the rig has no markers: give --markers CLIP.c3d)") : std::string()));
        }
        mr.markers.push_back(found);
      }
      rig.marker_regions.push_back(std::move(mr));
    }
    for (std::size_t g = 0, h = desc.region_handles.size(); g < rigid_groups.size(); ++g) {
      if (group_regions[g].empty()) continue;
      RigMarkerRegion mr;
      mr.region_handle = static_cast<std::int32_t>(h++);
      mr.markers = rigid_groups[g].markers;  // rig.markers is in the order of markers.labels
      rig.marker_regions.push_back(std::move(mr));
    }
  }

  // Puts the meshes, B, the stiffness and the volume weights into the rig and validates it.
  void assembleRig() {
    DeformerSetup& setup = rig.setup;
    rig.tet_mesh = full;
    rig.body_vertex_count = body.vertexCount();
    rig.body_tet_count = body.tetCount();
    rig.fine_vertices = fine.vertices;
    rig.fine_triangles = fine.triangles;
    b.conservativeResize(b.rows(), full.vertexCount());
    b.makeCompressed();
    rig.pose_transfer = makePoseTransferCsr<double>(b);
    rig.pose_transfer.cols = full.vertexCount();
    const bool uniform = std::all_of(stiffness.begin(), stiffness.end(), [](double s) { return s == 1.0; });
    if (!uniform) setup.stiffness = stiffness;
    volume.resize(static_cast<std::size_t>(full.tetCount()), 0.0);
    if (std::any_of(volume.begin(), volume.end(), [](double w) { return w > 0.0; })) setup.volume_weights = volume;

    if (std::string e = validateRig(rig); !e.empty()) throw RigBuildError("the built rig is inconsistent: " + e);
  }

  // Checks that the rig loads: builds its Deformer (Laplacian, factorization).
  void checkDeformer() {
    auto t0 = Clock::now();
    prog.begin("checking the rig (Deformer: Laplacian, factorization)");
    try {
      const Deformer deformer(rig.tet_mesh, rig.setup);
      report.factorize_seconds = deformer.factorizeSeconds();
    } catch (const std::exception& e) {
      throw RigBuildError(std::string("the rig does not load: ") + e.what());
    }
    report.check_seconds = since(t0);
    prog.end("factorized in " + formatNumber("%.3f", report.factorize_seconds) + " s");
  }

  // The coarse level: the same inputs and rest frame (so the same alignment: one rig space) with a
  // smaller tet-vertex budget. A surface that cannot be tetrahedralized that coarsely (arms close
  // to the body merge once decimated) gets the level at twice the budget, and so on while the
  // level stays below half the rig's budget; past that, the rig has none, with a note: the coarse
  // level only speeds the frame's convergence, the rig is whole without it.
  void buildCoarseLevel() {
    const std::int32_t asked = *inputs.coarse_tet_vertices;
    const std::string why = "the surface, decimated that far, intersects itself or has parts thinner than its triangles";
    for (std::int32_t n = asked; n == asked || 2 * n <= target; n *= 2) {
      auto t0 = Clock::now();
      prog.begin("building the coarse level (" + std::to_string(n) + " tet vertices)");
      BuildRigInputs coarse_inputs = inputs;
      coarse_inputs.tet_vertices = n;
      coarse_inputs.coarse_tet_vertices.reset();
      coarse_inputs.coarse_level = true;
      coarse_inputs.frame_auto = false;
      if (report.rest_frame >= 0) coarse_inputs.frame = report.rest_frame;
      BuildRigReport coarse_report;
      Rig coarse;
      try {
        coarse = buildRig(coarse_inputs, &coarse_report);
      } catch (const TetBudgetError&) {
        prog.end("no tet mesh at this budget");
        continue;
      }
      for (const std::string& note : coarse_report.notes) {
        if (note.starts_with("volume '")) report.notes.push_back("coarse level: " + note);
      }
      if (n != asked) {
        report.notes.push_back("the coarse level has " + std::to_string(n) + " tet vertices, not " + std::to_string(asked) +
                               ": there is no tet mesh of " + std::to_string(asked) + " (" + why + ")");
      }
      rig.coarse = std::make_shared<const Rig>(std::move(coarse));
      if (std::string e = validateRig(rig); !e.empty()) throw RigBuildError("the coarse level does not fit the rig: " + e);
      report.coarse_seconds = since(t0);
      prog.end(std::to_string(rig.coarse->tet_mesh.vertexCount()) + " tet vertices, " + std::to_string(rig.coarse->tet_mesh.tetCount()) +
               " tets");
      return;
    }
    report.notes.push_back("the rig has no coarse level: there is no tet mesh of " + std::to_string(asked) +
                           " tet vertices or of twice that up to half the rig's budget (" + why +
                           "); the frame solves the rig alone, which lands farther from its converged pose within a frame's iterations");
  }
};

}  // namespace

Rig buildRig(const BuildRigInputs& inputs, BuildRigReport* report_out, Progress* progress) {
  Progress quiet("", Progress::Mode::kQuiet);
  RigBuilder build(inputs, progress ? *progress : quiet);
  // Budgets first: a bad --tet-vertices stops the build before any heavy work.
  build.checkTetBudgets();
  build.rig.builder = "tetrig build-rig " TETRIG_VERSION_STRING;
  build.rig.name = inputs.description.name.empty() ? inputs.mesh.filename().string() : inputs.description.name;
  // The mesh exists and something will drive the rig.
  build.checkInputs();
  // The body tet mesh, fine mesh and B from a tet mesh; or the fine mesh from a surface.
  if (isTetMeshPath(inputs.mesh)) {
    build.readTetInput();
  } else {
    build.importSurfaceInput();
  }
  // Unit and axes of the rig.
  build.chooseUnit();
  // Markers: rest frame, alignment and checks, before the heavy work.
  if (build.clip || build.given) build.fitMarkers();
  // Surface input: the coarse tet mesh and B.
  if (!build.report.tet_input) build.tetrahedralizeSurface();
  build.recordMeshes();
  // Pose sensors without markers: device mm -> rig units from the description.
  if (!build.clip && !build.given && !inputs.description.pose_sensors.empty()) build.alignForPoseSensors();
  build.ctx.marker_labels = &build.markers.labels;
  build.ctx.marker_positions = &build.marker_rig;
  // Selections onto the body tet mesh.
  build.resolveSelections();
  // Markers bound by invisible tets.
  build.bindMarkersToBody();
  // Regions driven by markers.
  build.addMarkerRegions();
  // The rig's meshes, B and weights; validated.
  build.assembleRig();
  // Optionally: the rig's Deformer builds.
  if (inputs.check_deformer) build.checkDeformer();
  // Optionally: the coarse level.
  if (inputs.coarse_tet_vertices) build.buildCoarseLevel();
  if (report_out) *report_out = std::move(build.report);
  return std::move(build.rig);
}

}  // namespace tetrig::rigbuild
