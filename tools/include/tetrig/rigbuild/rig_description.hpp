// The rig description: a small JSON file saying which parts of a mesh are handles, rigid groups
// and stiff or soft, and how markers bind (documented in docs/rig-format.md, "Rig description").
//
// Selections refer to the FINE mesh (vertex ids, a deformation-survey .sel file) or to space in
// rig units (box, sphere, around a marker); the tet mesh is generated, so they are resolved onto
// tet vertices and tets after tetrahedralization (see build_rig.hpp).
//
// Offline, any thread, allocates, throws RigBuildError with the file name and the JSON path
// (e.g. "man.json: region_handles[2].select: unknown selection kind 'cube'").
#pragma once

#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/alignment_checks.hpp"
#include "tetrig/rigbuild/surface_mesh.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace tetrig::rigbuild {

struct Selection {
  enum class Kind { kVertices, kSelFile, kBox, kSphere, kNearMarker };
  Kind kind = Kind::kVertices;
  std::vector<std::int32_t> vertices;      // kVertices: fine-mesh vertex ids (tet ids for a tet-mesh input)
  std::filesystem::path sel_file;          // kSelFile: one status per line per fine vertex
  std::vector<std::int32_t> sel_values;    // kSelFile: statuses selected (e.g. {2} = handle)
  Eigen::Vector3d min = Eigen::Vector3d::Zero(), max = Eigen::Vector3d::Zero();  // kBox, rig units
  Eigen::Vector3d center = Eigen::Vector3d::Zero();                             // kSphere
  double radius = 0.0;                     // kSphere, kNearMarker (rig units)
  std::string marker;                      // kNearMarker: label
  int min_corners = 4;                     // a tet is selected when >= this many corners are (1..4); 4: the region never grows past the selection
  std::string where;                       // JSON path, for messages
};

struct NamedSelection {
  std::string name;
  Selection select;
  bool oriented = true;    // region handles only
  std::vector<std::string> markers;  // region handles only: a marker cluster driving it (RigMarkerRegion); empty: none
  double value = 1.0;      // stiffness and volume entries only
};

struct PointHandleSpec {
  std::string name;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // rig units, rest pose
};

struct MarkerOptions {
  std::filesystem::path clip;              // C3D file; empty = no markers (the CLI's --markers wins)
  std::int64_t frame = 0;                  // rest frame, 0-based index into the clip
  bool frame_auto = false;                 // "frame": "auto": the frame that best fits the mesh's rest pose (rest_frame_search.hpp)
  std::vector<std::string> labels;         // empty = every labelled physical marker
  std::vector<std::string> exclude;
  std::string device_up = "z";             // C3D convention
  std::string alignment = "auto";          // "auto" (coarse + similarity ICP), "units" (axes and unit only), "matrix"
  std::vector<double> matrix;              // "matrix": 12 numbers, 3x4 row-major, device mm -> rig units
  int icp_iterations = 60;
  bool icp_scale = true;                   // similarity (true) or rigid (false) ICP
  double max_scale_change = 0.25;          // ICP scale kept within (1 +- this) of the height-based estimate
  double marker_offset = 0.0;              // expected marker height above the skin (rig units) during ICP
  double fit_power = 2.0;                  // ICP minimises sum |r|^p (2: least squares; IRLS otherwise)
  std::optional<double> max_distance;      // rig units; a marker further from the surface stops the build
  double max_distance_fraction = 0.06;     // ... without max_distance: this fraction of the mesh's bounding-box diagonal
  AlignmentCheckLimits checks;             // plausibility of an automatic alignment (alignment_checks.hpp)
  int faces_per_marker = 6;                // invisible tets per marker (closest qualifying boundary faces)
  double face_spread = 0.0;                // MarkerBindOptions::face_spread (0: the nearest faces)
  double fan_spread = 0.0;                 // MarkerBindOptions::fan_spread (0: faces)
  int fan_spokes = 6;                      // MarkerBindOptions::fan_spokes
  double fan_weight = 1.0;                 // MarkerBindOptions::fan_weight
  double invisible_stiffness = 10.0;       // stiffness weight of invisible tets (body tets: 1): a marker's offset
                                           // from the skin turns with the skin (docs/fidelity.md)
  bool rigid_regions = true;               // markers that move rigidly together over the clip drive the skin
                                           // around them as an oriented region (rigid_marker_groups.hpp);
                                           // only when the description has no region_handles
  bool keep_zero_points = false;           // C3D samples at x = y = z = 0 with residual 0 are valid, not
                                           // gaps (drivers::C3DReadOptions; CLI --keep-zero-markers)
};

// A pose sensor (e.g. "hydra1", one Razer Hydra controller) driving an oriented region handle of
// the same description (runtime: tetrig/pose_sensor.hpp).
struct PoseSensorSpec {
  std::string sensor;                      // the marker label the source gives the sensor
  std::string region;                      // name of a region handle of this description
  std::int32_t region_index = -1;          // its index in region_handles (resolved by the parser)
  PoseSensorMode mode = PoseSensorMode::kClutch;
  std::uint8_t clutch_buttons = 0xFF;      // clutch engaged while any of these button bits is set (1..255)
  double translation_scale = 1.0;          // controller motion (rig units) -> region motion, > 0
  std::string where;                       // JSON path, for messages
};

struct RigDescription {
  std::filesystem::path source;            // the JSON file ("" when built from defaults)
  std::string name;
  std::string mesh_unit = "m";             // "m", "cm", "mm" or "auto" (from the mesh's height)
  std::string mesh_up = "y";
  std::int32_t tet_vertices = 2500;        // decimation target (surface inputs)
  double pose_radius_fraction = 0.05;      // paper section 2.4: 5 % of the bounding-box diagonal
  std::int32_t pose_max_nonzeros = 0;      // 0 = uncapped
  std::vector<NamedSelection> vertex_handles;
  std::vector<NamedSelection> region_handles;
  std::vector<PointHandleSpec> point_handles;
  std::vector<NamedSelection> rigid_groups;
  std::vector<NamedSelection> stiffness;   // later entries override earlier ones
  std::vector<NamedSelection> volume;      // volume-term weights in [0, 1) (DeformerSetup::volume_weights); later entries override
  MarkerOptions markers;
  std::vector<PoseSensorSpec> pose_sensors;
  int rotation_steps = 2;
  double point_handle_weight = 1e3;
};

// Parses a rig description (see docs/rig-format.md). Relative paths in it (sel files, clip) are
// resolved against the JSON file's directory.
RigDescription readRigDescription(const std::filesystem::path& path);
RigDescription parseRigDescription(const std::string& json_text, const std::filesystem::path& source);

// Millimetres -> rig unit factor for a unit name ("m" 0.001, "cm" 0.1, "mm" 1). Throws for others.
double rigUnitsPerMm(const std::string& unit);

}  // namespace tetrig::rigbuild
