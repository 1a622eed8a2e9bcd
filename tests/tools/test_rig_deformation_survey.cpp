// The deformation-survey editing cases (Botsch & Sorkine; ../shared/data/NOTES.md section 1):
// cactus and cylinder, each with a .sel (per file vertex: 0 fixed, 1 region of interest, 2 handle)
// and a .def (4x4 transform of the handle). The rig is built from the .sel through the rig JSON
// (two region handles with sel_file selections), the .def is applied to the handle region, the
// Deformer runs to convergence and the fine mesh is reconstructed by pose transfer. Measured on
// the FINE mesh against the survey's own linear-Laplacian result (*-laplacian_editing.off, same
// vertices and faces, read here): volume, handle vertices on the .def transform, fixed vertices
// in place, no inverted tet.
#include "small_rig.hpp"
#include "tetrig/deformer.hpp"
#include "tetrig/pose_transfer.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/build_rig.hpp"
#include "tetrig/rigbuild/rig_description.hpp"
#include "test_data.hpp"

#include <Eigen/SVD>
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

Eigen::Matrix4d readDef(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::vector<double> values;
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream s(line);
    for (double x; s >> x;) values.push_back(x);
  }
  Eigen::Matrix4d m = Eigen::Matrix4d::Zero();
  if (values.size() == 16) {
    for (int i = 0; i < 16; ++i) m(i / 4, i % 4) = values[static_cast<std::size_t>(i)];
  }
  return m;
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

// Test names and ctest listings show the case's name instead of its bytes.
void PrintTo(const SurveyCase& c, std::ostream* os) { *os << c.name; }

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
  const Eigen::Matrix4d def = readDef(def_path);
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
  // its nearest rotation (polar factor) goes to the region handle.
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(def.topLeftCorner<3, 3>(), Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Matrix3d rotation = svd.matrixU() * svd.matrixV().transpose();
  ASSERT_GT(rotation.determinant(), 0.0);
  ASSERT_LT((rotation - def.topLeftCorner<3, 3>()).norm(), 1e-4);

  // The rig: region handles from the .sel (statuses 0 and 2), oriented so that the handle's
  // rotation is interpolated over the mesh. How a .sel status reaches the tets: file vertex i is
  // fine vertex i (importSurface keeps the file order); the selected fine vertices that the
  // decimation kept are the selected tet vertices S (TetGen's interior points are never in S);
  // a tet joins the region when all four corners are in S (min_corners 4). With the default 3, a
  // tet with three corners on the selection drags its fourth, region-of-interest corner into the
  // rigid handle (measured on the cylinder at 800 tet vertices: the handle region reached from
  // z = 11.5 down to z = 5.5, half the cylinder). Fine vertices the decimation removed follow
  // through B; the errors below are measured on them too.
  const TempDir dir;
  const std::string json = R"({ "name": ")" + std::string(c.name) + R"(", "mesh_unit": "m", "mesh_up": "y",
    "region_handles": [
      { "name": "fixed", "oriented": true, "select": { "sel_file": ")" + sel_path.string() + R"(", "sel_values": [0], "min_corners": 4 } },
      { "name": "handle", "oriented": true, "select": { "sel_file": ")" + sel_path.string() + R"(", "sel_values": [2], "min_corners": 4 } } ] })";
  rigbuild::BuildRigInputs in;
  in.mesh = mesh_path;
  in.description = rigbuild::parseRigDescription(json, dir.path() / "survey.json");
  in.tet_vertices = c.tet_vertices;
  const Rig rig = rigbuild::buildRig(in);
  ASSERT_EQ(rig.setup.region_handles.size(), 2u);

  // The fine mesh is the file's mesh in the file's order (the importer keeps it): fine vertex i
  // is file vertex i, so the .sel statuses apply to the fine mesh directly.
  ASSERT_EQ(static_cast<std::size_t>(rig.fine_vertices.rows()), nv);
  for (std::size_t i = 0; i < nv; ++i) {
    ASSERT_EQ(Eigen::Vector3d(rig.fine_vertices.row(static_cast<Eigen::Index>(i)).transpose()), rest.v[i]) << "vertex " << i;
  }

  auto deform = [&](bool update_rotations, std::vector<double>& fine, double& converged_step, int& iterations) {
    DeformerSetup setup = rig.setup;
    setup.options.update_rotations = update_rotations;
    Deformer deformer(rig.tet_mesh, setup);
    std::vector<RigidTransform> regions(2);
    regions[1].rotation = Eigen::Quaterniond(rotation);
    regions[1].translation = def.topRightCorner<3, 1>();
    HandleTargets targets;
    targets.region_transforms = regions;
    StepBudget budget;
    budget.max_iterations = 10;
    // To convergence: until ten more iterations move no tet vertex by more than 1e-7 of the
    // diagonal (at most 5000 iterations).
    std::vector<double> previous(deformer.positions().begin(), deformer.positions().end());
    converged_step = 0;
    iterations = 0;
    for (int batch = 0; batch < 500; ++batch) {
      const StepStats stats = deformer.step(targets, budget);
      iterations += stats.iterations;
      EXPECT_EQ(stats.flags & (kStepTargetsRejected | kStepTargetsWrongSize), 0u);
      double moved = 0;
      for (std::size_t k = 0; k < previous.size(); ++k) moved = std::max(moved, std::abs(deformer.positions()[k] - previous[k]));
      previous.assign(deformer.positions().begin(), deformer.positions().end());
      converged_step = moved / diag;
      if (converged_step < 1e-7) break;
    }
    // No inverted or flat tet in the deformed tet mesh.
    TetMesh deformed = rig.tet_mesh;
    for (std::int32_t v = 0; v < deformed.vertexCount(); ++v) deformed.vertices.row(v) = deformer.position(v).transpose();
    std::int32_t inverted = 0;
    for (std::int32_t t = 0; t < deformed.tetCount(); ++t) inverted += signedVolume(deformed, t) <= 0.0 ? 1 : 0;
    fine.assign(nv * 3, 0.0);
    applyPoseTransfer(rig.pose_transfer.view(), deformer.positions().data(), fine.data());
    return inverted;
  };

  std::vector<double> fine;
  double last_step = 0;
  int iterations = 0;
  const std::int32_t inverted = deform(true, fine, last_step, iterations);
  auto finePoint = [&fine](std::size_t i) { return Eigen::Vector3d(fine[3 * i], fine[3 * i + 1], fine[3 * i + 2]); };
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
  std::vector<double> linear_fine;
  double linear_step = 0;
  int linear_iterations = 0;
  (void)deform(false, linear_fine, linear_step, linear_iterations);
  const double linear_change =
      enclosedVolume([&](int i) { return Eigen::Vector3d(linear_fine[3 * static_cast<std::size_t>(i)], linear_fine[3 * static_cast<std::size_t>(i) + 1],
                                                         linear_fine[3 * static_cast<std::size_t>(i) + 2]); },
                     rest.f) /
          rest_volume -
      1.0;
  std::printf("[ measured ] %s: %d tet vertices, %d tets; volume change: ours %+.2f %%, our linear Laplacian %+.2f %%, "
              "survey reference %+.2f %%; handle |x - Mp|/diag max %.2e mean %.2e; fixed |x - p|/diag max %.2e; last 10-iteration "
              "step %.1e of the diagonal after %d iterations; inverted tets %d\n",
              c.name, rig.tet_mesh.vertexCount(), rig.tet_mesh.tetCount(), 100 * ours_change, 100 * linear_change,
              100 * reference_change, handle_max, handle_sum / static_cast<double>(handles), fixed_max, last_step, iterations,
              inverted);

  EXPECT_LT(last_step, 1e-7) << "did not converge";
  EXPECT_EQ(inverted, 0);
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
}

// Measured (this code, min_corners 4): cylinder (4802 fine vertices, not decimated; TetGen adds
// 99 interior points: 4901 tet vertices, 13307 tets): volume -6.8 % (survey reference -35.1 %,
// our linear mode -68.7 %), handle error max 4.6e-4, fixed max 4.0e-4 of the diagonal, no
// inverted tet. Cactus (5261 -> 5000 tet vertices, 18086 tets): volume -3.1 % (reference
// -16.1 %, our linear -19.7 %), handle max 3.6e-4, fixed max 5.0e-4, no inverted tet. The bounds
// leave about 1.5x (volume) and 4x (distances) of room.
// Why these tet budgets: quadric decimation of the cylinder (zero error along its straight
// generators) leaves tets as long as the whole cylinder (longest tet edge 12.0 of a 12.3
// diagonal at 800 tet vertices); bent by 120 degrees such a mesh folds (800: 185 inverted tets,
// fine volume -83 %; 2500: 205 inverted, -54 %). The cactus at 2500 loses 3.8 % but has 5
// inverted tets. See docs/rig-builder.md, "Deformation-survey edits".
INSTANTIATE_TEST_SUITE_P(Data, SurveyEdit,
                         ::testing::Values(SurveyCase{"cylinder", 5000, 0.10, 2e-3, 2e-3},
                                           SurveyCase{"cactus", 5000, 0.05, 2e-3, 2e-3}),
                         [](const ::testing::TestParamInfo<SurveyCase>& param_info) { return std::string(param_info.param.name); });

}  // namespace
}  // namespace tetrig
