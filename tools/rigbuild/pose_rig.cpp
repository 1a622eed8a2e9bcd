// Posing a rig offline from region transforms (pose_rig.hpp): .def files of the Botsch-Sorkine
// deformation survey ("On Linear Variational Surface Deformation Methods", IEEE TVCG 2008), the
// Deformer (Stoll et al. 2007) run until its energy stops changing, pose transfer to the fine mesh,
// and the fine mesh as OBJ.
#include "tetrig/rigbuild/pose_rig.hpp"

#include "tetrig/pose_transfer.hpp"
#include "tetrig/printable_text.hpp"
#include "tetrig/rigbuild/write_file_atomic.hpp"

#include <Eigen/SVD>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <limits>
#include <optional>
#include <span>
#include <sstream>

namespace tetrig::rigbuild {
namespace {

std::string number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

std::string regionList(const Rig& rig) {
  std::string names;
  for (const std::string& n : rig.region_handle_names) names += (names.empty() ? "'" : ", '") + printableText(n, 64) + "'";
  return names.empty() ? std::string("none") : names;
}

}  // namespace

DefTransform parseDefText(std::string_view text, const std::string& where, double rotation_tolerance) {
  std::vector<double> values;
  std::size_t line_number = 0;
  std::size_t start = 0;
  while (start <= text.size()) {
    std::size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    ++line_number;
    std::string_view line = text.substr(start, end - start);
    if (const std::size_t hash = line.find('#'); hash != std::string_view::npos) line = line.substr(0, hash);
    std::size_t i = 0;
    while (i < line.size()) {
      while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r' || line[i] == ',')) ++i;
      if (i >= line.size()) break;
      std::size_t j = i;
      while (j < line.size() && line[j] != ' ' && line[j] != '\t' && line[j] != '\r' && line[j] != ',') ++j;
      const std::string token(line.substr(i, j - i));
      char* parsed_end = nullptr;
      errno = 0;
      const double v = std::strtod(token.c_str(), &parsed_end);
      if (parsed_end != token.c_str() + token.size() || errno == ERANGE || !std::isfinite(v)) {
        throw RigBuildError(where + ":" + std::to_string(line_number) + ": expected a finite number of the 4x4 matrix, found '" +
                            printableText(token, 40) + "'; a .def holds 16 numbers (row-major) and '#' comment lines");
      }
      values.push_back(v);
      if (values.size() > 16) {
        throw RigBuildError(where + ":" + std::to_string(line_number) +
                            ": more than 16 numbers; a .def holds one 4x4 matrix (row-major) and '#' comment lines");
      }
      i = j;
    }
    start = end + 1;
  }
  if (values.size() != 16) {
    throw RigBuildError(where + ": " + std::to_string(values.size()) +
                        " numbers, a .def holds 16 (a 4x4 matrix, row-major, and '#' comment lines)");
  }
  DefTransform d;
  for (int k = 0; k < 16; ++k) d.matrix(k / 4, k % 4) = values[static_cast<std::size_t>(k)];
  const Eigen::RowVector4d bottom = d.matrix.row(3);
  if ((bottom - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > 1e-6) {
    throw RigBuildError(where + ": the bottom row is " + number(bottom[0]) + " " + number(bottom[1]) + " " + number(bottom[2]) + " " +
                        number(bottom[3]) + ", not 0 0 0 1: not an affine transform");
  }
  const Eigen::Matrix3d linear = d.matrix.topLeftCorner<3, 3>();
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(linear, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d s = svd.singularValues();
  const Eigen::Matrix3d rotation = svd.matrixU() * svd.matrixV().transpose();
  d.rotation_error = (linear - rotation).norm();
  if (linear.determinant() <= 0.0 || d.rotation_error > rotation_tolerance) {
    throw RigBuildError(where + ": the linear part is not a rotation (singular values " + number(s[0]) + " " + number(s[1]) + " " +
                        number(s[2]) + ", determinant " + number(linear.determinant()) +
                        "): region handles are rigid, so a .def may only rotate and translate; remove the scale, shear or mirror");
  }
  d.rigid.rotation = Eigen::Quaterniond(rotation).normalized();
  d.rigid.translation = d.matrix.topRightCorner<3, 1>();
  return d;
}

DefTransform readDefFile(const std::filesystem::path& path, double rotation_tolerance) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw RigBuildError(path.string() + ": no such .def file");
  const auto bytes = std::filesystem::file_size(path, ec);
  if (ec || bytes > (1u << 20)) {
    throw RigBuildError(path.string() + ": " + (ec ? "cannot read its size" : std::to_string(bytes) + " bytes") +
                        ", not a .def (a 4x4 matrix: a few hundred bytes)");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw RigBuildError(path.string() + ": cannot open the .def file");
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return parseDefText(text, path.string(), rotation_tolerance);
}

PoseResult poseRig(const Rig& rig, const std::vector<std::pair<std::string, RigidTransform>>& regions, const PoseOptions& options) {
  if (options.iterations < 0 || options.max_iterations < 1 || options.batch < 1 || !(options.step_tolerance > 0.0)) {
    throw RigBuildError("pose options: iterations >= 0, max_iterations >= 1, batch >= 1 and step_tolerance > 0 are required");
  }
  const std::size_t region_count = rig.setup.region_handles.size();
  if (region_count == 0 && !regions.empty()) {
    throw RigBuildError("the rig has no region handles to pose: build it with region_handles in the rig JSON (docs/rig-format.md)");
  }
  std::vector<RigidTransform> transforms(region_count);
  std::vector<char> given(region_count, 0);
  for (const auto& [name, transform] : regions) {
    const auto it = std::find(rig.region_handle_names.begin(), rig.region_handle_names.end(), name);
    if (it == rig.region_handle_names.end()) {
      throw RigBuildError("no region handle named '" + printableText(name, 64) + "' in the rig (its regions: " + regionList(rig) + ")");
    }
    const auto r = static_cast<std::size_t>(it - rig.region_handle_names.begin());
    if (given[r]) throw RigBuildError("region handle '" + printableText(name, 64) + "' is posed twice: give each region once");
    given[r] = 1;
    if (!transform.rotation.coeffs().allFinite() || !transform.translation.allFinite() ||
        std::abs(transform.rotation.norm() - 1.0) > 1e-6) {
      throw RigBuildError("region handle '" + printableText(name, 64) +
                          "': the transform is not a finite rigid motion (unit quaternion, finite translation)");
    }
    transforms[r] = transform;
  }

  DeformerSetup setup = rig.setup;
  setup.options.update_rotations = options.update_rotations;
  setup.options.volume_weight = options.volume_weight;
  std::optional<Deformer> deformer;
  try {
    deformer.emplace(rig.tet_mesh, setup);
  } catch (const std::exception& e) {
    throw RigBuildError(std::string("the rig does not load into the deformer: ") + e.what());
  }
  // Vertex handles (markers) and point handles stay at their rest positions.
  std::vector<Eigen::Vector3d> vertex_targets;
  for (const std::int32_t v : rig.setup.vertex_handles) vertex_targets.emplace_back(rig.tet_mesh.vertices.row(v).transpose());
  std::vector<Eigen::Vector3d> point_targets;
  for (const PointHandle& p : rig.setup.point_handles) {
    Eigen::Vector3d x = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k) x += p.barycentric[k] * rig.tet_mesh.vertices.row(rig.tet_mesh.tets(p.tet, k)).transpose();
    point_targets.push_back(x);
  }
  HandleTargets targets;
  targets.vertex_positions = vertex_targets;
  targets.region_transforms = transforms;
  targets.point_positions = point_targets;

  const double diagonal = std::max(boundingBoxDiagonal(rig.fine_vertices), std::numeric_limits<double>::min());
  PoseResult result;
  std::vector<double> previous(deformer->positions().begin(), deformer->positions().end());
  auto batchStep = [&]() {
    double moved = 0.0;
    const std::span<const double> x = deformer->positions();
    for (std::size_t k = 0; k < previous.size(); ++k) moved = std::max(moved, std::abs(x[k] - previous[k]));
    previous.assign(x.begin(), x.end());
    return moved / diagonal;
  };
  StepBudget budget;
  const int limit = options.iterations > 0 ? options.iterations : options.max_iterations;
  double previous_energy = std::numeric_limits<double>::quiet_NaN();
  while (result.iterations < limit) {
    budget.max_iterations = std::min(options.batch, limit - result.iterations);
    const StepStats stats = deformer->step(targets, budget);
    result.iterations += stats.iterations;
    result.energy = stats.energy;
    result.step_flags |= stats.flags;
    result.last_batch_step = batchStep();
    result.relative_energy_change =
        std::isfinite(previous_energy) && stats.energy > 0.0 ? std::abs(previous_energy - stats.energy) / stats.energy : 0.0;
    previous_energy = stats.energy;
    if (options.iterations == 0 && result.last_batch_step <= options.step_tolerance) {
      result.converged = true;
      break;
    }
  }
  if (options.iterations > 0) result.converged = true;
  if ((result.step_flags & (kStepTargetsRejected | kStepTargetsWrongSize)) != 0) {
    throw RigBuildError("the deformer refused the pose's targets (non-finite, absurd beyond 1e6, or the wrong count): check the transforms");
  }
  result.tet_positions.assign(deformer->positions().begin(), deformer->positions().end());
  TetMesh deformed = rig.tet_mesh;
  for (std::int32_t v = 0; v < deformed.vertexCount(); ++v) deformed.vertices.row(v) = deformer->position(v).transpose();
  for (std::int32_t t = 0; t < rig.body_tet_count; ++t) result.inverted_tets += signedVolume(deformed, t) <= 0.0 ? 1 : 0;
  result.fine_positions.assign(static_cast<std::size_t>(rig.fine_vertices.rows()) * 3, 0.0);
  applyPoseTransfer(rig.pose_transfer.view(), result.tet_positions.data(), result.fine_positions.data());
  if (!std::all_of(result.fine_positions.begin(), result.fine_positions.end(), [](double v) { return std::isfinite(v); })) {
    throw RigBuildError("the pose produced non-finite positions: the rig or the transforms are broken");
  }
  return result;
}

std::string fineMeshObjText(const Rig& rig, const std::vector<double>& fine_positions, const std::string& comment) {
  if (fine_positions.size() != static_cast<std::size_t>(rig.fine_vertices.rows()) * 3) {
    throw RigBuildError("OBJ: " + std::to_string(fine_positions.size() / 3) + " positions for a fine mesh of " +
                        std::to_string(rig.fine_vertices.rows()) + " vertices");
  }
  std::string text;
  std::istringstream lines(comment);
  for (std::string l; std::getline(lines, l);) text += "# " + l + "\n";
  char line[112];
  for (std::size_t i = 0; i < fine_positions.size(); i += 3) {
    std::snprintf(line, sizeof line, "v %.10g %.10g %.10g\n", fine_positions[i], fine_positions[i + 1], fine_positions[i + 2]);
    text += line;
  }
  for (Eigen::Index f = 0; f < rig.fine_triangles.rows(); ++f) {
    std::snprintf(line, sizeof line, "f %d %d %d\n", rig.fine_triangles(f, 0) + 1, rig.fine_triangles(f, 1) + 1, rig.fine_triangles(f, 2) + 1);
    text += line;
  }
  return text;
}

void writeObjAtomically(const std::filesystem::path& path, const Rig& rig, const std::vector<double>& fine_positions,
                        const std::string& comment) {
  const std::string text = fineMeshObjText(rig, fine_positions, comment);
  writeFileAtomically(path, std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()));
}

}  // namespace tetrig::rigbuild
