// `tetrig inspect`: a rig's contents as text. Every string that comes from the file (names, unit,
// labels, axes) is printed through tetrig::printableText: a rig is input from anyone, and its text
// must not reach the terminal as control sequences.
#include "tetrig/rigbuild/describe_rig.hpp"

#include "tetrig/printable_text.hpp"
#include "tetrig/rigbuild/tet_quality.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

namespace tetrig::rigbuild {

namespace {
// File text longer than this is cut short ("... (N bytes)"); a name may hold 64 KiB.
constexpr std::size_t kMaxShownBytes = 256;

std::string shown(const std::string& file_text) { return printableText(file_text, kMaxShownBytes); }

std::string hex2(unsigned value) {
  char text[8];
  std::snprintf(text, sizeof text, "%02x", value & 0xFFu);
  return text;
}
}  // namespace

std::string describeRig(const Rig& rig, std::int64_t file_bytes, bool list_markers) {
  std::ostringstream o;
  auto line = [&](const char* f, auto... args) {
    const int n = std::snprintf(nullptr, 0, f, args...);
    std::string text(static_cast<std::size_t>(std::max(n, 0)), '\0');
    std::snprintf(text.data(), text.size() + 1, f, args...);
    o << text << '\n';
  };
  const std::string unit = shown(rig.unit);
  line("rig:           %s", shown(rig.name).c_str());
  line("built by:      %s (format version %u)", shown(rig.builder).c_str(), kRigFormatVersion);
  line("unit:          %s, up axis %s", unit.c_str(), shown(rig.alignment.rig_up).c_str());
  const Eigen::Vector3d lo = rig.fine_vertices.colwise().minCoeff(), hi = rig.fine_vertices.colwise().maxCoeff();
  line("bounding box:  [%.4g %.4g %.4g] .. [%.4g %.4g %.4g] (size %.4g x %.4g x %.4g)", lo.x(), lo.y(), lo.z(), hi.x(), hi.y(), hi.z(),
       hi.x() - lo.x(), hi.y() - lo.y(), hi.z() - lo.z());
  line("fine mesh:     %d vertices, %d triangles", static_cast<int>(rig.fine_vertices.rows()), static_cast<int>(rig.fine_triangles.rows()));
  line("tet mesh:      %d vertices (%d body + %d marker), %d tets (%d body + %d invisible)", rig.tet_mesh.vertexCount(),
       rig.body_vertex_count, rig.tet_mesh.vertexCount() - rig.body_vertex_count, rig.tet_mesh.tetCount(), rig.body_tet_count,
       rig.tet_mesh.tetCount() - rig.body_tet_count);
  line("tet quality:   %s", tetQuality(rig.tet_mesh, 0, rig.body_tet_count).summary().c_str());
  const PoseTransferCsr<double>& b = rig.pose_transfer;
  std::int32_t max_row = 0;
  for (std::int32_t r = 0; r < b.rows; ++r) max_row = std::max(max_row, b.row_offsets[static_cast<std::size_t>(r) + 1] - b.row_offsets[static_cast<std::size_t>(r)]);
  line("pose transfer: B %d x %d, %lld non-zeros (%.1f per row, max %d)", b.rows, b.cols, static_cast<long long>(b.nonzeros()),
       b.rows ? static_cast<double>(b.nonzeros()) / b.rows : 0.0, max_row);
  const DeformerSetup& s = rig.setup;
  line("handles:       %zu vertex (%zu markers), %zu region, %zu point", s.vertex_handles.size(), rig.markers.size(),
       s.region_handles.size(), s.point_handles.size());
  std::string last;
  std::size_t run = 0;
  auto flush = [&]() {
    if (run > 0 && last.rfind("marker:", 0) != 0) line("  vertex handle '%s': %zu vertices", shown(last).c_str(), run);
  };
  for (const std::string& n : rig.vertex_handle_names) {
    if (n != last) {
      flush();
      last = n;
      run = 0;
    }
    ++run;
  }
  flush();
  for (std::size_t r = 0; r < s.region_handles.size(); ++r) {
    line("  region handle '%s': %zu tets, %s", shown(rig.region_handle_names[r]).c_str(), s.region_handles[r].tets.size(),
         s.region_handles[r].oriented ? "oriented" : "position only");
  }
  for (std::size_t p = 0; p < s.point_handles.size(); ++p) {
    line("  point handle '%s': tet %d", shown(rig.point_handle_names[p]).c_str(), s.point_handles[p].tet);
  }
  for (const RigPoseSensor& sensor : rig.pose_sensors) {
    line("  pose sensor '%s' drives region '%s': %s%s, translation scale %g", shown(sensor.sensor_label).c_str(),
         shown(rig.region_handle_names[static_cast<std::size_t>(sensor.region_handle)]).c_str(),
         sensor.mode == PoseSensorMode::kClutch ? "clutch on buttons 0x" : "absolute",
         sensor.mode == PoseSensorMode::kClutch ? hex2(sensor.clutch_buttons).c_str() : "", sensor.translation_scale);
  }
  for (const RigMarkerRegion& mr : rig.marker_regions) {
    std::string labels;
    for (const std::int32_t m : mr.markers) {
      if (!labels.empty()) labels += ' ';  // (not `(empty ? "" : " ") + shown(..)`: GCC 12 -Wrestrict false positive)
      labels += shown(rig.markers[static_cast<std::size_t>(m)].label);
    }
    line("  markers %s drive region '%s' (best-fit rigid transform)", labels.c_str(),
         shown(rig.region_handle_names[static_cast<std::size_t>(mr.region_handle)]).c_str());
  }
  line("rigid groups:  %zu", s.rigid_groups.size());
  for (std::size_t g = 0; g < s.rigid_groups.size(); ++g) {
    line("  rigid group '%s': %zu tets", shown(rig.rigid_group_names[g]).c_str(), s.rigid_groups[g].tets.size());
  }
  if (s.stiffness.empty()) {
    line("stiffness:     uniform (1)");
  } else {
    const auto [mn, mx] = std::minmax_element(s.stiffness.begin(), s.stiffness.end());
    line("stiffness:     per tet, %.4g .. %.4g", *mn, *mx);
  }
  if (!s.volume_weights.empty()) {
    const auto weighted = std::count_if(s.volume_weights.begin(), s.volume_weights.end(), [](double w) { return w > 0.0; });
    line("volume term:   on %td of %zu tets, weight up to %.4g", weighted, s.volume_weights.size(),
         *std::max_element(s.volume_weights.begin(), s.volume_weights.end()));
  }
  if (!rig.markers.empty()) {
    std::vector<double> d;
    for (const RigMarker& m : rig.markers) d.push_back(m.surface_distance);
    std::sort(d.begin(), d.end());
    line("markers:       %zu, rest distance to surface median %.4g max %.4g %s", rig.markers.size(), d[d.size() / 2], d.back(),
         unit.c_str());
    if (list_markers) {
      for (const RigMarker& m : rig.markers) {
        line("  %-10s vertex %6d  rest [%.4f %.4f %.4f]  %d faces  distance %.4f", shown(m.label).c_str(), m.tet_vertex, m.rest_position.x(),
             m.rest_position.y(), m.rest_position.z(), m.bound_faces, m.surface_distance);
      }
    }
  }
  // The device -> rig transform means something only when markers or pose sensors use it.
  const RigAlignment& a = rig.alignment;
  if (rig.markers.empty() && rig.pose_sensors.empty()) {
    line("alignment:     none (no markers or pose sensors)");
  } else {
    line("alignment:     device mm (up %s) -> rig %s: scale %.5g (units %.5g x fit %.5g)", shown(a.device_up).c_str(), unit.c_str(),
         std::cbrt(std::abs(a.linear.determinant())), a.rig_units_per_mm, a.fit_scale);
    for (int r = 0; r < 3; ++r) {
      line("  [% .6g % .6g % .6g | % .6g]", a.linear(r, 0), a.linear(r, 1), a.linear(r, 2), a.translation[r]);
    }
  }
  if (const RigSurfaceAttributes& sa = rig.surface; !sa.empty()) {
    std::size_t textured = 0;
    for (Eigen::Index f = 0; f < sa.corner_uvs.rows(); ++f) textured += (sa.corner_uvs.row(f).array() >= 0).all() ? 1 : 0;
    std::string names;
    for (std::size_t m = 0; m < sa.materials.size() && m < 8; ++m) {
      if (!names.empty()) names += ", ";
      names += shown(sa.materials[m].name);
      if (!sa.materials[m].diffuse_texture.empty()) names += " (" + shown(sa.materials[m].diffuse_texture) + ")";
    }
    if (sa.materials.size() > 8) names += ", ...";
    line("surface:       %lld uvs on %zu of %lld triangles, %zu materials%s%s", static_cast<long long>(sa.uvs.rows()), textured,
         static_cast<long long>(sa.corner_uvs.rows()), sa.materials.size(), names.empty() ? "" : ": ", names.c_str());
    if (!sa.asset.empty()) line("  from %s", shown(sa.asset).c_str());
  }
  line("deformer:      rotation_steps %d, point_handle_weight %.4g", s.options.rotation_steps, s.options.point_handle_weight);
  if (rig.coarse) {
    line("coarse level:  %d tet vertices (%d body + %zu marker), %d tets", rig.coarse->tet_mesh.vertexCount(), rig.coarse->body_vertex_count,
         rig.coarse->markers.size(), rig.coarse->tet_mesh.tetCount());
  }
  line("memory:        %.2f MB of rig arrays%s", static_cast<double>(rigMemoryBytes(rig)) / 1e6,
       file_bytes > 0 ? (", file " + std::to_string(file_bytes) + " bytes").c_str() : "");
  return o.str();
}

}  // namespace tetrig::rigbuild
