// The tetrig rig file format (docs/rig-format.md, "Binary layout"): little-endian, magic
// "TETRIGRF", format version, section table, CRC-32C over everything after the header.
// The CRC-32C here is the Castagnoli CRC (reflected polynomial 0x82F63B78), table driven; the
// runtime may not link tetrig::drivers (which has its own copy for the marker-stream protocol).
#include "tetrig/rig_file.hpp"

#include "tetrig/printable_text.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <string_view>
#include <type_traits>
#include <unordered_map>

namespace tetrig {
namespace {

constexpr std::size_t kHeaderBytes = 32;
constexpr std::size_t kTableEntryBytes = 24;
constexpr std::uint32_t kMaxSections = 64;
constexpr std::uint32_t kMaxStringBytes = 1u << 16;

constexpr std::uint32_t tag(const char (&s)[5]) {
  return static_cast<std::uint32_t>(static_cast<unsigned char>(s[0])) |
         (static_cast<std::uint32_t>(static_cast<unsigned char>(s[1])) << 8) |
         (static_cast<std::uint32_t>(static_cast<unsigned char>(s[2])) << 16) |
         (static_cast<std::uint32_t>(static_cast<unsigned char>(s[3])) << 24);
}

constexpr std::uint32_t kTagMeta = tag("META");
constexpr std::uint32_t kTagTetVertices = tag("TETV");
constexpr std::uint32_t kTagTets = tag("TETS");
constexpr std::uint32_t kTagFine = tag("FINE");
constexpr std::uint32_t kTagPoseTransfer = tag("BCSR");
constexpr std::uint32_t kTagVertexHandles = tag("VHND");
constexpr std::uint32_t kTagRegionHandles = tag("RHND");
constexpr std::uint32_t kTagPointHandles = tag("PHND");
constexpr std::uint32_t kTagRigidGroups = tag("RGID");
constexpr std::uint32_t kTagStiffness = tag("STIF");
constexpr std::uint32_t kTagMarkers = tag("MARK");
constexpr std::uint32_t kTagAlignment = tag("ALGN");
constexpr std::uint32_t kTagOptions = tag("OPTS");
// Optional sections: written only when non-empty; absent means empty (files written before they
// existed stay loadable, and older readers skip them as unknown tags).
constexpr std::uint32_t kTagPoseSensors = tag("PSNS");
constexpr std::uint32_t kTagCoarse = tag("CRSE");  // the coarse level: a whole rig file (its own header and checksum)
constexpr std::uint32_t kTagMarkerRegions = tag("MKRG");  // regions driven by marker clusters
constexpr std::uint32_t kTagVolumeWeights = tag("VOLW");  // per-tet volume-term weights (DeformerSetup::volume_weights)
constexpr std::uint32_t kTagSurface = tag("UVMT");  // the asset's texture coordinates and materials (Rig::surface)
constexpr std::size_t kPoseSensorMinBytes = 4 + 4 + 1 + 1 + 8;  // empty label, region, mode, buttons, scale

std::string tagName(std::uint32_t t) {
  std::string s;
  for (int i = 0; i < 4; ++i) {
    const char c = static_cast<char>((t >> (8 * i)) & 0xFFu);
    s += (c >= 32 && c < 127) ? c : '?';
  }
  return s;
}

constexpr std::array<std::uint32_t, 256> makeCrcTable() {
  std::array<std::uint32_t, 256> table{};
  for (std::uint32_t i = 0; i < 256; ++i) {
    std::uint32_t c = i;
    for (int k = 0; k < 8; ++k) c = (c & 1u) ? (0x82F63B78u ^ (c >> 1)) : (c >> 1);
    table[i] = c;
  }
  return table;
}
constexpr std::array<std::uint32_t, 256> kCrcTable = makeCrcTable();

// ---- writing ----
class Writer {
 public:
  void u8(std::uint8_t v) { bytes_.push_back(v); }
  void u32(std::uint32_t v) {
    for (int i = 0; i < 4; ++i) bytes_.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void i32(std::int32_t v) { u32(static_cast<std::uint32_t>(v)); }
  void u64(std::uint64_t v) {
    for (int i = 0; i < 8; ++i) bytes_.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void f64(double v) {
    std::uint64_t b = 0;
    std::memcpy(&b, &v, sizeof b);
    u64(b);
  }
  void count(std::size_t n, const char* what) {
    if (n > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max())) {
      throw RigFileError(std::string("rig file: too many ") + what + " to store");
    }
    u32(static_cast<std::uint32_t>(n));
  }
  void str(const std::string& s) {
    if (s.size() > kMaxStringBytes) throw RigFileError("rig file: a name is longer than 65536 bytes: " + s.substr(0, 40));
    u32(static_cast<std::uint32_t>(s.size()));
    bytes_.insert(bytes_.end(), s.begin(), s.end());
  }
  // Every coefficient of a matrix, row after row.
  template <class Matrix>
  void f64Rows(const Matrix& m) {
    for (Eigen::Index i = 0; i < m.rows(); ++i)
      for (Eigen::Index k = 0; k < m.cols(); ++k) f64(static_cast<double>(m(i, k)));
  }
  template <class Matrix>
  void i32Rows(const Matrix& m) {
    for (Eigen::Index i = 0; i < m.rows(); ++i)
      for (Eigen::Index k = 0; k < m.cols(); ++k) i32(static_cast<std::int32_t>(m(i, k)));
  }
  void f64s(const std::vector<double>& v) {
    for (const double x : v) f64(x);
  }
  void i32s(const std::vector<std::int32_t>& v) {
    for (const std::int32_t x : v) i32(x);
  }
  void pad8() {
    while (bytes_.size() % 8 != 0) bytes_.push_back(0);
  }
  std::vector<std::uint8_t>& bytes() { return bytes_; }

 private:
  std::vector<std::uint8_t> bytes_;
};

// ---- reading: bounds-checked little-endian cursor over one section ----
class Cursor {
 public:
  Cursor(const std::uint8_t* data, std::size_t size, std::string where) : data_(data), size_(size), where_(std::move(where)) {}

  [[noreturn]] void fail(const std::string& what) const {
    throw RigFileError(where_ + " at byte " + std::to_string(pos_) + ": " + what);
  }
  std::size_t remaining() const { return size_ - pos_; }
  void need(std::size_t n, const char* what) const {
    if (n > remaining()) {
      fail(std::string("truncated: ") + what + " needs " + std::to_string(n) + " bytes, " + std::to_string(remaining()) +
           " left in the section");
    }
  }
  std::uint8_t u8(const char* what) {
    need(1, what);
    return data_[pos_++];
  }
  std::uint32_t u32(const char* what) {
    need(4, what);
    std::uint32_t v = 0;
    for (int i = 0; i < 4; ++i) v |= static_cast<std::uint32_t>(data_[pos_ + static_cast<std::size_t>(i)]) << (8 * i);
    pos_ += 4;
    return v;
  }
  std::int32_t i32(const char* what) { return static_cast<std::int32_t>(u32(what)); }
  std::uint64_t u64(const char* what) {
    need(8, what);
    std::uint64_t v = 0;
    for (int i = 0; i < 8; ++i) v |= static_cast<std::uint64_t>(data_[pos_ + static_cast<std::size_t>(i)]) << (8 * i);
    pos_ += 8;
    return v;
  }
  double f64(const char* what) {
    const std::uint64_t b = u64(what);
    double v = 0.0;
    std::memcpy(&v, &b, sizeof v);
    if (!std::isfinite(v)) fail(std::string("non-finite value in ") + what);
    return v;
  }
  // `rows` rows of a fixed-width matrix, row-major: f64 entries for a double matrix, i32 for an
  // integer one (each entry checked as f64/i32 check it; the whole size checked first).
  template <class Matrix>
  void rows(Matrix& m, std::size_t rows, const char* what) {
    using Scalar = typename Matrix::Scalar;
    constexpr bool kFloating = std::is_floating_point_v<Scalar>;
    constexpr auto kCols = static_cast<std::size_t>(Matrix::ColsAtCompileTime);
    static_assert(Matrix::ColsAtCompileTime > 0, "a fixed number of columns");
    need(rows * kCols * (kFloating ? 8 : 4), what);
    m.resize(static_cast<Eigen::Index>(rows), static_cast<Eigen::Index>(kCols));
    for (std::size_t i = 0; i < rows; ++i) {
      for (std::size_t k = 0; k < kCols; ++k) {
        if constexpr (kFloating) {
          m(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(k)) = f64(what);
        } else {
          m(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(k)) = i32(what);
        }
      }
    }
  }
  // A count of records of at least `min_record_bytes` each: checked against the bytes left before
  // anything is allocated.
  std::size_t count(const char* what, std::size_t min_record_bytes) {
    const std::uint32_t n = u32(what);
    if (n > static_cast<std::uint32_t>(std::numeric_limits<std::int32_t>::max())) fail(std::string("absurd count of ") + what);
    if (min_record_bytes > 0 && static_cast<std::uint64_t>(n) * min_record_bytes > remaining()) {
      fail(std::string("truncated: ") + std::to_string(n) + " " + what + " need at least " +
           std::to_string(static_cast<std::uint64_t>(n) * min_record_bytes) + " bytes, " + std::to_string(remaining()) +
           " left in the section");
    }
    return n;
  }
  std::string str(const char* what) {
    const std::uint32_t n = u32(what);
    if (n > kMaxStringBytes) fail(std::string(what) + " is longer than 65536 bytes");
    need(n, what);
    std::string s(reinterpret_cast<const char*>(data_ + pos_), n);
    pos_ += n;
    return s;
  }
  void end() const {
    if (pos_ != size_) fail(std::to_string(size_ - pos_) + " unexpected bytes at the end of the section");
  }

 private:
  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t pos_ = 0;
  std::string where_;
};

void writeSection(Writer& w, std::vector<std::array<std::uint64_t, 3>>& table, std::uint32_t t,
                  const std::vector<std::uint8_t>& body) {
  w.pad8();
  table.push_back({t, w.bytes().size(), body.size()});
  w.bytes().insert(w.bytes().end(), body.begin(), body.end());
}

bool finite3(const Eigen::Vector3d& v) { return v.allFinite(); }

// Why the texture coordinates and materials do not fit a fine mesh of `triangles` triangles ("" when they do).
std::string surfaceAttributesFault(const RigSurfaceAttributes& a, std::int32_t triangles) {
  auto num = [](auto v) { return std::to_string(v); };
  if (a.empty()) {
    if (a.corner_uvs.rows() != 0 || !a.triangle_materials.empty() || !a.material_libraries.empty() || !a.asset.empty()) {
      return "texture coordinates and materials: per-triangle data or file names without a uv table or materials";
    }
    return {};
  }
  if (a.corner_uvs.rows() != triangles || a.triangle_materials.size() != static_cast<std::size_t>(triangles)) {
    return "texture coordinates and materials: " + num(a.corner_uvs.rows()) + " corner rows and " + num(a.triangle_materials.size()) +
           " triangle materials for " + num(triangles) + " fine triangles";
  }
  if (!a.uvs.allFinite()) return "texture coordinates: a uv is not finite";
  const auto uv_count = static_cast<std::int32_t>(a.uvs.rows());
  for (Eigen::Index f = 0; f < a.corner_uvs.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const std::int32_t u = a.corner_uvs(f, k);
      if (u < -1 || u >= uv_count) return "texture coordinates: fine triangle " + num(f) + " names uv " + num(u) + " of " + num(uv_count);
    }
  }
  const auto material_count = static_cast<std::int32_t>(a.materials.size());
  for (std::size_t f = 0; f < a.triangle_materials.size(); ++f) {
    const std::int32_t m = a.triangle_materials[f];
    if (m < -1 || m >= material_count) return "materials: fine triangle " + num(f) + " names material " + num(m) + " of " + num(material_count);
  }
  auto utf8 = [](const std::string& text, const std::string& what) -> std::string {
    return isWellFormedUtf8(text) ? std::string() : what + " is not valid UTF-8 ('" + printableText(text, 64) + "')";
  };
  if (std::string e = utf8(a.asset, "the asset's path"); !e.empty()) return e;
  for (std::size_t i = 0; i < a.material_libraries.size(); ++i) {
    if (std::string e = utf8(a.material_libraries[i], "material library " + num(i)); !e.empty()) return e;
  }
  for (std::size_t i = 0; i < a.materials.size(); ++i) {
    const RigMaterial& m = a.materials[i];
    if (std::string e = utf8(m.name, "the name of material " + num(i)); !e.empty()) return e;
    if (std::string e = utf8(m.diffuse_texture, "the texture of material " + num(i)); !e.empty()) return e;
    if (!m.diffuse_color.allFinite()) return "material " + num(i) + " has a non-finite colour";
  }
  return {};
}

}  // namespace

std::uint32_t rigCrc32c(std::span<const std::uint8_t> data, std::uint32_t previous) noexcept {
  std::uint32_t c = previous ^ 0xFFFFFFFFu;
  for (const std::uint8_t b : data) c = kCrcTable[(c ^ b) & 0xFFu] ^ (c >> 8);
  return c ^ 0xFFFFFFFFu;
}

std::vector<std::array<float, 3>> markerRestPositionsMm(const Rig& rig) {
  const Eigen::Matrix3d inverse = rig.alignment.linear.inverse();
  std::vector<std::array<float, 3>> out;
  out.reserve(rig.markers.size());
  for (const RigMarker& m : rig.markers) {
    const Eigen::Vector3d mm = inverse * (m.rest_position - rig.alignment.translation);
    out.push_back({static_cast<float>(mm.x()), static_cast<float>(mm.y()), static_cast<float>(mm.z())});
  }
  return out;
}

namespace {

// The tet mesh (body counts, tets) and the fine mesh (finite vertices, triangles in range).
std::string meshFault(const Rig& rig) {
  const std::int32_t nv = rig.tet_mesh.vertexCount();
  const std::int32_t nt = rig.tet_mesh.tetCount();
  const std::int32_t nf = static_cast<std::int32_t>(rig.fine_vertices.rows());
  auto num = [](auto v) { return std::to_string(v); };
  if (nv <= 0 || nt <= 0) return "the tet mesh is empty";
  if (rig.body_vertex_count < 4 || rig.body_vertex_count > nv) return "body vertex count " + num(rig.body_vertex_count) + " is not in [4, " + num(nv) + "]";
  if (rig.body_tet_count < 1 || rig.body_tet_count > nt) return "body tet count " + num(rig.body_tet_count) + " is not in [1, " + num(nt) + "]";
  const TetMeshReport report = checkTetMesh(rig.tet_mesh);
  if (!report.ok()) return "tet mesh: " + report.summary();
  if (nf <= 0) return "the fine mesh has no vertices";
  if (!rig.fine_vertices.allFinite()) return "the fine mesh has non-finite vertices";
  for (Eigen::Index f = 0; f < rig.fine_triangles.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const std::int32_t v = rig.fine_triangles(f, k);
      if (v < 0 || v >= nf) return "fine triangle " + num(f) + " names vertex " + num(v) + " of " + num(nf);
    }
  }
  return {};
}

// The pose-transfer matrix B: its size, its CSR arrays, rows summing to 1.
std::string poseTransferFault(const Rig& rig) {
  const std::int32_t nv = rig.tet_mesh.vertexCount();
  const std::int32_t nf = static_cast<std::int32_t>(rig.fine_vertices.rows());
  auto num = [](auto v) { return std::to_string(v); };
  const PoseTransferCsr<double>& b = rig.pose_transfer;
  if (b.rows != nf || b.cols != nv) {
    return "pose transfer B is " + num(b.rows) + " x " + num(b.cols) + ", expected " + num(nf) + " x " + num(nv);
  }
  if (b.row_offsets.size() != static_cast<std::size_t>(b.rows) + 1 || b.columns.size() != b.weights.size() ||
      b.row_offsets.front() != 0 || b.row_offsets.back() < 0 ||
      static_cast<std::size_t>(b.row_offsets.back()) != b.columns.size()) {
    return "pose transfer B: array sizes do not match its row offsets";
  }
  if (std::string e = validatePoseTransfer(b.view()); !e.empty()) return "pose transfer B: " + e;
  for (std::int32_t r = 0; r < b.rows; ++r) {
    double sum = 0.0;
    for (std::int32_t k = b.row_offsets[static_cast<std::size_t>(r)]; k < b.row_offsets[static_cast<std::size_t>(r) + 1]; ++k) {
      sum += b.weights[static_cast<std::size_t>(k)];
    }
    if (!(std::abs(sum - 1.0) <= 1e-6)) return "pose transfer B: row " + num(r) + " sums to " + std::to_string(sum) + ", not 1";
  }
  return {};
}

// The vertex, region and point handles: in range, no vertex handle twice.
std::string handlesFault(const Rig& rig) {
  const std::int32_t nv = rig.tet_mesh.vertexCount();
  const std::int32_t nt = rig.tet_mesh.tetCount();
  auto num = [](auto v) { return std::to_string(v); };
  const DeformerSetup& s = rig.setup;
  std::vector<std::uint8_t> used(static_cast<std::size_t>(nv), 0);
  for (std::size_t h = 0; h < s.vertex_handles.size(); ++h) {
    const std::int32_t v = s.vertex_handles[h];
    if (v < 0 || v >= nv) return "vertex handle " + num(h) + " names vertex " + num(v) + " of " + num(nv);
    if (used[static_cast<std::size_t>(v)]) return "vertex " + num(v) + " is a vertex handle twice";
    used[static_cast<std::size_t>(v)] = 1;
  }
  for (std::size_t r = 0; r < s.region_handles.size(); ++r) {
    if (s.region_handles[r].tets.empty()) return "region handle " + num(r) + " has no tets";
    for (const std::int32_t t : s.region_handles[r].tets) {
      if (t < 0 || t >= nt) return "region handle " + num(r) + " names tet " + num(t) + " of " + num(nt);
    }
  }
  for (std::size_t p = 0; p < s.point_handles.size(); ++p) {
    const PointHandle& ph = s.point_handles[p];
    if (ph.tet < 0 || ph.tet >= nt) return "point handle " + num(p) + " names tet " + num(ph.tet) + " of " + num(nt);
    if (!ph.barycentric.allFinite() || std::abs(ph.barycentric.sum() - 1.0) > 1e-6) {
      return "point handle " + num(p) + " has barycentric weights that are not finite or do not sum to 1";
    }
  }
  return {};
}

// The rigid groups (disjoint), the stiffness and the volume weights (one valid value per tet).
std::string groupsAndWeightsFault(const Rig& rig) {
  const std::int32_t nt = rig.tet_mesh.tetCount();
  auto num = [](auto v) { return std::to_string(v); };
  const DeformerSetup& s = rig.setup;
  std::vector<std::uint8_t> grouped(static_cast<std::size_t>(nt), 0);
  for (std::size_t g = 0; g < s.rigid_groups.size(); ++g) {
    for (const std::int32_t t : s.rigid_groups[g].tets) {
      if (t < 0 || t >= nt) return "rigid group " + num(g) + " names tet " + num(t) + " of " + num(nt);
      if (grouped[static_cast<std::size_t>(t)]) return "tet " + num(t) + " is in two rigid groups";
      grouped[static_cast<std::size_t>(t)] = 1;
    }
  }
  if (!s.stiffness.empty()) {
    if (s.stiffness.size() != static_cast<std::size_t>(nt)) return "stiffness has " + num(s.stiffness.size()) + " values for " + num(nt) + " tets";
    for (std::size_t t = 0; t < s.stiffness.size(); ++t) {
      if (!(s.stiffness[t] > 0.0) || !std::isfinite(s.stiffness[t])) return "stiffness of tet " + num(t) + " is not a positive number";
    }
  }
  if (!s.volume_weights.empty()) {
    if (s.volume_weights.size() != static_cast<std::size_t>(nt)) {
      return "volume weights has " + num(s.volume_weights.size()) + " values for " + num(nt) + " tets";
    }
    for (std::size_t t = 0; t < s.volume_weights.size(); ++t) {
      if (!(s.volume_weights[t] >= 0.0 && s.volume_weights[t] < 1.0)) return "volume weight of tet " + num(t) + " is not in [0, 1)";
    }
  }
  return {};
}

// One name per handle and rigid group.
std::string handleNamesFault(const Rig& rig) {
  const DeformerSetup& s = rig.setup;
  if (rig.vertex_handle_names.size() != s.vertex_handles.size() || rig.region_handle_names.size() != s.region_handles.size() ||
      rig.point_handle_names.size() != s.point_handles.size() || rig.rigid_group_names.size() != s.rigid_groups.size()) {
    return "the handle name lists do not match the handle counts";
  }
  return {};
}

// The invisible tets: each body tet without a marker corner, each invisible tet with one; each
// marker joined to the body by as many invisible tets as it says (marker_of: marker vertex -> marker).
std::string markerBindingFault(const Rig& rig, const std::vector<std::int32_t>& marker_of) {
  const std::int32_t nt = rig.tet_mesh.tetCount();
  auto num = [](auto v) { return std::to_string(v); };
  std::vector<std::int32_t> bound(rig.markers.size(), 0);
  for (std::int32_t t = 0; t < nt; ++t) {
    std::int32_t markers_in_tet = 0, marker_vertex = -1;
    for (int k = 0; k < 4; ++k) {
      const std::int32_t v = rig.tet_mesh.tets(t, k);
      if (v >= rig.body_vertex_count) {
        ++markers_in_tet;
        marker_vertex = v;
      }
    }
    if (t < rig.body_tet_count && markers_in_tet != 0) return "body tet " + num(t) + " names marker vertex " + num(marker_vertex);
    if (t >= rig.body_tet_count) {
      if (markers_in_tet != 1) return "invisible tet " + num(t) + " has " + num(markers_in_tet) + " marker corners, not 1";
      ++bound[static_cast<std::size_t>(marker_of[static_cast<std::size_t>(marker_vertex - rig.body_vertex_count)])];
    }
  }
  for (std::size_t m = 0; m < rig.markers.size(); ++m) {
    if (rig.markers[m].bound_faces != bound[m]) {
      return "marker " + num(m) + " (" + printableText(rig.markers[m].label, 64) + ") says " + num(rig.markers[m].bound_faces) +
             " bound faces but " + num(bound[m]) + " invisible tets join it to the body";
    }
    if (bound[m] == 0) return "marker " + num(m) + " (" + printableText(rig.markers[m].label, 64) + ") is joined to the body by no invisible tet";
  }
  return {};
}

// The markers: one marker vertex each, its vertex handle, finite values, distinct UTF-8 labels; then
// their binding by the invisible tets.
std::string markersFault(const Rig& rig) {
  const std::int32_t nv = rig.tet_mesh.vertexCount();
  auto num = [](auto v) { return std::to_string(v); };
  const DeformerSetup& s = rig.setup;
  // Markers: the tet vertices after the body ones, one per marker, each joined to the body by the
  // invisible tets (the tets after the body ones, each with three body corners and one marker).
  const std::int32_t marker_vertices = nv - rig.body_vertex_count;
  if (static_cast<std::size_t>(marker_vertices) != rig.markers.size()) {
    return "the tet mesh has " + num(marker_vertices) + " vertices after its " + num(rig.body_vertex_count) + " body vertices but the rig has " +
           num(rig.markers.size()) + " markers (one vertex per marker)";
  }
  std::vector<std::int32_t> marker_of(static_cast<std::size_t>(marker_vertices), -1);
  std::unordered_map<std::string_view, std::size_t> label_owner;  // linear in the marker count, even for a hostile file
  label_owner.reserve(rig.markers.size());
  for (std::size_t m = 0; m < rig.markers.size(); ++m) {
    const RigMarker& mk = rig.markers[m];
    const std::string who = "marker " + num(m) + " (" + printableText(mk.label, 64) + ")";
    if (mk.label.empty()) return "marker " + num(m) + " has an empty label";
    if (!isWellFormedUtf8(mk.label)) return who + ": the label is not valid UTF-8";
    if (mk.tet_vertex < rig.body_vertex_count || mk.tet_vertex >= nv) {
      return who + " names tet vertex " + num(mk.tet_vertex) + ", not a marker vertex (" + num(rig.body_vertex_count) + ".." + num(nv - 1) + ")";
    }
    std::int32_t& owner = marker_of[static_cast<std::size_t>(mk.tet_vertex - rig.body_vertex_count)];
    if (owner >= 0) return who + " and marker " + num(owner) + " name the same tet vertex " + num(mk.tet_vertex);
    owner = static_cast<std::int32_t>(m);
    if (mk.vertex_handle < 0 || static_cast<std::size_t>(mk.vertex_handle) >= s.vertex_handles.size() ||
        s.vertex_handles[static_cast<std::size_t>(mk.vertex_handle)] != mk.tet_vertex) {
      return who + " is not the vertex handle it names (" + num(mk.vertex_handle) + ")";
    }
    if (!finite3(mk.rest_position) || !std::isfinite(mk.surface_distance)) return who + " has a non-finite rest position";
    if (mk.bound_faces < 0) return who + " has a negative bound-face count (" + num(mk.bound_faces) + ")";
    if (const auto [it, fresh] = label_owner.emplace(mk.label, m); !fresh) {
      return who + " has the label of marker " + num(it->second) + ": labels must be distinct";
    }
  }
  return markerBindingFault(rig, marker_of);
}

// The alignment: finite, invertible, positive scale and unit.
std::string alignmentFault(const Rig& rig) {
  const RigAlignment& a = rig.alignment;
  if (!a.linear.allFinite() || !a.translation.allFinite() || !std::isfinite(a.fit_scale) || !std::isfinite(a.rig_units_per_mm) ||
      std::abs(a.linear.determinant()) <= 0.0) {
    return "the alignment transform is not finite and invertible";
  }
  if (!(a.fit_scale > 0.0) || !(a.rig_units_per_mm > 0.0)) return "the alignment's fit scale or unit conversion is not positive";
  return {};
}

// The pose sensors and marker regions: each drives one oriented region handle, none driven twice;
// a marker region names at least three distinct, not collinear markers.
std::string drivenRegionsFault(const Rig& rig) {
  auto num = [](auto v) { return std::to_string(v); };
  const DeformerSetup& s = rig.setup;
  // Each oriented region handle is driven by at most one pose sensor or marker cluster.
  std::vector<std::uint8_t> driven(s.region_handles.size(), 0);
  const auto claimRegion = [&](const std::string& who, std::int32_t region) -> std::string {
    if (region < 0 || static_cast<std::size_t>(region) >= s.region_handles.size()) {
      return who + " names region handle " + num(region) + " of " + num(s.region_handles.size());
    }
    const auto r = static_cast<std::size_t>(region);
    if (!s.region_handles[r].oriented) return who + " drives region handle " + num(r) + ", which is not oriented";
    if (driven[r]) return "region handle " + num(r) + " is driven twice (by pose sensors or marker clusters)";
    driven[r] = 1;
    return {};
  };
  for (std::size_t p = 0; p < rig.pose_sensors.size(); ++p) {
    const RigPoseSensor& ps = rig.pose_sensors[p];
    const std::string who = "pose sensor " + num(p) + (ps.sensor_label.empty() ? std::string() : " (" + printableText(ps.sensor_label, 64) + ")");
    if (ps.sensor_label.empty()) return who + " has an empty sensor label";
    if (std::string error = claimRegion(who, ps.region_handle); !error.empty()) return error;
    if (ps.mode != PoseSensorMode::kClutch && ps.mode != PoseSensorMode::kAbsolute) return who + " has an unknown mode";
    if (ps.mode == PoseSensorMode::kClutch && ps.clutch_buttons == 0) return who + " is in clutch mode with no clutch button";
    if (!(ps.translation_scale > 0.0) || !std::isfinite(ps.translation_scale)) {
      return who + " has a translation scale that is not a finite positive number";
    }
  }
  for (std::size_t k = 0; k < rig.marker_regions.size(); ++k) {
    const RigMarkerRegion& mr = rig.marker_regions[k];
    const std::string who = "marker region " + num(k);
    if (std::string error = claimRegion(who, mr.region_handle); !error.empty()) return error;
    if (mr.markers.size() < 3) return who + " has " + num(mr.markers.size()) + " markers (a rotation needs at least 3)";
    Eigen::Vector3d c0 = Eigen::Vector3d::Zero();
    for (std::size_t i = 0; i < mr.markers.size(); ++i) {
      const std::int32_t m = mr.markers[i];
      if (m < 0 || static_cast<std::size_t>(m) >= rig.markers.size()) return who + " names marker " + num(m) + " of " + num(rig.markers.size());
      for (std::size_t j = 0; j < i; ++j) {
        if (mr.markers[j] == m) return who + " names marker " + num(m) + " twice";
      }
      c0 += rig.markers[static_cast<std::size_t>(m)].rest_position / static_cast<double>(mr.markers.size());
    }
    // Not collinear: the rest positions must spread across their main axis.
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (const std::int32_t m : mr.markers) {
      const Eigen::Vector3d d = rig.markers[static_cast<std::size_t>(m)].rest_position - c0;
      cov += d * d.transpose();
    }
    const Eigen::Vector3d ev = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov, Eigen::EigenvaluesOnly).eigenvalues();
    if (!(ev(1) > 1e-6 * ev(2))) return who + ": its markers lie on a line at rest (the rotation about it is not defined)";
  }
  return {};
}

// Every string is valid UTF-8.
std::string stringsFault(const Rig& rig) {
  auto num = [](auto v) { return std::to_string(v); };
  const RigAlignment& a = rig.alignment;
  // Every string is UTF-8 (the format says so); printing escapes control characters (printable_text.hpp).
  auto utf8 = [](const std::string& text, const std::string& what) -> std::string {
    return isWellFormedUtf8(text) ? std::string() : what + " is not valid UTF-8 ('" + printableText(text, 64) + "')";
  };
  auto utf8_list = [&](const std::vector<std::string>& names, const char* what) -> std::string {
    for (std::size_t i = 0; i < names.size(); ++i) {
      if (std::string e = utf8(names[i], std::string(what) + " " + num(i)); !e.empty()) return e;
    }
    return {};
  };
  for (const std::string& e : {utf8(rig.name, "the rig name"), utf8(rig.unit, "the unit"), utf8(rig.builder, "the builder"),
                               utf8(a.device_up, "the device up axis"), utf8(a.rig_up, "the rig up axis"),
                               utf8_list(rig.vertex_handle_names, "the name of vertex handle"),
                               utf8_list(rig.region_handle_names, "the name of region handle"),
                               utf8_list(rig.point_handle_names, "the name of point handle"),
                               utf8_list(rig.rigid_group_names, "the name of rigid group")}) {
    if (!e.empty()) return e;
  }
  for (std::size_t p = 0; p < rig.pose_sensors.size(); ++p) {
    if (std::string e = utf8(rig.pose_sensors[p].sensor_label, "the label of pose sensor " + num(p)); !e.empty()) return e;
  }
  return {};
}

// The deformer options: rotation steps in range, positive finite weights.
std::string optionsFault(const Rig& rig) {
  auto num = [](auto v) { return std::to_string(v); };
  const DeformerOptions& o = rig.setup.options;
  if (o.rotation_steps < 0 || o.rotation_steps > 64) return "rotation_steps " + num(o.rotation_steps) + " is not in [0, 64]";
  if (!(o.point_handle_weight > 0.0) || !std::isfinite(o.point_handle_weight) || !(o.max_abs_coordinate > 0.0) ||
      !std::isfinite(o.max_abs_coordinate)) {
    return "deformer options hold a non-positive or non-finite weight";
  }
  return {};
}

}  // namespace

std::string validateRig(const Rig& rig) {
  // Each step returns the first fault it finds ("" when none).
  if (std::string e = meshFault(rig); !e.empty()) return e;
  if (std::string e = poseTransferFault(rig); !e.empty()) return e;
  if (std::string e = handlesFault(rig); !e.empty()) return e;
  if (std::string e = groupsAndWeightsFault(rig); !e.empty()) return e;
  if (std::string e = handleNamesFault(rig); !e.empty()) return e;
  if (std::string e = markersFault(rig); !e.empty()) return e;
  if (std::string e = alignmentFault(rig); !e.empty()) return e;
  if (std::string e = drivenRegionsFault(rig); !e.empty()) return e;
  if (std::string e = stringsFault(rig); !e.empty()) return e;
  // The texture coordinates and materials fit the fine mesh.
  if (std::string e = surfaceAttributesFault(rig.surface, static_cast<std::int32_t>(rig.fine_triangles.rows())); !e.empty()) return e;
  if (std::string e = optionsFault(rig); !e.empty()) return e;
  if (rig.coarse) return coarseLevelMismatch(rig, *rig.coarse);
  return {};
}

std::string coarseLevelMismatch(const Rig& rig, const Rig& coarse) {
  auto num = [](auto v) { return std::to_string(v); };
  if (coarse.coarse) return "the coarse level has a coarse level of its own";
  if (std::string e = validateRig(coarse); !e.empty()) return "the coarse level: " + e;
  if (coarse.setup.region_handles.size() != rig.setup.region_handles.size()) {
    return "the coarse level has " + num(coarse.setup.region_handles.size()) + " region handles, the rig " +
           num(rig.setup.region_handles.size());
  }
  for (const RigMarker& m : coarse.markers) {
    if (std::none_of(rig.markers.begin(), rig.markers.end(), [&m](const RigMarker& r) { return r.label == m.label; })) {
      return "the coarse level's marker '" + printableText(m.label, 64) + "' is not a marker of the rig";
    }
  }
  // The same rig space: the coarse level is driven with the rig's own marker targets.
  const RigAlignment& a = rig.alignment;
  const double tolerance = 1e-9 * (a.linear.norm() + a.translation.norm() + 1.0);
  if ((coarse.alignment.linear - a.linear).norm() > tolerance || (coarse.alignment.translation - a.translation).norm() > tolerance ||
      coarse.alignment.rig_units_per_mm != a.rig_units_per_mm) {
    return "the coarse level's alignment (device -> rig) differs from the rig's: build both from the same mesh and clip frame";
  }
  return {};
}

std::vector<std::uint8_t> serializeRig(const Rig& rig) {
  if (std::string e = validateRig(rig); !e.empty()) throw RigFileError("rig file: cannot write an invalid rig: " + e);
  std::vector<std::array<std::uint64_t, 3>> table;
  // The sections, at offsets from their own start: the header and the table (32 + 24 n bytes, a
  // multiple of 8, so every section stays 8-aligned) go in front once n is known.
  Writer out;
  // One section: its body written by `fill` into a writer of its own, then appended and listed.
  const auto section = [&out, &table](std::uint32_t tag, auto&& fill) {
    Writer w;
    fill(w);
    writeSection(out, table, tag, w.bytes());
  };
  section(kTagMeta, [&](Writer& w) {
    w.str(rig.name);
    w.str(rig.unit);
    w.str(rig.builder);
  });
  section(kTagTetVertices, [&](Writer& w) {
    w.count(static_cast<std::size_t>(rig.tet_mesh.vertexCount()), "tet vertices");
    w.u32(static_cast<std::uint32_t>(rig.body_vertex_count));
    w.f64Rows(rig.tet_mesh.vertices);
  });
  section(kTagTets, [&](Writer& w) {
    w.count(static_cast<std::size_t>(rig.tet_mesh.tetCount()), "tets");
    w.u32(static_cast<std::uint32_t>(rig.body_tet_count));
    w.i32Rows(rig.tet_mesh.tets);
  });
  section(kTagFine, [&](Writer& w) {
    w.count(static_cast<std::size_t>(rig.fine_vertices.rows()), "fine vertices");
    w.count(static_cast<std::size_t>(rig.fine_triangles.rows()), "fine triangles");
    w.f64Rows(rig.fine_vertices);
    w.i32Rows(rig.fine_triangles);
  });
  section(kTagPoseTransfer, [&](Writer& w) {
    const PoseTransferCsr<double>& b = rig.pose_transfer;
    w.u32(static_cast<std::uint32_t>(b.rows));
    w.u32(static_cast<std::uint32_t>(b.cols));
    w.count(b.columns.size(), "pose-transfer weights");
    w.i32s(b.row_offsets);
    w.i32s(b.columns);
    w.f64s(b.weights);
  });
  section(kTagVertexHandles, [&](Writer& w) {
    w.count(rig.setup.vertex_handles.size(), "vertex handles");
    for (std::size_t h = 0; h < rig.setup.vertex_handles.size(); ++h) {
      w.i32(rig.setup.vertex_handles[h]);
      w.str(rig.vertex_handle_names[h]);
    }
  });
  section(kTagRegionHandles, [&](Writer& w) {
    w.count(rig.setup.region_handles.size(), "region handles");
    for (std::size_t r = 0; r < rig.setup.region_handles.size(); ++r) {
      const RegionHandle& region = rig.setup.region_handles[r];
      w.u8(region.oriented ? 1 : 0);
      w.str(rig.region_handle_names[r]);
      w.count(region.tets.size(), "region tets");
      w.i32s(region.tets);
    }
  });
  section(kTagPointHandles, [&](Writer& w) {
    w.count(rig.setup.point_handles.size(), "point handles");
    for (std::size_t p = 0; p < rig.setup.point_handles.size(); ++p) {
      const PointHandle& ph = rig.setup.point_handles[p];
      w.i32(ph.tet);
      for (int k = 0; k < 4; ++k) w.f64(ph.barycentric[k]);
      w.str(rig.point_handle_names[p]);
    }
  });
  section(kTagRigidGroups, [&](Writer& w) {
    w.count(rig.setup.rigid_groups.size(), "rigid groups");
    for (std::size_t g = 0; g < rig.setup.rigid_groups.size(); ++g) {
      w.str(rig.rigid_group_names[g]);
      w.count(rig.setup.rigid_groups[g].tets.size(), "rigid group tets");
      w.i32s(rig.setup.rigid_groups[g].tets);
    }
  });
  section(kTagStiffness, [&](Writer& w) {
    w.count(rig.setup.stiffness.size(), "stiffness values");
    w.f64s(rig.setup.stiffness);
  });
  section(kTagMarkers, [&](Writer& w) {
    w.count(rig.markers.size(), "markers");
    for (const RigMarker& m : rig.markers) {
      w.str(m.label);
      w.i32(m.tet_vertex);
      w.i32(m.vertex_handle);
      for (int k = 0; k < 3; ++k) w.f64(m.rest_position[k]);
      w.i32(m.bound_faces);
      w.f64(m.surface_distance);
    }
  });
  section(kTagAlignment, [&](Writer& w) {
    const RigAlignment& a = rig.alignment;
    w.f64Rows(a.linear);
    for (int k = 0; k < 3; ++k) w.f64(a.translation[k]);
    w.f64(a.fit_scale);
    w.f64(a.rig_units_per_mm);
    w.str(a.device_up);
    w.str(a.rig_up);
  });
  section(kTagOptions, [&](Writer& w) {
    const DeformerOptions& o = rig.setup.options;
    w.u8(o.update_rotations ? 1 : 0);
    w.u8(o.interpolate_rotations ? 1 : 0);
    w.i32(o.rotation_steps);
    w.f64(o.point_handle_weight);
    w.f64(o.max_abs_coordinate);
  });
  // The optional sections, written only when they hold something.
  if (!rig.pose_sensors.empty()) {
    section(kTagPoseSensors, [&](Writer& w) {
      w.count(rig.pose_sensors.size(), "pose sensors");
      for (const RigPoseSensor& ps : rig.pose_sensors) {
        w.str(ps.sensor_label);
        w.i32(ps.region_handle);
        w.u8(static_cast<std::uint8_t>(ps.mode));
        w.u8(ps.clutch_buttons);
        w.f64(ps.translation_scale);
      }
    });
  }
  if (!rig.marker_regions.empty()) {
    section(kTagMarkerRegions, [&](Writer& w) {
      w.count(rig.marker_regions.size(), "marker regions");
      for (const RigMarkerRegion& mr : rig.marker_regions) {
        w.i32(mr.region_handle);
        w.count(mr.markers.size(), "markers of a marker region");
        w.i32s(mr.markers);
      }
    });
  }
  if (!rig.setup.volume_weights.empty()) {
    section(kTagVolumeWeights, [&](Writer& w) {
      w.count(rig.setup.volume_weights.size(), "volume weights");
      w.f64s(rig.setup.volume_weights);
    });
  }
  if (!rig.surface.empty()) {
    section(kTagSurface, [&](Writer& w) {
      const RigSurfaceAttributes& a = rig.surface;
      w.str(a.asset);
      w.count(a.material_libraries.size(), "material libraries");
      for (const std::string& l : a.material_libraries) w.str(l);
      w.count(a.materials.size(), "materials");
      for (const RigMaterial& m : a.materials) {
        w.str(m.name);
        w.str(m.diffuse_texture);
        for (int k = 0; k < 3; ++k) w.f64(m.diffuse_color[k]);
      }
      w.count(static_cast<std::size_t>(a.uvs.rows()), "texture coordinates");
      w.f64Rows(a.uvs);
      w.count(static_cast<std::size_t>(a.corner_uvs.rows()), "textured triangles");
      for (Eigen::Index f = 0; f < a.corner_uvs.rows(); ++f) {
        for (int k = 0; k < 3; ++k) w.i32(a.corner_uvs(f, k));
        w.i32(a.triangle_materials[static_cast<std::size_t>(f)]);
      }
    });
  }
  if (rig.coarse) writeSection(out, table, kTagCoarse, serializeRig(*rig.coarse));
  // No padding after the last section: the file ends where it does.
  const std::size_t prefix = kHeaderBytes + table.size() * kTableEntryBytes;
  std::vector<std::uint8_t> bytes(prefix, 0);
  bytes.insert(bytes.end(), out.bytes().begin(), out.bytes().end());
  // Section table.
  for (std::size_t i = 0; i < table.size(); ++i) {
    Writer e;
    e.u32(static_cast<std::uint32_t>(table[i][0]));
    e.u32(0);
    e.u64(prefix + table[i][1]);
    e.u64(table[i][2]);
    std::copy(e.bytes().begin(), e.bytes().end(), bytes.begin() + static_cast<std::ptrdiff_t>(kHeaderBytes + i * kTableEntryBytes));
  }
  // Header.
  Writer h;
  for (const char c : kRigMagic) h.u8(static_cast<std::uint8_t>(c));
  h.u32(kRigFormatVersion);
  h.u32(static_cast<std::uint32_t>(table.size()));
  h.u64(bytes.size());
  h.u32(rigCrc32c(std::span<const std::uint8_t>(bytes).subspan(kHeaderBytes)));
  h.u32(0);
  std::copy(h.bytes().begin(), h.bytes().end(), bytes.begin());
  return bytes;
}

namespace {

// A fault in the file `name`: thrown as "name: what".
[[noreturn]] void fileFault(const std::string& name, const std::string& what) { throw RigFileError(name + ": " + what); }

// Checks the header (magic, version, size, reserved word, checksum, section count); returns the
// section count.
std::uint32_t checkHeader(std::span<const std::uint8_t> bytes, const std::string& name, const RigParseOptions& options) {
  auto fail = [&name](const std::string& what) -> void { fileFault(name, what); };
  if (bytes.size() < kHeaderBytes) {
    fail("not a rig file: " + std::to_string(bytes.size()) + " bytes, shorter than the 32-byte header");
  }
  if (std::memcmp(bytes.data(), kRigMagic, sizeof kRigMagic) != 0) fail("not a rig file (magic is not TETRIGRF)");
  Cursor header(bytes.data() + 8, kHeaderBytes - 8, name + ": header");
  const std::uint32_t version = header.u32("version");
  const std::uint32_t section_count = header.u32("section count");
  const std::uint64_t file_size = header.u64("file size");
  const std::uint32_t crc = header.u32("checksum");
  const std::uint32_t reserved = header.u32("reserved");
  if (version != kRigFormatVersion) {
    fail("rig format version " + std::to_string(version) + ", this program reads version " + std::to_string(kRigFormatVersion) +
         ": rebuild the rig with this version's `tetrig build-rig`");
  }
  if (file_size != bytes.size()) {
    fail("the header says " + std::to_string(file_size) + " bytes but the file has " + std::to_string(bytes.size()) +
         " (truncated or appended to): rebuild or re-copy it");
  }
  if (reserved != 0) fail("reserved header word is not 0");
  if (options.verify_checksum) {
    const std::uint32_t actual = rigCrc32c(bytes.subspan(kHeaderBytes));
    if (actual != crc) {
      std::ostringstream s;
      s << std::hex << "checksum mismatch (stored 0x" << crc << ", computed 0x" << actual
        << "): the file is corrupted; rebuild or re-copy it";
      fail(s.str());
    }
  }
  if (section_count == 0 || section_count > kMaxSections) fail("absurd section count " + std::to_string(section_count));
  return section_count;
}

// One entry of the section table.
struct Entry {
  std::uint32_t tag;
  std::size_t offset, size;
};

// Reads the section table and checks each entry (a printable tag, a reserved 0, inside the file,
// 8-byte aligned, no tag twice).
std::vector<Entry> readSectionTable(std::span<const std::uint8_t> bytes, const std::string& name, std::uint32_t section_count,
                                    std::size_t table_end) {
  auto fail = [&name](const std::string& what) -> void { fileFault(name, what); };
  if (table_end > bytes.size()) fail("truncated section table");
  std::vector<Entry> entries;
  Cursor table(bytes.data() + kHeaderBytes, section_count * kTableEntryBytes, name + ": section table");
  for (std::uint32_t i = 0; i < section_count; ++i) {
    const std::uint32_t t = table.u32("tag");
    const std::uint32_t entry_reserved = table.u32("reserved");
    const std::uint64_t offset = table.u64("offset");
    const std::uint64_t size = table.u64("size");
    const std::string entry = "section table entry " + std::to_string(i) + " (" + tagName(t) + ")";
    for (int k = 0; k < 4; ++k) {
      const std::uint32_t c = (t >> (8 * k)) & 0xFFu;
      if (c < 0x20 || c > 0x7E) fail(entry + ": the tag is not four printable ASCII characters: the file is corrupt or not a rig");
    }
    if (entry_reserved != 0) {
      fail(entry + ": reserved word is " + std::to_string(entry_reserved) + ", not 0: the file is corrupt or not a rig");
    }
    if (offset < table_end || offset > bytes.size() || size > bytes.size() - offset) {
      fail("section " + tagName(t) + " lies outside the file (offset " + std::to_string(offset) + ", size " + std::to_string(size) + ")");
    }
    if (offset % 8 != 0) fail("section " + tagName(t) + " starts at byte " + std::to_string(offset) + ", not on an 8-byte boundary");
    for (const Entry& e : entries) {
      if (e.tag == t) fail("section " + tagName(t) + " appears twice");
    }
    entries.push_back({t, static_cast<std::size_t>(offset), static_cast<std::size_t>(size)});
  }
  return entries;
}

// Layout (docs/rig-format.md): in file order, the first section starts right after the table
// and each further one at the end of the one before rounded up to 8 bytes, with zero padding
// between them; the last one ends the file. No byte of the file is outside the header, the
// table, a section or that padding, and no two sections share a byte.
void checkSectionLayout(std::span<const std::uint8_t> bytes, const std::string& name, const std::vector<Entry>& entries, std::size_t table_end) {
  auto fail = [&name](const std::string& what) -> void { fileFault(name, what); };
  std::vector<Entry> by_offset = entries;
  std::stable_sort(by_offset.begin(), by_offset.end(),
                   [](const Entry& a, const Entry& b) { return a.offset != b.offset ? a.offset < b.offset : a.size < b.size; });
  std::size_t end = table_end;
  std::string previous = "the section table";
  for (const Entry& e : by_offset) {
    const std::string here = "section " + tagName(e.tag) + " (bytes " + std::to_string(e.offset) + ".." + std::to_string(e.offset + e.size) + ")";
    if (e.offset < end) fail(here + " overlaps " + previous + ", which ends at byte " + std::to_string(end));
    const std::size_t expected = (end + 7) / 8 * 8;
    if (e.offset != expected) {
      fail(here + " starts " + std::to_string(e.offset - end) + " bytes after the end of " + previous + " (byte " + std::to_string(end) +
           "); only the zero padding up to the next 8-byte boundary (byte " + std::to_string(expected) + ") may lie between sections");
    }
    for (std::size_t at = end; at < e.offset; ++at) {
      if (bytes[at] != 0) fail("padding byte " + std::to_string(at) + " before " + here + " is not 0");
    }
    end = e.offset + e.size;
    previous = "section " + tagName(e.tag);
  }
  if (end != bytes.size()) {
    fail(std::to_string(bytes.size() - end) + " bytes after the last section (" + previous + " ends at byte " + std::to_string(end) +
         ", the file at " + std::to_string(bytes.size()) + "): the file is corrupt or was appended to");
  }
}

// The checked sections of a file, by tag.
struct Sections {
  std::span<const std::uint8_t> bytes;
  const std::string& name;
  std::vector<Entry> entries;

  bool has(std::uint32_t t) const {
    return std::any_of(entries.begin(), entries.end(), [t](const Entry& e) { return e.tag == t; });
  }
  // A cursor over section t; a missing section is an error.
  Cursor section(std::uint32_t t) const {
    for (const Entry& e : entries) {
      if (e.tag == t) return Cursor(bytes.data() + e.offset, e.size, name + ": section " + tagName(t));
    }
    throw RigFileError(name + ": section " + tagName(t) + " is missing");
  }
};

// META, TETV, TETS, FINE: the rig's name, unit and builder, the tet mesh and the fine mesh.
void readMeshSections(const Sections& sections, Rig& rig) {
  {
    Cursor c = sections.section(kTagMeta);
    rig.name = c.str("rig name");
    rig.unit = c.str("unit");
    rig.builder = c.str("builder");
    c.end();
  }
  {
    Cursor c = sections.section(kTagTetVertices);
    const std::size_t n = c.count("tet vertices", 0);
    rig.body_vertex_count = static_cast<std::int32_t>(c.u32("body vertex count"));
    c.rows(rig.tet_mesh.vertices, n, "tet vertex positions");
    c.end();
  }
  {
    Cursor c = sections.section(kTagTets);
    const std::size_t n = c.count("tets", 0);
    rig.body_tet_count = static_cast<std::int32_t>(c.u32("body tet count"));
    c.rows(rig.tet_mesh.tets, n, "tet corners");
    c.end();
  }
  {
    Cursor c = sections.section(kTagFine);
    const std::size_t nv = c.count("fine vertices", 0);
    const std::size_t nf = c.count("fine triangles", 0);
    c.need(nv * 24 + nf * 12, "fine mesh");
    c.rows(rig.fine_vertices, nv, "fine vertex positions");
    c.rows(rig.fine_triangles, nf, "fine triangle corners");
    c.end();
  }
}

// The pose-transfer matrix B (CSR).
void readPoseTransfer(Cursor c, PoseTransferCsr<double>& b) {
  const std::uint32_t rows = c.u32("B rows");
  const std::uint32_t cols = c.u32("B columns");
  if (rows > static_cast<std::uint32_t>(std::numeric_limits<std::int32_t>::max() - 1) ||
      cols > static_cast<std::uint32_t>(std::numeric_limits<std::int32_t>::max())) {
    c.fail("absurd B size");
  }
  const std::size_t nnz = c.count("pose-transfer weights", 0);
  c.need((static_cast<std::size_t>(rows) + 1) * 4 + nnz * 12, "pose-transfer matrix");
  b.rows = static_cast<std::int32_t>(rows);
  b.cols = static_cast<std::int32_t>(cols);
  b.row_offsets.resize(static_cast<std::size_t>(rows) + 1);
  for (std::int32_t& o : b.row_offsets) o = c.i32("B row offset");
  b.columns.resize(nnz);
  for (std::int32_t& col : b.columns) col = c.i32("B column");
  b.weights.resize(nnz);
  for (double& x : b.weights) x = c.f64("B weight");
  c.end();
}

// A section that is a count and that many finite doubles (STIF, VOLW). `count_what` and `item_what`
// name them in messages.
void readDoubles(Cursor c, std::vector<double>& out, const char* count_what, const char* item_what) {
  out.resize(c.count(count_what, 8));
  for (double& x : out) x = c.f64(item_what);
  c.end();
}

// VHND, RHND, PHND, RGRP, STIF: the handles with their names, the rigid groups and the stiffness.
void readHandleSections(const Sections& sections, Rig& rig) {
  {
    Cursor c = sections.section(kTagVertexHandles);
    const std::size_t n = c.count("vertex handles", 8);
    rig.setup.vertex_handles.resize(n);
    rig.vertex_handle_names.resize(n);
    for (std::size_t h = 0; h < n; ++h) {
      rig.setup.vertex_handles[h] = c.i32("vertex handle");
      rig.vertex_handle_names[h] = c.str("vertex handle name");
    }
    c.end();
  }
  {
    Cursor c = sections.section(kTagRegionHandles);
    const std::size_t n = c.count("region handles", 9);
    rig.setup.region_handles.resize(n);
    rig.region_handle_names.resize(n);
    for (std::size_t r = 0; r < n; ++r) {
      const std::uint8_t oriented = c.u8("region orientation flag");
      if (oriented > 1) c.fail("region orientation flag is not 0 or 1");
      rig.setup.region_handles[r].oriented = oriented == 1;
      rig.region_handle_names[r] = c.str("region handle name");
      const std::size_t nt = c.count("region tets", 4);
      rig.setup.region_handles[r].tets.resize(nt);
      for (std::int32_t& t : rig.setup.region_handles[r].tets) t = c.i32("region tet");
    }
    c.end();
  }
  {
    Cursor c = sections.section(kTagPointHandles);
    const std::size_t n = c.count("point handles", 40);
    rig.setup.point_handles.resize(n);
    rig.point_handle_names.resize(n);
    for (std::size_t p = 0; p < n; ++p) {
      rig.setup.point_handles[p].tet = c.i32("point handle tet");
      for (int k = 0; k < 4; ++k) rig.setup.point_handles[p].barycentric[k] = c.f64("point handle weight");
      rig.point_handle_names[p] = c.str("point handle name");
    }
    c.end();
  }
  {
    Cursor c = sections.section(kTagRigidGroups);
    const std::size_t n = c.count("rigid groups", 8);
    rig.setup.rigid_groups.resize(n);
    rig.rigid_group_names.resize(n);
    for (std::size_t g = 0; g < n; ++g) {
      rig.rigid_group_names[g] = c.str("rigid group name");
      const std::size_t nt = c.count("rigid group tets", 4);
      rig.setup.rigid_groups[g].tets.resize(nt);
      for (std::int32_t& t : rig.setup.rigid_groups[g].tets) t = c.i32("rigid group tet");
    }
    c.end();
  }
  readDoubles(sections.section(kTagStiffness), rig.setup.stiffness, "stiffness values", "stiffness");
}

// MARK: the markers.
void readMarkers(Cursor c, std::vector<RigMarker>& markers) {
  const std::size_t n = c.count("markers", 48);
  markers.resize(n);
  for (RigMarker& m : markers) {
    m.label = c.str("marker label");
    m.tet_vertex = c.i32("marker tet vertex");
    m.vertex_handle = c.i32("marker vertex handle");
    for (int k = 0; k < 3; ++k) m.rest_position[k] = c.f64("marker rest position");
    m.bound_faces = c.i32("marker bound faces");
    m.surface_distance = c.f64("marker surface distance");
  }
  c.end();
}

// ALGN: device mm -> rig units.
void readAlignment(Cursor c, RigAlignment& a) {
  for (int r = 0; r < 3; ++r) {
    for (int k = 0; k < 3; ++k) a.linear(r, k) = c.f64("alignment matrix");
  }
  for (int k = 0; k < 3; ++k) a.translation[k] = c.f64("alignment translation");
  a.fit_scale = c.f64("alignment scale");
  a.rig_units_per_mm = c.f64("alignment unit");
  a.device_up = c.str("device up axis");
  a.rig_up = c.str("rig up axis");
  c.end();
}

// OPTS: the deformer options.
void readOptions(Cursor c, DeformerOptions& o) {
  const std::uint8_t update = c.u8("update_rotations");
  const std::uint8_t interpolate = c.u8("interpolate_rotations");
  if (update > 1 || interpolate > 1) c.fail("option flags are not 0 or 1");
  o.update_rotations = update == 1;
  o.interpolate_rotations = interpolate == 1;
  o.rotation_steps = c.i32("rotation_steps");
  o.point_handle_weight = c.f64("point_handle_weight");
  o.max_abs_coordinate = c.f64("max_abs_coordinate");
  c.end();
}

// The optional pose-sensor section.
void readPoseSensors(Cursor c, std::vector<RigPoseSensor>& pose_sensors) {
  const std::size_t n = c.count("pose sensors", kPoseSensorMinBytes);
  pose_sensors.resize(n);
  for (RigPoseSensor& ps : pose_sensors) {
    ps.sensor_label = c.str("pose sensor label");
    ps.region_handle = c.i32("pose sensor region handle");
    const std::uint8_t mode = c.u8("pose sensor mode");
    if (mode > static_cast<std::uint8_t>(PoseSensorMode::kAbsolute)) {
      c.fail("pose sensor mode " + std::to_string(mode) + " is not 0 (clutch) or 1 (absolute)");
    }
    ps.mode = static_cast<PoseSensorMode>(mode);
    ps.clutch_buttons = c.u8("pose sensor clutch buttons");
    ps.translation_scale = c.f64("pose sensor translation scale");
  }
  c.end();
}

// The optional marker-region section.
void readMarkerRegions(Cursor c, std::vector<RigMarkerRegion>& marker_regions) {
  const std::size_t n = c.count("marker regions", 8);
  marker_regions.resize(n);
  for (RigMarkerRegion& mr : marker_regions) {
    mr.region_handle = c.i32("marker region handle");
    const std::size_t k = c.count("markers of a marker region", 4);
    mr.markers.resize(k);
    for (std::int32_t& m : mr.markers) m = c.i32("marker region marker");
  }
  c.end();
}

// The optional section of texture coordinates and materials; it may not be empty.
void readSurface(Cursor c, RigSurfaceAttributes& a) {
  a.asset = c.str("asset path");
  a.material_libraries.resize(c.count("material libraries", 4));
  for (std::string& l : a.material_libraries) l = c.str("material library");
  a.materials.resize(c.count("materials", 32));
  for (RigMaterial& m : a.materials) {
    m.name = c.str("material name");
    m.diffuse_texture = c.str("material texture");
    for (int k = 0; k < 3; ++k) m.diffuse_color[k] = c.f64("material colour");
  }
  const std::size_t uvs = c.count("texture coordinates", 16);
  c.rows(a.uvs, uvs, "texture coordinates");
  const std::size_t triangles = c.count("textured triangles", 16);
  a.corner_uvs.resize(static_cast<Eigen::Index>(triangles), 3);
  a.triangle_materials.resize(triangles);
  for (std::size_t f = 0; f < triangles; ++f) {
    for (int k = 0; k < 3; ++k) a.corner_uvs(static_cast<Eigen::Index>(f), k) = c.i32("corner uv");
    a.triangle_materials[f] = c.i32("triangle material");
  }
  c.end();
  if (a.empty()) c.fail("the section holds neither texture coordinates nor materials");
}

Rig parseRigAt(std::span<const std::uint8_t> bytes, std::string_view source_name, const RigParseOptions& options, bool nested);

}  // namespace

Rig parseRig(std::span<const std::uint8_t> bytes, std::string_view source_name, const RigParseOptions& options) {
  return parseRigAt(bytes, source_name, options, false);
}

namespace {
// nested: parsing a CRSE section, which may not hold one of its own (checked before parsing it, so
// a crafted file cannot nest levels to any depth).
Rig parseRigAt(std::span<const std::uint8_t> bytes, std::string_view source_name, const RigParseOptions& options, bool nested) {
  const std::string name(source_name);
  // The header, then the section table and the sections' layout.
  const std::uint32_t section_count = checkHeader(bytes, name, options);
  const std::size_t table_end = kHeaderBytes + section_count * kTableEntryBytes;
  const Sections sections{bytes, name, readSectionTable(bytes, name, section_count, table_end)};
  checkSectionLayout(bytes, name, sections.entries, table_end);

  // The required sections, in file-format order.
  Rig rig;
  readMeshSections(sections, rig);
  readPoseTransfer(sections.section(kTagPoseTransfer), rig.pose_transfer);
  readHandleSections(sections, rig);
  readMarkers(sections.section(kTagMarkers), rig.markers);
  readAlignment(sections.section(kTagAlignment), rig.alignment);
  readOptions(sections.section(kTagOptions), rig.setup.options);
  // The optional sections.
  if (sections.has(kTagPoseSensors)) readPoseSensors(sections.section(kTagPoseSensors), rig.pose_sensors);
  if (sections.has(kTagMarkerRegions)) readMarkerRegions(sections.section(kTagMarkerRegions), rig.marker_regions);
  if (sections.has(kTagVolumeWeights)) readDoubles(sections.section(kTagVolumeWeights), rig.setup.volume_weights, "volume weights", "volume weight");
  if (sections.has(kTagSurface)) readSurface(sections.section(kTagSurface), rig.surface);
  // The coarse level: a whole rig in section CRSE, itself without one.
  if (sections.has(kTagCoarse)) {
    if (nested) fileFault(name, "the coarse level has a coarse level of its own (section CRSE)");
    for (const Entry& e : sections.entries) {
      if (e.tag != kTagCoarse) continue;
      Rig coarse = parseRigAt(bytes.subspan(e.offset, e.size), name + ": section CRSE (the coarse level)", options, true);
      rig.coarse = std::make_shared<const Rig>(std::move(coarse));
    }
  }
  if (std::string e = validateRig(rig); !e.empty()) fileFault(name, e);
  return rig;
}
}  // namespace

Rig loadRigFile(const std::filesystem::path& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw RigFileError(path.string() + ": is a folder, not a rig file (give the .rig file that tetrig build-rig wrote)");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw RigFileError(path.string() + ": cannot open the rig file (missing or unreadable)");
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw RigFileError(path.string() + ": read error");
  return parseRig(bytes, path.string());
}

std::int64_t rigMemoryBytes(const Rig& rig) {
  std::int64_t bytes = 0;
  bytes += rig.tet_mesh.vertices.size() * 8 + rig.tet_mesh.tets.size() * 4;
  bytes += rig.fine_vertices.size() * 8 + rig.fine_triangles.size() * 4;
  bytes += rig.pose_transfer.bytes();
  bytes += static_cast<std::int64_t>(rig.setup.vertex_handles.size() * 4 + rig.setup.point_handles.size() * 40 +
                                     (rig.setup.stiffness.size() + rig.setup.volume_weights.size()) * 8 + rig.markers.size() * sizeof(RigMarker) +
                                     rig.pose_sensors.size() * sizeof(RigPoseSensor));
  for (const RigMarkerRegion& mr : rig.marker_regions) bytes += static_cast<std::int64_t>(8 + mr.markers.size() * 4);
  for (const RegionHandle& r : rig.setup.region_handles) bytes += static_cast<std::int64_t>(r.tets.size() * 4);
  for (const RigidGroup& g : rig.setup.rigid_groups) bytes += static_cast<std::int64_t>(g.tets.size() * 4);
  const RigSurfaceAttributes& a = rig.surface;
  bytes += static_cast<std::int64_t>(a.uvs.size() * 8 + a.corner_uvs.size() * 4 + a.triangle_materials.size() * 4);
  if (rig.coarse) bytes += rigMemoryBytes(*rig.coarse);
  return bytes;
}

}  // namespace tetrig
