// Rig description JSON reader (format: docs/rig-format.md, "Rig description").
#include "tetrig/rigbuild/rig_description.hpp"

#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>
#include <type_traits>

namespace tetrig::rigbuild {
namespace {

using nlohmann::json;

class Reader {
 public:
  Reader(std::string file, std::filesystem::path base) : file_(std::move(file)), base_(std::move(base)) {}

  [[noreturn]] void fail(const std::string& where, const std::string& what) const {
    throw RigBuildError(file_ + ": " + (where.empty() ? std::string("top level") : where) + ": " + what);
  }

  void allowKeys(const json& j, const std::string& where, std::initializer_list<const char*> keys) const {
    if (!j.is_object()) fail(where, "expected an object");
    std::set<std::string> allowed;
    for (const char* k : keys) allowed.insert(k);
    for (auto it = j.begin(); it != j.end(); ++it) {
      if (!allowed.count(it.key())) {
        std::string list;
        for (const char* k : keys) list += std::string(list.empty() ? "" : ", ") + k;
        fail(where, "unknown key '" + it.key() + "' (allowed: " + list + ")");
      }
    }
  }

  double number(const json& j, const std::string& where) const {
    if (!j.is_number()) fail(where, "expected a number");
    const double v = j.get<double>();
    if (!std::isfinite(v)) fail(where, "expected a finite number");
    return v;
  }
  // A JSON integer in [lo, hi], checked on the full value before any conversion: a number beyond
  // 64 bits, a fraction, or a number written with a fraction or an exponent (2.0, 1e3) is refused,
  // never wrapped or truncated ("rotation_steps": 4294967298 must not become 2).
  template <typename T>
  T integer(const json& j, const std::string& where, T lo, T hi) const {
    static_assert(std::is_integral_v<T> && sizeof(T) <= sizeof(std::int64_t));
    const std::string range = "an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
    if (j.is_number_unsigned()) {
      const std::uint64_t v = j.get<std::uint64_t>();
      if (hi < 0 || v > static_cast<std::uint64_t>(hi) || (lo > 0 && v < static_cast<std::uint64_t>(lo))) {
        fail(where, "expected " + range + ", got " + std::to_string(v));
      }
      return static_cast<T>(v);
    }
    if (j.is_number_integer()) {
      const std::int64_t v = j.get<std::int64_t>();
      if (v < static_cast<std::int64_t>(lo) || v > static_cast<std::int64_t>(hi)) fail(where, "expected " + range + ", got " + std::to_string(v));
      return static_cast<T>(v);
    }
    if (j.is_number()) fail(where, "expected " + range + ", got " + j.dump() + " (write integers without a fraction or exponent)");
    fail(where, "expected " + range);
  }
  std::string string(const json& j, const std::string& where) const {
    if (!j.is_string()) fail(where, "expected a string");
    return j.get<std::string>();
  }
  bool boolean(const json& j, const std::string& where) const {
    if (!j.is_boolean()) fail(where, "expected true or false");
    return j.get<bool>();
  }
  Eigen::Vector3d vec3(const json& j, const std::string& where) const {
    if (!j.is_array() || j.size() != 3) fail(where, "expected [x, y, z]");
    return {number(j[0], where + "[0]"), number(j[1], where + "[1]"), number(j[2], where + "[2]")};
  }
  std::vector<std::string> strings(const json& j, const std::string& where) const {
    if (!j.is_array()) fail(where, "expected an array of strings");
    std::vector<std::string> out;
    for (std::size_t i = 0; i < j.size(); ++i) out.push_back(string(j[i], where + "[" + std::to_string(i) + "]"));
    return out;
  }
  std::filesystem::path path(const json& j, const std::string& where) const {
    std::filesystem::path p = string(j, where);
    if (p.is_relative()) p = base_ / p;
    return p;
  }

  Selection selection(const json& j, const std::string& where) const {
    allowKeys(j, where, {"vertices", "sel_file", "sel_values", "box", "sphere", "near_marker", "radius", "min_corners"});
    Selection s;
    s.where = where;
    int kinds = 0;
    if (j.contains("vertices")) {
      ++kinds;
      s.kind = Selection::Kind::kVertices;
      const json& v = j["vertices"];
      if (!v.is_array() || v.empty()) fail(where + ".vertices", "expected a non-empty array of vertex ids");
      for (std::size_t i = 0; i < v.size(); ++i) {
        s.vertices.push_back(integer<std::int32_t>(v[i], where + ".vertices[" + std::to_string(i) + "]", 0,
                                                   std::numeric_limits<std::int32_t>::max()));
      }
    }
    if (j.contains("sel_file")) {
      ++kinds;
      s.kind = Selection::Kind::kSelFile;
      s.sel_file = path(j["sel_file"], where + ".sel_file");
      if (!j.contains("sel_values")) fail(where, "sel_file needs sel_values, e.g. [2] for the handle of a deformation-survey .sel");
      const json& v = j["sel_values"];
      if (!v.is_array() || v.empty()) fail(where + ".sel_values", "expected a non-empty array of integers");
      for (std::size_t i = 0; i < v.size(); ++i) {
        s.sel_values.push_back(integer<std::int32_t>(v[i], where + ".sel_values[" + std::to_string(i) + "]",
                                                     std::numeric_limits<std::int32_t>::min(), std::numeric_limits<std::int32_t>::max()));
      }
    } else if (j.contains("sel_values")) {
      fail(where, "sel_values without sel_file");
    }
    if (j.contains("box")) {
      ++kinds;
      s.kind = Selection::Kind::kBox;
      allowKeys(j["box"], where + ".box", {"min", "max"});
      if (!j["box"].contains("min") || !j["box"].contains("max")) fail(where + ".box", "needs min and max");
      s.min = vec3(j["box"]["min"], where + ".box.min");
      s.max = vec3(j["box"]["max"], where + ".box.max");
      if ((s.max.array() < s.min.array()).any()) fail(where + ".box", "max is below min on some axis");
    }
    if (j.contains("sphere")) {
      ++kinds;
      s.kind = Selection::Kind::kSphere;
      allowKeys(j["sphere"], where + ".sphere", {"center", "radius"});
      if (!j["sphere"].contains("center") || !j["sphere"].contains("radius")) fail(where + ".sphere", "needs center and radius");
      s.center = vec3(j["sphere"]["center"], where + ".sphere.center");
      s.radius = number(j["sphere"]["radius"], where + ".sphere.radius");
      if (!(s.radius > 0)) fail(where + ".sphere.radius", "must be positive");
    }
    if (j.contains("near_marker")) {
      ++kinds;
      s.kind = Selection::Kind::kNearMarker;
      s.marker = string(j["near_marker"], where + ".near_marker");
      if (!j.contains("radius")) fail(where, "near_marker needs a radius (rig units)");
      s.radius = number(j["radius"], where + ".radius");
      if (!(s.radius > 0)) fail(where + ".radius", "must be positive");
    } else if (j.contains("radius")) {
      fail(where, "radius belongs to near_marker (a sphere takes sphere.radius)");
    }
    if (kinds != 1) fail(where, "give exactly one of vertices, sel_file, box, sphere, near_marker");
    if (j.contains("min_corners")) {
      s.min_corners = integer<int>(j["min_corners"], where + ".min_corners", 1, 4);
    }
    return s;
  }

  enum class Value { kNone, kStiffness, kVolume };  // what an entry's `value` is

  std::vector<NamedSelection> list(const json& root, const char* key, bool region, Value value = Value::kNone) const {
    std::vector<NamedSelection> out;
    if (!root.contains(key)) return out;
    const json& arr = root[key];
    if (!arr.is_array()) fail(key, "expected an array");
    for (std::size_t i = 0; i < arr.size(); ++i) {
      const std::string where = std::string(key) + "[" + std::to_string(i) + "]";
      if (region) {
        allowKeys(arr[i], where, {"name", "select", "oriented", "markers"});
      } else if (value != Value::kNone) {
        allowKeys(arr[i], where, {"name", "select", "value"});
      } else {
        allowKeys(arr[i], where, {"name", "select"});
      }
      NamedSelection n;
      n.name = arr[i].contains("name") ? string(arr[i]["name"], where + ".name") : std::string(key) + std::to_string(i);
      if (!arr[i].contains("select")) fail(where, "needs a select");
      n.select = selection(arr[i]["select"], where + ".select");
      if (region && arr[i].contains("oriented")) n.oriented = boolean(arr[i]["oriented"], where + ".oriented");
      if (region && arr[i].contains("markers")) {
        n.markers = strings(arr[i]["markers"], where + ".markers");
        if (n.markers.size() < 3) fail(where + ".markers", "needs at least 3 marker labels (a rigid cluster fixes a rotation)");
        for (std::size_t a = 0; a < n.markers.size(); ++a) {
          for (std::size_t b = 0; b < a; ++b) {
            if (n.markers[a] == n.markers[b]) fail(where + ".markers", "names '" + n.markers[a] + "' twice");
          }
        }
        if (!n.oriented) fail(where + ".markers", "a region driven by markers takes their rotation: it must be oriented");
      }
      if (value == Value::kStiffness) {
        if (!arr[i].contains("value")) fail(where, "needs a value (stiffness weight; body tets default to 1)");
        n.value = number(arr[i]["value"], where + ".value");
        if (!(n.value > 0)) fail(where + ".value", "must be positive");
      } else if (value == Value::kVolume) {
        if (!arr[i].contains("value")) fail(where, "needs a value (the volume term's share of each tet's energy, in [0, 1))");
        n.value = number(arr[i]["value"], where + ".value");
        if (!(n.value >= 0 && n.value < 1)) {
          fail(where + ".value", "must be in [0, 1) (0: as rigid as possible; the term slows convergence by about 1 / (1 - value))");
        }
      }
      out.push_back(std::move(n));
    }
    return out;
  }

  std::string file_;
  std::filesystem::path base_;
};

// The text parsed as JSON; a syntax error names its byte.
json parseDescriptionJson(const std::string& json_text, const std::string& file) {
  json root;
  try {
    root = json::parse(json_text);
  } catch (const json::parse_error& e) {
    throw RigBuildError(file + ": not valid JSON at byte " + std::to_string(e.byte) + ": fix the syntax");
  }
  return root;
}

// The top level: known keys only, format "tetrig-rig", version 1.
void checkTopLevel(const Reader& r, const json& root) {
  r.allowKeys(root, "", {"format", "version", "name", "mesh_unit", "mesh_up", "tet_vertices", "pose_transfer", "vertex_handles",
                         "region_handles", "point_handles", "rigid_groups", "stiffness", "volume", "markers", "pose_sensors", "deformer"});
  if (root.contains("format") && r.string(root["format"], "format") != "tetrig-rig") {
    r.fail("format", "expected \"tetrig-rig\"");
  }
  if (root.contains("version") && r.integer<std::int64_t>(root["version"], "version", 0, std::numeric_limits<std::int32_t>::max()) != 1) {
    r.fail("version", "this program reads version 1");
  }
}

// name, mesh_unit, mesh_up and tet_vertices.
void readMeshKeys(const Reader& r, const json& root, RigDescription& d) {
  if (root.contains("name")) d.name = r.string(root["name"], "name");
  if (root.contains("mesh_unit")) {
    d.mesh_unit = r.string(root["mesh_unit"], "mesh_unit");
    if (d.mesh_unit != "auto") {
      try {
        (void)rigUnitsPerMm(d.mesh_unit);
      } catch (const RigBuildError& e) {
        r.fail("mesh_unit", e.what());
      }
    }
  }
  if (root.contains("mesh_up")) d.mesh_up = r.string(root["mesh_up"], "mesh_up");
  if (root.contains("tet_vertices")) {
    d.tet_vertices = r.integer<std::int32_t>(root["tet_vertices"], "tet_vertices", 4, 10'000'000);
  }
}

// pose_transfer: the radius fraction and the cap on non-zeros per row of B.
void readPoseTransfer(const Reader& r, const json& p, RigDescription& d) {
  r.allowKeys(p, "pose_transfer", {"radius_fraction", "max_nonzeros_per_row"});
  if (p.contains("radius_fraction")) d.pose_radius_fraction = r.number(p["radius_fraction"], "pose_transfer.radius_fraction");
  if (!(d.pose_radius_fraction > 0)) r.fail("pose_transfer.radius_fraction", "must be positive");
  if (p.contains("max_nonzeros_per_row")) {
    d.pose_max_nonzeros = r.integer<std::int32_t>(p["max_nonzeros_per_row"], "pose_transfer.max_nonzeros_per_row", 0,
                                                  std::numeric_limits<std::int32_t>::max());
    if (d.pose_max_nonzeros > 0 && d.pose_max_nonzeros < 4) r.fail("pose_transfer.max_nonzeros_per_row", "must be 0 (no cap) or at least 4");
  }
}

// point_handles: a name and a position each.
void readPointHandles(const Reader& r, const json& arr, RigDescription& d) {
  if (!arr.is_array()) r.fail("point_handles", "expected an array");
  for (std::size_t i = 0; i < arr.size(); ++i) {
    const std::string where = "point_handles[" + std::to_string(i) + "]";
    r.allowKeys(arr[i], where, {"name", "position"});
    PointHandleSpec p;
    p.name = arr[i].contains("name") ? r.string(arr[i]["name"], where + ".name") : "point" + std::to_string(i);
    if (!arr[i].contains("position")) r.fail(where, "needs a position [x, y, z] in rig units");
    p.position = r.vec3(arr[i]["position"], where + ".position");
    d.point_handles.push_back(p);
  }
}

// markers.checks: which alignment checks run and their limits.
void readAlignmentChecks(const Reader& r, const json& c, AlignmentCheckLimits& k) {
  r.allowKeys(c, "markers.checks",
              {"scale", "pose", "min_fit_scale", "max_fit_scale", "max_extent_gap", "far_distance_fraction", "max_far_fraction"});
  if (c.contains("scale")) k.check_scale = r.boolean(c["scale"], "markers.checks.scale");
  if (c.contains("pose")) k.check_pose = r.boolean(c["pose"], "markers.checks.pose");
  if (c.contains("min_fit_scale")) k.min_fit_scale = r.number(c["min_fit_scale"], "markers.checks.min_fit_scale");
  if (c.contains("max_fit_scale")) k.max_fit_scale = r.number(c["max_fit_scale"], "markers.checks.max_fit_scale");
  if (!(k.min_fit_scale > 0 && k.min_fit_scale <= k.max_fit_scale)) {
    r.fail("markers.checks", "min_fit_scale must be positive and at most max_fit_scale");
  }
  if (c.contains("max_extent_gap")) k.max_extent_gap = r.number(c["max_extent_gap"], "markers.checks.max_extent_gap");
  if (!(k.max_extent_gap > 0 && k.max_extent_gap <= 1)) r.fail("markers.checks.max_extent_gap", "must be in (0, 1]");
  if (c.contains("far_distance_fraction")) k.far_distance_fraction = r.number(c["far_distance_fraction"], "markers.checks.far_distance_fraction");
  if (!(k.far_distance_fraction > 0 && k.far_distance_fraction <= 1)) r.fail("markers.checks.far_distance_fraction", "must be in (0, 1]");
  if (c.contains("max_far_fraction")) k.max_far_fraction = r.number(c["max_far_fraction"], "markers.checks.max_far_fraction");
  if (!(k.max_far_fraction >= 0 && k.max_far_fraction <= 1)) r.fail("markers.checks.max_far_fraction", "must be in [0, 1]");
}

// markers: the clip, rest frame and labels, the alignment and its checks, the binding by
// invisible tets.
void readMarkerOptions(const Reader& r, const json& m, MarkerOptions& o) {
  r.allowKeys(m, "markers", {"clip", "frame", "labels", "exclude", "device_up", "alignment", "matrix", "icp_iterations", "icp_scale",
                             "max_scale_change", "marker_offset", "fit_power", "max_distance", "max_distance_fraction", "checks",
                             "faces_per_marker", "face_spread", "fan_spread", "fan_spokes", "fan_weight",
                             "invisible_stiffness", "rigid_regions"});
  if (m.contains("clip")) o.clip = r.path(m["clip"], "markers.clip");
  if (m.contains("frame")) {
    if (m["frame"].is_string()) {
      // "auto": the frame that best fits the mesh's rest pose (rest_frame_search.hpp).
      if (m["frame"].get<std::string>() != "auto") r.fail("markers.frame", "expected an integer in [0, 100000000] or \"auto\"");
      o.frame_auto = true;
    } else {
      o.frame = r.integer<std::int64_t>(m["frame"], "markers.frame", 0, 100'000'000);
    }
  }
  if (m.contains("labels")) o.labels = r.strings(m["labels"], "markers.labels");
  if (m.contains("exclude")) o.exclude = r.strings(m["exclude"], "markers.exclude");
  if (m.contains("device_up")) o.device_up = r.string(m["device_up"], "markers.device_up");
  if (m.contains("alignment")) {
    o.alignment = r.string(m["alignment"], "markers.alignment");
    if (o.alignment != "auto" && o.alignment != "units" && o.alignment != "matrix") {
      r.fail("markers.alignment", "expected \"auto\", \"units\" or \"matrix\"");
    }
  }
  if (m.contains("matrix")) {
    const json& a = m["matrix"];
    if (!a.is_array() || a.size() != 12) r.fail("markers.matrix", "expected 12 numbers (3x4 row-major, device mm -> rig units)");
    for (std::size_t i = 0; i < 12; ++i) o.matrix.push_back(r.number(a[i], "markers.matrix[" + std::to_string(i) + "]"));
  }
  if (o.alignment == "matrix" && o.matrix.empty()) r.fail("markers", "alignment \"matrix\" needs markers.matrix");
  if (m.contains("icp_iterations")) o.icp_iterations = r.integer<int>(m["icp_iterations"], "markers.icp_iterations", 0, 10000);
  if (m.contains("icp_scale")) o.icp_scale = r.boolean(m["icp_scale"], "markers.icp_scale");
  if (m.contains("max_scale_change")) o.max_scale_change = r.number(m["max_scale_change"], "markers.max_scale_change");
  if (!(o.max_scale_change >= 0 && o.max_scale_change < 1)) r.fail("markers.max_scale_change", "must be in [0, 1)");
  if (m.contains("marker_offset")) o.marker_offset = r.number(m["marker_offset"], "markers.marker_offset");
  if (m.contains("fit_power")) o.fit_power = r.number(m["fit_power"], "markers.fit_power");
  if (!(o.fit_power >= 1.0 && o.fit_power <= 16.0)) r.fail("markers.fit_power", "must be in [1, 16]");
  if (m.contains("max_distance")) {
    o.max_distance = r.number(m["max_distance"], "markers.max_distance");
    if (!(*o.max_distance > 0)) r.fail("markers.max_distance", "must be positive");
  }
  if (m.contains("max_distance_fraction")) o.max_distance_fraction = r.number(m["max_distance_fraction"], "markers.max_distance_fraction");
  if (!(o.max_distance_fraction > 0 && o.max_distance_fraction <= 1)) r.fail("markers.max_distance_fraction", "must be in (0, 1]");
  if (m.contains("checks")) readAlignmentChecks(r, m["checks"], o.checks);
  if (m.contains("faces_per_marker")) o.faces_per_marker = r.integer<int>(m["faces_per_marker"], "markers.faces_per_marker", 1, 16);
  if (m.contains("face_spread")) o.face_spread = r.number(m["face_spread"], "markers.face_spread");
  if (!(o.face_spread >= 0 && o.face_spread <= 100)) r.fail("markers.face_spread", "must be in [0, 100]");
  if (m.contains("fan_spread")) o.fan_spread = r.number(m["fan_spread"], "markers.fan_spread");
  if (!(o.fan_spread >= 0 && o.fan_spread <= 100)) r.fail("markers.fan_spread", "must be in [0, 100]");
  if (m.contains("fan_spokes")) o.fan_spokes = r.integer<int>(m["fan_spokes"], "markers.fan_spokes", 3, 32);
  if (m.contains("fan_weight")) o.fan_weight = r.number(m["fan_weight"], "markers.fan_weight");
  if (!(o.fan_weight >= 0 && o.fan_weight <= 1000)) r.fail("markers.fan_weight", "must be in [0, 1000]");
  if (m.contains("rigid_regions")) o.rigid_regions = r.boolean(m["rigid_regions"], "markers.rigid_regions");
  if (m.contains("invisible_stiffness")) o.invisible_stiffness = r.number(m["invisible_stiffness"], "markers.invisible_stiffness");
  if (!(o.invisible_stiffness > 0)) r.fail("markers.invisible_stiffness", "must be positive");
}

// One pose sensor: its sensor label, the oriented region handle it drives (no other sensor's,
// none driven by markers), its mode, clutch buttons and translation scale.
PoseSensorSpec readPoseSensor(const Reader& r, const json& entry, const std::string& where, const RigDescription& d) {
  r.allowKeys(entry, where, {"sensor", "region", "mode", "clutch_buttons", "translation_scale"});
  PoseSensorSpec p;
  p.where = where;
  if (!entry.contains("sensor")) r.fail(where, "needs a sensor (the marker label of the controller, e.g. \"hydra0\")");
  p.sensor = r.string(entry["sensor"], where + ".sensor");
  if (p.sensor.empty()) r.fail(where + ".sensor", "must not be empty");
  if (!entry.contains("region")) r.fail(where, "needs a region (the name of an oriented region handle)");
  p.region = r.string(entry["region"], where + ".region");
  std::string names;
  for (std::size_t h = 0; h < d.region_handles.size(); ++h) {
    const NamedSelection& region = d.region_handles[h];
    names += (names.empty() ? "" : ", ") + region.name;
    if (region.name != p.region) continue;
    if (p.region_index >= 0) r.fail(where + ".region", "two region handles are named '" + p.region + "': rename one");
    p.region_index = static_cast<std::int32_t>(h);
  }
  if (p.region_index < 0) {
    r.fail(where + ".region", "no region handle is named '" + p.region + "' (region handles: " +
                                  (names.empty() ? std::string("none") : names) + ")");
  }
  if (!d.region_handles[static_cast<std::size_t>(p.region_index)].oriented) {
    r.fail(where + ".region", "region handle '" + p.region + "' is not oriented; a pose sensor drives its rotation (set \"oriented\": true)");
  }
  if (!d.region_handles[static_cast<std::size_t>(p.region_index)].markers.empty()) {
    r.fail(where + ".region", "region handle '" + p.region + "' is already driven by its markers");
  }
  for (const PoseSensorSpec& other : d.pose_sensors) {
    if (other.region_index == p.region_index) {
      r.fail(where + ".region", "region handle '" + p.region + "' is already driven by " + other.where + " (sensor " + other.sensor + ")");
    }
  }
  if (entry.contains("mode")) {
    const std::string mode = r.string(entry["mode"], where + ".mode");
    if (mode == "clutch") {
      p.mode = PoseSensorMode::kClutch;
    } else if (mode == "absolute") {
      p.mode = PoseSensorMode::kAbsolute;
    } else {
      r.fail(where + ".mode", "expected \"clutch\" or \"absolute\"");
    }
  }
  if (entry.contains("clutch_buttons")) {
    p.clutch_buttons = static_cast<std::uint8_t>(r.integer<int>(entry["clutch_buttons"], where + ".clutch_buttons", 1, 255));
  }
  if (entry.contains("translation_scale")) p.translation_scale = r.number(entry["translation_scale"], where + ".translation_scale");
  if (!(p.translation_scale > 0)) r.fail(where + ".translation_scale", "must be positive");
  return p;
}

// pose_sensors, in order.
void readPoseSensors(const Reader& r, const json& arr, RigDescription& d) {
  if (!arr.is_array()) r.fail("pose_sensors", "expected an array");
  for (std::size_t i = 0; i < arr.size(); ++i) {
    const std::string where = "pose_sensors[" + std::to_string(i) + "]";
    d.pose_sensors.push_back(readPoseSensor(r, arr[i], where, d));
  }
}

// deformer: rotation_steps and point_handle_weight.
void readDeformer(const Reader& r, const json& m, RigDescription& d) {
  r.allowKeys(m, "deformer", {"rotation_steps", "point_handle_weight"});
  if (m.contains("rotation_steps")) d.rotation_steps = r.integer<int>(m["rotation_steps"], "deformer.rotation_steps", 0, 64);
  if (m.contains("point_handle_weight")) d.point_handle_weight = r.number(m["point_handle_weight"], "deformer.point_handle_weight");
  if (!(d.point_handle_weight > 0)) r.fail("deformer.point_handle_weight", "must be positive");
}

}  // namespace

double rigUnitsPerMm(const std::string& unit) {
  if (unit == "m") return 1e-3;
  if (unit == "cm") return 1e-1;
  if (unit == "mm") return 1.0;
  throw RigBuildError("unknown unit '" + unit + "': use m, cm or mm");
}

RigDescription parseRigDescription(const std::string& json_text, const std::filesystem::path& source) {
  const std::string file = source.empty() ? std::string("rig description") : source.string();
  Reader r(file, source.empty() ? std::filesystem::path(".") : source.parent_path());
  const json root = parseDescriptionJson(json_text, file);
  checkTopLevel(r, root);
  RigDescription d;
  d.source = source;
  readMeshKeys(r, root, d);
  if (root.contains("pose_transfer")) readPoseTransfer(r, root["pose_transfer"], d);
  // Handles, rigid groups, stiffness and volume: lists of named selections.
  d.vertex_handles = r.list(root, "vertex_handles", false);
  d.region_handles = r.list(root, "region_handles", true);
  d.rigid_groups = r.list(root, "rigid_groups", false);
  d.stiffness = r.list(root, "stiffness", false, Reader::Value::kStiffness);
  d.volume = r.list(root, "volume", false, Reader::Value::kVolume);
  if (root.contains("point_handles")) readPointHandles(r, root["point_handles"], d);
  if (root.contains("markers")) readMarkerOptions(r, root["markers"], d.markers);
  // Pose sensors after the region handles they name.
  if (root.contains("pose_sensors")) readPoseSensors(r, root["pose_sensors"], d);
  if (root.contains("deformer")) readDeformer(r, root["deformer"], d);
  return d;
}

RigDescription readRigDescription(const std::filesystem::path& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw RigBuildError(path.string() + ": is a folder, not a rig description (give a .json file; docs/rig-format.md)");
  std::ifstream in(path);
  if (!in) throw RigBuildError(path.string() + ": cannot open the rig description (missing or unreadable)");
  std::stringstream s;
  s << in.rdbuf();
  return parseRigDescription(s.str(), path);
}

}  // namespace tetrig::rigbuild
