// The deformation-survey editing cases (Botsch & Sorkine; ../shared/data/NOTES.md section 1):
// cactus and cylinder, each with a .sel (per file vertex: 0 fixed, 1 region of interest, 2 handle)
// and a .def (4x4 transform of the handle). The rig is built from the .sel through the rig JSON
// (two region handles with sel_file selections), the .def is applied to the handle region by
// rigbuild::poseRig (the library behind `tetrig pose`: the Deformer run until its energy stops
// changing, the fine mesh by pose transfer). Measured on the FINE mesh against the survey's own
// linear-Laplacian result (*-laplacian_editing.off, same vertices and faces, read here): volume,
// handle vertices on the .def transform, fixed vertices in place, no inverted tet, tet quality.
#include "small_rig.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/build_rig.hpp"
#include "tetrig/rigbuild/pose_rig.hpp"
#include "tetrig/rigbuild/rig_description.hpp"
#include "tetrig/rigbuild/tet_quality.hpp"
#include "test_data.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <ostream>
#include <sstream>
#include <string>
#include <vector>

namespace tetrig {
namespace {

using test::TempDir;

struct OffMesh {
  std::vector<Eigen::Vector3d> v;
  std::vector<std::array<int, 3>> f;
};

// OFF as the survey writes it: "OFF", counts, one vertex per line, "3 a b c" faces.
OffMesh readOff(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::string magic;
  std::size_t nv = 0, nf = 0, ne = 0;
  in >> magic >> nv >> nf >> ne;
  OffMesh m;
  if (magic != "OFF") return m;
  m.v.resize(nv);
  for (auto& p : m.v) in >> p.x() >> p.y() >> p.z();
  for (std::size_t i = 0; i < nf && in; ++i) {
    int n = 0;
    std::array<int, 3> t{};
    in >> n >> t[0] >> t[1] >> t[2];
    if (n == 3) m.f.push_back(t);
  }
  return m;
}

// The volume term's share and the convergence criterion of its pose: the volume term slows the
// local/global iteration (its target holds w F, so each step moves 1 - w of the plain one's way;
// docs/deformation.md), so its pose stops at 1e-6 of the diagonal per 10 iterations instead of 2e-7.
constexpr double kSurveyVolumeWeight = 0.9;
constexpr double kSurveyVolumeStepTolerance = 1e-6;

// Enclosed volume (divergence theorem) of positions `x` with the faces of `faces`.
template <typename Positions>
double enclosedVolume(const Positions& x, const std::vector<std::array<int, 3>>& faces) {
  double v = 0;
  for (const auto& t : faces) v += x(t[0]).dot(x(t[1]).cross(x(t[2]))) / 6.0;
  return v;
}

std::vector<int> readSel(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::vector<int> s;
  for (std::string line; std::getline(in, line);) {
    if (!line.empty() && line[0] != '#') s.push_back(std::stoi(line));
  }
  return s;
}

struct SurveyCase {
  const char* name;
  std::int32_t tet_vertices;
  // Bounds asserted below, each with its measured value (idle run, this code) in the comment at
  // the instantiation.
  double max_volume_change;      // |V_ours / V_rest - 1|
  double max_handle_error;       // max over handle vertices of |x - M p| / diagonal
  double max_fixed_error;        // max over fixed vertices of |x - p| / diagonal
};

// Test names and ctest listings show the case's name and budget instead of its bytes.
void PrintTo(const SurveyCase& c, std::ostream* os) { *os << c.name << '_' << c.tet_vertices; }

class SurveyEdit : public ::testing::TestWithParam<SurveyCase> {};

TEST_P(SurveyEdit, DefAppliedThroughTheRigPreservesVolume) {
  const SurveyCase& c = GetParam();
  const std::string base = std::string("meshes/deformation-survey/") + c.name;
  TETRIG_REQUIRE_DATA(mesh_path, base + ".off");
  TETRIG_REQUIRE_DATA(sel_path, base + ".sel");
  TETRIG_REQUIRE_DATA(def_path, base + ".def");
  TETRIG_REQUIRE_DATA(reference_path, base + "-laplacian_editing.off");

  // The data, read here independently of the builder.
  const OffMesh rest = readOff(mesh_path);
  const OffMesh reference = readOff(reference_path);
  const std::vector<int> sel = readSel(sel_path);
  const rigbuild::DefTransform def_file = rigbuild::readDefFile(def_path);
  const Eigen::Matrix4d& def = def_file.matrix;
  ASSERT_FALSE(rest.v.empty());
  ASSERT_EQ(reference.v.size(), rest.v.size());
  ASSERT_EQ(sel.size(), rest.v.size());
  ASSERT_EQ(def(3, 3), 1.0);
  const std::size_t nv = rest.v.size();
  Eigen::Vector3d lo = rest.v[0], hi = rest.v[0];
  for (const auto& p : rest.v) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const double diag = (hi - lo).norm();
  auto defApplied = [&def](const Eigen::Vector3d& p) -> Eigen::Vector3d { return def.topLeftCorner<3, 3>() * p + def.topRightCorner<3, 1>(); };

  // What the .def means, checked on the survey's own result: its handle vertices sit exactly on
  // M p and its fixed vertices did not move (both to the file's 6 printed digits).
  double ref_handle = 0, ref_fixed = 0;
  for (std::size_t i = 0; i < nv; ++i) {
    if (sel[i] == 2) ref_handle = std::max(ref_handle, (reference.v[i] - defApplied(rest.v[i])).norm() / diag);
    if (sel[i] == 0) ref_fixed = std::max(ref_fixed, (reference.v[i] - rest.v[i]).norm() / diag);
  }
  EXPECT_LT(ref_handle, 1e-5);
  EXPECT_LT(ref_fixed, 1e-5);
  const double rest_volume = enclosedVolume([&](int i) { return rest.v[static_cast<std::size_t>(i)]; }, rest.f);
  const double reference_change =
      enclosedVolume([&](int i) { return reference.v[static_cast<std::size_t>(i)]; }, reference.f) / rest_volume - 1.0;

  // The handle's rigid transform: the .def's linear part is a rotation up to its printed digits;
  // readDefFile projects it onto its nearest rotation (polar factor) for the region handle.
  ASSERT_LT(def_file.rotation_error, 1e-4);
  ASSERT_LT((def_file.rigid.rotation.toRotationMatrix() - def.topLeftCorner<3, 3>()).norm(), 1e-4);

  // The rig: region handles from the .sel (statuses 0 and 2), oriented so that the handle's
  // rotation is interpolated over the mesh. How a .sel status reaches the tets: file vertex i is
  // fine vertex i (importSurface keeps the file order); the selected fine vertices that the
  // decimation kept are selected tet vertices, and TetGen's interior points under them join
  // (extendSelectionInward); a tet joins the region when all four corners are selected
  // (min_corners 4). With 3, a tet with three corners on the selection drags its fourth,
  // region-of-interest corner into the rigid handle (measured on the cylinder at 800 tet
  // vertices, before the interior points: the handle region reached from z = 11.5 down to
  // z = 5.5, half the cylinder). Fine vertices the decimation removed follow through B; the
  // errors below are measured on them too.
  const TempDir dir;
  const std::string json = R"({ "name": ")" + std::string(c.name) + R"(", "mesh_unit": "m", "mesh_up": "y",
    "region_handles": [
      { "name": "fixed", "oriented": true, "select": { "sel_file": ")" + sel_path.string() + R"(", "sel_values": [0], "min_corners": 4 } },
      { "name": "handle", "oriented": true, "select": { "sel_file": ")" + sel_path.string() + R"(", "sel_values": [2], "min_corners": 4 } } ] })";
  rigbuild::BuildRigInputs in;
  in.mesh = mesh_path;
  in.description = rigbuild::parseRigDescription(json, dir.path() / "survey.json");
  in.tet_vertices = c.tet_vertices;
  rigbuild::BuildRigReport report;
  const Rig rig = rigbuild::buildRig(in, &report);
  ASSERT_EQ(rig.setup.region_handles.size(), 2u);

  // The fine mesh is the file's mesh in the file's order (the importer keeps it): fine vertex i
  // is file vertex i, so the .sel statuses apply to the fine mesh directly.
  ASSERT_EQ(static_cast<std::size_t>(rig.fine_vertices.rows()), nv);
  for (std::size_t i = 0; i < nv; ++i) {
    ASSERT_EQ(Eigen::Vector3d(rig.fine_vertices.row(static_cast<Eigen::Index>(i)).transpose()), rest.v[i]) << "vertex " << i;
  }

  // The pose: the handle region takes the .def's transform, the fixed region stays.
  rigbuild::PoseOptions options;
  const rigbuild::PoseResult ours = rigbuild::poseRig(rig, {{"handle", def_file.rigid}}, options);
  ASSERT_EQ(ours.fine_positions.size(), nv * 3);
  auto finePoint = [&ours](std::size_t i) {
    return Eigen::Vector3d(ours.fine_positions[3 * i], ours.fine_positions[3 * i + 1], ours.fine_positions[3 * i + 2]);
  };
  const double ours_change = enclosedVolume([&](int i) { return finePoint(static_cast<std::size_t>(i)); }, rest.f) / rest_volume - 1.0;
  double handle_max = 0, handle_sum = 0, fixed_max = 0;
  std::size_t handles = 0;
  for (std::size_t i = 0; i < nv; ++i) {
    if (sel[i] == 2) {
      const double e = (finePoint(i) - defApplied(rest.v[i])).norm() / diag;
      handle_max = std::max(handle_max, e);
      handle_sum += e;
      ++handles;
    }
    if (sel[i] == 0) fixed_max = std::max(fixed_max, (finePoint(i) - rest.v[i]).norm() / diag);
  }
  // The same rig with the linear Laplacian (rotations fixed at I): our counterpart of the
  // survey's reference.
  options.update_rotations = false;
  const rigbuild::PoseResult linear = rigbuild::poseRig(rig, {{"handle", def_file.rigid}}, options);
  const double linear_change =
      enclosedVolume([&](int i) { return Eigen::Vector3d(linear.fine_positions[3 * static_cast<std::size_t>(i)],
                                                         linear.fine_positions[3 * static_cast<std::size_t>(i) + 1],
                                                         linear.fine_positions[3 * static_cast<std::size_t>(i) + 2]); },
                     rest.f) /
          rest_volume -
      1.0;
  // The same rig with the volume term (DeformerOptions::volume_weight, docs/deformation.md): each
  // tet's energy (1 - w) ||F - R||^2 + w ||F - T||^2 with T its nearest unit-volume shape.
  options.update_rotations = true;
  options.volume_weight = kSurveyVolumeWeight;
  options.step_tolerance = kSurveyVolumeStepTolerance;
  const rigbuild::PoseResult kept = rigbuild::poseRig(rig, {{"handle", def_file.rigid}}, options);
  auto keptPoint = [&kept](std::size_t i) {
    return Eigen::Vector3d(kept.fine_positions[3 * i], kept.fine_positions[3 * i + 1], kept.fine_positions[3 * i + 2]);
  };
  const double kept_change = enclosedVolume([&](int i) { return keptPoint(static_cast<std::size_t>(i)); }, rest.f) / rest_volume - 1.0;
  double kept_handle_max = 0, kept_fixed_max = 0;
  for (std::size_t i = 0; i < nv; ++i) {
    if (sel[i] == 2) kept_handle_max = std::max(kept_handle_max, (keptPoint(i) - defApplied(rest.v[i])).norm() / diag);
    if (sel[i] == 0) kept_fixed_max = std::max(kept_fixed_max, (keptPoint(i) - rest.v[i]).norm() / diag);
  }
  std::printf("[ measured ] %s at %d with the volume term (w %.2f): volume change %+.2f %%, handle max %.2e, fixed max %.2e of the "
              "diagonal, %d iterations, inverted tets %d\n",
              c.name, c.tet_vertices, kSurveyVolumeWeight, 100 * kept_change, kept_handle_max, kept_fixed_max, kept.iterations,
              kept.inverted_tets);
  const rigbuild::TetQuality quality = rigbuild::tetQuality(rig.tet_mesh, 0, rig.body_tet_count);
  std::printf("[ measured ] %s at %d: %d tet vertices (%d on the surface), %d tets, %s; volume change: ours %+.2f %%, our linear "
              "Laplacian %+.2f %%, survey reference %+.2f %%; handle |x - Mp|/diag max %.2e mean %.2e; fixed |x - p|/diag max %.2e; "
              "%d iterations, relative energy change %.1e, last 10-iteration step %.1e of the diagonal; inverted tets %d\n",
              c.name, c.tet_vertices, rig.tet_mesh.vertexCount(), rig.tet_mesh.vertexCount() - report.interior_vertices,
              rig.tet_mesh.tetCount(), quality.summary().c_str(), 100 * ours_change, 100 * linear_change, 100 * reference_change,
              handle_max, handle_sum / static_cast<double>(handles), fixed_max, ours.iterations, ours.relative_energy_change,
              ours.last_batch_step, ours.inverted_tets);

  EXPECT_TRUE(ours.converged);
  EXPECT_TRUE(linear.converged);
  EXPECT_EQ(ours.inverted_tets, 0);
  // Tets fit for deformation: the old quadric decimation (no edge bound, surface-only tets) gave
  // median radius ratios of 0.05-0.2 here and minima of 1e-3.
  EXPECT_GT(quality.median_radius_ratio, 0.4);
  EXPECT_GT(quality.min_radius_ratio, 0.005);
  // The budget is the whole tet mesh: surface vertices plus TetGen's interior points.
  EXPECT_NEAR(rig.tet_mesh.vertexCount(), c.tet_vertices, 0.06 * c.tet_vertices);
  // The survey's linear result loses volume (NOTES.md: 16 % cactus, 35 % cylinder), and so does our
  // own linear mode on the same rig: the setup reproduces the reference's situation.
  EXPECT_LT(reference_change, -0.10);
  EXPECT_LT(linear_change, -0.10);
  // The volumetric method keeps the volume: below a quarter of the reference's loss and of our
  // own linear mode's, and within the case's stated bound.
  EXPECT_LT(std::abs(ours_change), 0.25 * std::abs(reference_change));
  EXPECT_LT(std::abs(ours_change), 0.25 * std::abs(linear_change));
  EXPECT_LT(std::abs(ours_change), c.max_volume_change);
  EXPECT_LT(handle_max, c.max_handle_error);
  EXPECT_LT(fixed_max, c.max_fixed_error);
  // With the volume term the fine mesh keeps its volume within 1 % (issue 13's target), without
  // inverting a tet, and the handles still land.
  EXPECT_TRUE(kept.converged);
  EXPECT_EQ(kept.inverted_tets, 0);
  EXPECT_LT(std::abs(kept_change), 0.01);
  EXPECT_LT(std::abs(kept_change), 0.5 * std::abs(ours_change));
  EXPECT_LT(kept_handle_max, c.max_handle_error);
  EXPECT_LT(kept_fixed_max, c.max_fixed_error);
}

// Measured (this code: guarded OpenMesh decimation, TetGen pq2.0QY, the budget split between the
// surface and TetGen's interior points, min_corners 4, converged to 2e-7 of the diagonal per 10
// iterations): cylinder at 800 (792 tet vertices, 2930 tets): volume -5.30 % (survey reference
// -35.1 %, our linear mode -67.9 %), handle max 3.1e-3, fixed max 3.2e-3 of the diagonal; at
// 2500 (2530, 9324): -4.58 %, 2.8e-3, 1.2e-3. Cactus at 800 (786, 2526): -3.53 % (reference
// -16.1 %, linear -20.3 %), 1.1e-3, 1.8e-3; at 2500 (2528, 8747): -3.08 %, 8.6e-4, 7.6e-4. No
// inverted tet; tet radius ratio median 0.59-0.63, min 0.010-0.045. The bounds leave 1.3-1.6x
// (volume) and 1.6-4x (distances).
// Before (meshoptimizer's quadric decimation without an edge bound, TetGen pQY: no interior
// points): the cylinder kept a few rings and its tets ran the whole length (longest tet edge 12.0
// of a 12.3 diagonal at 800); bent by 120 degrees it folded (800: 130 inverted tets, fine volume
// -74 %; 2500: 205 inverted, -54 %); the cactus lost 7.2 % / 3.8 % with 6 / 5 inverted tets. See
// docs/rig-builder.md, "Deformation-survey edits".
INSTANTIATE_TEST_SUITE_P(Data, SurveyEdit,
                         ::testing::Values(SurveyCase{"cylinder", 800, 0.07, 6e-3, 6e-3}, SurveyCase{"cylinder", 2500, 0.07, 6e-3, 6e-3},
                                           SurveyCase{"cactus", 800, 0.05, 3e-3, 3e-3}, SurveyCase{"cactus", 2500, 0.05, 3e-3, 3e-3}),
                         [](const ::testing::TestParamInfo<SurveyCase>& param_info) {
                           return std::string(param_info.param.name) + "_" + std::to_string(param_info.param.tet_vertices);
                         });

}  // namespace
}  // namespace tetrig
