// The rig file: one binary, versioned, checksummed file holding everything the runtime needs to
// deform a character (byte layout: docs/rig-format.md, "Binary layout").
//
//   tetrig::Rig rig = tetrig::loadRigFile("man.rig");      // load time: allocates, may throw
//   tetrig::Deformer deformer(rig.tet_mesh, rig.setup);     // ready to step()
//   // per frame: device marker (mm, device axes) -> rig units with rig.alignment, write the
//   // target of marker k at targets.vertex_positions[rig.markers[k].vertex_handle];
//   // x_fine = B x_tet with rig.pose_transfer (tetrig/pose_transfer.hpp).
//   // pose sensors (rig.pose_sensors): tetrig::LiveRig drives their region handles (docs/live.md, "Pose sensors").
//
// File = 32-byte header (magic "TETRIGRF", format version, section count, file size, CRC-32C of
// every byte after the header) + a section table (tag, offset, size per section) + sections.
// Thirteen sections are required; optional ones (PSNS: pose sensors; CRSE: the coarse level, a
// whole rig file of its own; UVMT: the asset's texture coordinates and materials) are written only
// when the rig has something to put in them, and a file without them loads as before.
// The loader checks magic, version, file size, checksum, the layout (every section on an 8-byte
// boundary, no overlap, only zero padding between sections, nothing after the last, reserved
// words 0), every section's bounds and exact size, every count against the bytes present (before
// allocating), every index range and every float for finiteness, every string for UTF-8, then that
// the tet mesh has no inverted or degenerate tet and the markers' vertices and invisible tets are
// as the format says. Any mismatch throws
// RigFileError with one line naming the file, the section and what was wrong; a truncated or
// corrupted file never crashes the loader (tested at every truncation length and fuzzed).
//
// Threads: all functions are load-time code (allocate, may throw), callable from any thread;
// a Rig is a plain value with no hidden state.
#pragma once

#include "tetrig/deformer.hpp"
#include "tetrig/pose_transfer.hpp"
#include "tetrig/tet_mesh.hpp"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace tetrig {

class RigFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

inline constexpr std::uint32_t kRigFormatVersion = 1;
inline constexpr char kRigMagic[8] = {'T', 'E', 'T', 'R', 'I', 'G', 'R', 'F'};

// A marker bound to the rig (paper section 3.2): an extra tet vertex joined to the nearest boundary
// faces by invisible tets, driven as a vertex handle.
struct RigMarker {
  std::string label;                                  // e.g. "LFHD" (subject prefix removed)
  std::int32_t tet_vertex = -1;                       // index into tet_mesh.vertices
  std::int32_t vertex_handle = -1;                    // index into setup.vertex_handles (== tet_vertex there)
  Eigen::Vector3d rest_position = Eigen::Vector3d::Zero();  // rig units, after alignment
  std::int32_t bound_faces = 0;                       // invisible tets joining it to the body
  double surface_distance = 0.0;                      // rest distance to the fine surface, rig units
};

// Device -> rig mapping: x_rig = linear * x_device_mm + translation, where x_device_mm is a marker
// position in millimetres in the device's (or C3D file's) own axes (tetrig::MarkerFrame). linear =
// scale * R * (unit conversion and axis change); it is a similarity (linear = s Q, Q a rotation).
struct RigAlignment {
  Eigen::Matrix3d linear = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  double fit_scale = 1.0;       // the similarity fit's own scale factor (1 = units alone matched)
  double rig_units_per_mm = 1.0;  // unit conversion alone (0.001 for a rig in metres)
  std::string device_up = "z";  // device up axis as given ("x", "y", "z", "-z", ...)
  std::string rig_up = "y";     // rig up axis
  Eigen::Vector3d apply(const Eigen::Vector3d& device_mm) const { return linear * device_mm + translation; }
};

// How a pose sensor drives its region handle (docs/live.md, "Pose sensors", has the equations).
enum class PoseSensorMode : std::uint8_t {
  kClutch = 0,    // the region follows the controller's motion while a clutch button is held
  kAbsolute = 1,  // the region follows the controller's pose, anchored at its first valid sample
};

// A pose sensor (a marker with an orientation, e.g. one Razer Hydra controller) bound by its label
// to an oriented region handle. Stored in the optional PSNS section of the rig file.
struct RigPoseSensor {
  std::string sensor_label;                     // e.g. "hydra0": the label the source gives the marker
  std::int32_t region_handle = -1;              // index into setup.region_handles (an oriented region)
  PoseSensorMode mode = PoseSensorMode::kClutch;
  std::uint8_t clutch_buttons = 0xFF;           // clutch engaged while any of these Marker::buttons bits is set
  double translation_scale = 1.0;               // controller motion (rig units after alignment) -> region motion
};

// An oriented region handle driven by a rigid cluster of markers (e.g. the three markers on a
// shoe driving the foot). Each frame its target is the best-fit rigid transform (least squares,
// equal weights) from the markers' rest positions to the positions the live rig drives them to:
//   c0 = mean rest_i,  c = mean x_i,  H = sum (x_i - c)(rest_i - c0)^T,
//   R = the rotation closest to H (polar decomposition, tetrig::closestRotation),  t = c - R c0.
// The rotation then spreads over the mesh by rotation interpolation (section 3.3 of the paper), so
// the part turns with its markers from the first iteration. Stored in the optional MKRG section.
struct RigMarkerRegion {
  std::int32_t region_handle = -1;     // index into setup.region_handles (an oriented region)
  std::vector<std::int32_t> markers;   // indices into Rig::markers, at least 3, not collinear at rest
};

// A material of the asset the rig was built from (OBJ `usemtl` / .mtl `newmtl`).
struct RigMaterial {
  std::string name;             // as in `usemtl`
  std::string diffuse_texture;  // the .mtl's map_Kd, relative to the asset's folder ("" none)
  Eigen::Vector3d diffuse_color = Eigen::Vector3d::Ones();  // the .mtl's Kd ((1, 1, 1) when it gives none)
};

// The asset's texture coordinates and materials on the fine mesh (optional section UVMT; built
// from OBJ assets, docs/rig-format.md "Texture coordinates and materials"). Present when `uvs` or
// `materials` is not empty; then corner_uvs and triangle_materials have one row per fine triangle.
struct RigSurfaceAttributes {
  std::string asset;                               // the asset's absolute path when the rig was built ("" unknown)
  std::vector<std::string> material_libraries;     // `mtllib` files, relative to the asset's folder
  std::vector<RigMaterial> materials;              // in order of first use
  Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor> uvs;  // the asset's `vt` list in file order (u, v; v up)
  Triangles corner_uvs;                            // #F by 3: the uvs row of each fine-triangle corner, -1: none
  std::vector<std::int32_t> triangle_materials;    // #F: index into materials, -1: none
  bool empty() const { return uvs.rows() == 0 && materials.empty(); }
};

struct Rig {
  std::string name;              // free text: source mesh, clip
  std::string unit = "m";        // rig unit name ("m", "mm", "cm", "mesh")
  std::string builder;           // the program and version that built it

  TetMesh tet_mesh;              // body vertices first, then marker vertices; body tets first, then invisible tets
  std::int32_t body_vertex_count = 0;
  std::int32_t body_tet_count = 0;

  Vertices fine_vertices;        // #fine by 3, rest pose, rig units
  Triangles fine_triangles;      // #F by 3, outward (counter-clockwise seen from outside)
  PoseTransferCsr<double> pose_transfer;  // B: #fine rows by #tetV columns, rows sum to 1

  DeformerSetup setup;           // handles (markers are vertex handles), rigid groups, per-tet stiffness, options
  std::vector<std::string> vertex_handle_names;  // one per setup.vertex_handles ("" allowed)
  std::vector<std::string> region_handle_names;  // one per setup.region_handles
  std::vector<std::string> point_handle_names;   // one per setup.point_handles
  std::vector<std::string> rigid_group_names;    // one per setup.rigid_groups
  std::vector<RigMarker> markers;
  RigAlignment alignment;
  std::vector<RigPoseSensor> pose_sensors;       // optional (empty: the file has no PSNS section)
  std::vector<RigMarkerRegion> marker_regions;   // optional (empty: the file has no MKRG section)
  // Optional coarse level (docs/fidelity.md, "Coarse level"; the file's CRSE section, absent when null): the
  // same mesh and markers built with fewer tet vertices, in the same rig space. It has no coarse
  // level of its own, every marker of it is a marker of this rig (by label), and it has as many
  // region handles.
  std::shared_ptr<const Rig> coarse;
  // Optional texture coordinates and materials of the asset (section UVMT; empty(): absent).
  RigSurfaceAttributes surface;
};

// Serialises a rig into the file format (header, section table, sections, checksum). Validates the
// rig first (validateRig) and throws RigFileError on a fault. Allocates.
std::vector<std::uint8_t> serializeRig(const Rig& rig);

struct RigParseOptions {
  bool verify_checksum = true;  // false only for fuzzing the section parsers behind the checksum
};

// Parses bytes produced by serializeRig. `source_name` appears in messages. Throws RigFileError.
Rig parseRig(std::span<const std::uint8_t> bytes, std::string_view source_name, const RigParseOptions& options = {});

// Reads and parses a rig file. Throws RigFileError (also for a missing or unreadable file).
Rig loadRigFile(const std::filesystem::path& path);

// Each rig marker's rest position back in device millimetres (the inverse of rig.alignment), in
// rig.markers order: what a device would report with the subject in the rest pose (the synthetic
// source sways these). Load time: allocates; any thread.
std::vector<std::array<float, 3>> markerRestPositionsMm(const Rig& rig);

// Checks a rig's internal consistency (sizes, index ranges, finite values, orientation, B's rows
// summing to 1, marker handles, one marker vertex per marker after the body vertices, invisible
// tets of three body corners and one marker, bound-face counts = invisible tets, marker labels
// non-empty and distinct, positive alignment scales, every string well-formed UTF-8, pose sensors:
// label non-empty, region in range and oriented, one sensor per region, clutch buttons non-zero in
// clutch mode, finite positive translation scale, texture coordinates and materials with one row per
// fine triangle and their indices in range, and a coarse level as coarseLevelMismatch says).
// Returns "" when valid, else a one-line description of the first fault (file text in it escaped
// with printableText).
std::string validateRig(const Rig& rig);

// Why `coarse` cannot be the coarse level of `rig` (Rig::coarse, or a second file given to the live
// rig), "" when it can: it must be a valid rig without a coarse level of its own, every marker of it
// a marker of `rig` (by label), as many region handles, and the same alignment (one rig space,
// within 1e-9 relative).
std::string coarseLevelMismatch(const Rig& rig, const Rig& coarse);

// Bytes the rig's arrays occupy in memory (positions, tets, B, handles; excluding the Deformer).
std::int64_t rigMemoryBytes(const Rig& rig);

// CRC-32C (Castagnoli, reflected polynomial 0x82F63B78, init and xor-out 0xFFFFFFFF) as used in
// the rig file; rigCrc32c("123456789") == 0xE3069283. No allocation, any thread.
std::uint32_t rigCrc32c(std::span<const std::uint8_t> data, std::uint32_t previous = 0) noexcept;

}  // namespace tetrig
