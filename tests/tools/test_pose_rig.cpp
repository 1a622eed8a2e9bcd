// Posing a rig offline: the .def reader (tetrig/rigbuild/pose_rig.hpp) on valid and broken files,
// poseRig's semantics on small generated rigs (rest pose, a rigid motion of a lone region, fixed
// iteration counts, refusals), the OBJ it writes, and `tetrig pose` through the binary: the
// deformation-survey edits reproduced from the command line (rig built by `tetrig build-rig` from
// the .sel through a rig JSON, posed with the .def) match the in-process pipeline of
// test_rig_deformation_survey, and bad input is one line, a non-zero exit and no file.
#include "run_command.hpp"
#include "small_rig.hpp"
#include "test_data.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/build_rig.hpp"
#include "tetrig/rigbuild/pose_rig.hpp"
#include "tetrig/rigbuild/rig_description.hpp"

#include <gtest/gtest.h>

#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace tetrig {
namespace {

using test::TempDir;

#define EXPECT_CONTAINS(haystack, needle) \
  EXPECT_NE(std::string(haystack).find(needle), std::string::npos) << "text: " << (haystack)

constexpr const char* kCylinderDef = R"(# 4x4 handle transformation matrix
-0.500000 0.000000 -0.866025 5.196152
0.000000 1.000000 0.000000 0.000000
0.866025 0.000000 -0.500000 9.000000
0.000000 0.000000 0.000000 1.000000
)";

std::string refusal(const std::string& text) {
  try {
    (void)rigbuild::parseDefText(text, "edit.def");
  } catch (const rigbuild::RigBuildError& e) {
    return e.what();
  }
  return "(accepted)";
}

TEST(DefFile, ReadsTheSurveyFormat) {
  const rigbuild::DefTransform d = rigbuild::parseDefText(kCylinderDef, "cylinder.def");
  EXPECT_EQ(d.matrix(0, 0), -0.5);
  EXPECT_EQ(d.matrix(0, 3), 5.196152);
  EXPECT_EQ(d.matrix(2, 0), 0.866025);
  EXPECT_EQ(d.matrix(3, 3), 1.0);
  // A rotation to the printed digits; its polar factor is the region's rotation, the last column
  // its translation.
  EXPECT_GT(d.rotation_error, 0.0);
  EXPECT_LT(d.rotation_error, 1e-5);
  const Eigen::Matrix3d r = d.rigid.rotation.toRotationMatrix();
  EXPECT_LT((r * r.transpose() - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  EXPECT_LT((r - d.matrix.topLeftCorner<3, 3>()).norm(), 1e-5);
  EXPECT_EQ(d.rigid.translation, Eigen::Vector3d(5.196152, 0.0, 9.0));
  // Comments anywhere, commas, CRLF line ends and one line holding everything are all fine.
  const rigbuild::DefTransform same = rigbuild::parseDefText(
      "# c\r\n-0.5, 0, -0.866025, 5.196152 # row 0\r\n0 1 0 0\n0.866025 0 -0.5 9\n0 0 0 1", "x.def");
  EXPECT_EQ(same.matrix, d.matrix);
  const rigbuild::DefTransform identity = rigbuild::parseDefText("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1", "i.def");
  EXPECT_EQ(identity.rigid.rotation.toRotationMatrix(), Eigen::Matrix3d::Identity());
  EXPECT_EQ(identity.rigid.translation, Eigen::Vector3d::Zero());
}

TEST(DefFile, RefusesWhatIsNotARigidTransform) {
  EXPECT_CONTAINS(refusal("1 0 0 0  0 1 0 0  0 0 1 0  0 0 0"), "edit.def: 15 numbers, a .def holds 16");
  EXPECT_CONTAINS(refusal(""), "edit.def: 0 numbers");
  EXPECT_CONTAINS(refusal("1 0 0 0  0 1 0 0  0 0 1 0  0 0 0 1 7"), "edit.def:1: more than 16 numbers");
  EXPECT_CONTAINS(refusal("1 0 0 0\n0 1 0 zero\n"), "edit.def:2: expected a finite number of the 4x4 matrix, found 'zero'");
  EXPECT_CONTAINS(refusal("1 0 0 0  0 1 0 nan  0 0 1 0  0 0 0 1"), "found 'nan'");
  EXPECT_CONTAINS(refusal("1 0 0 0  0 1 0 inf  0 0 1 0  0 0 0 1"), "found 'inf'");
  EXPECT_CONTAINS(refusal("1 0 0 0  0 1 0 1e999  0 0 1 0  0 0 0 1"), "found '1e999'");
  EXPECT_CONTAINS(refusal("1 0 0 0  0 1 0 0  0 0 1 0  0 0 1 1"), "bottom row is 0 0 1 1, not 0 0 0 1");
  // Scale, mirror and shear: region handles are rigid.
  EXPECT_CONTAINS(refusal("2 0 0 0  0 2 0 0  0 0 2 0  0 0 0 1"), "not a rotation (singular values 2 2 2");
  EXPECT_CONTAINS(refusal("-1 0 0 0  0 1 0 0  0 0 1 0  0 0 0 1"), "determinant -1");
  EXPECT_CONTAINS(refusal("1 0.5 0 0  0 1 0 0  0 0 1 0  0 0 0 1"), "remove the scale, shear or mirror");
  // Control bytes in a wrong file never reach the message raw.
  const std::string shown = refusal(std::string("1 0 \x1b[31m 0"));
  EXPECT_EQ(shown.find('\x1b'), std::string::npos) << shown;
  EXPECT_CONTAINS(shown, "found '\\x1b[31m'");

  const TempDir dir;
  try {
    (void)rigbuild::readDefFile(dir.path() / "missing.def");
    ADD_FAILURE() << "no exception";
  } catch (const rigbuild::RigBuildError& e) {
    EXPECT_CONTAINS(e.what(), "missing.def: no such .def file");
  }
  const std::filesystem::path big = dir.write("big.def", std::string(2u << 20, ' '));
  try {
    (void)rigbuild::readDefFile(big);
    ADD_FAILURE() << "no exception";
  } catch (const rigbuild::RigBuildError& e) {
    EXPECT_CONTAINS(e.what(), "not a .def");
  }
  EXPECT_EQ(rigbuild::readDefFile(dir.write("c.def", kCylinderDef)).matrix, rigbuild::parseDefText(kCylinderDef, "c").matrix);
}

double maxDistance(const std::vector<double>& a, const Vertices& b) {
  double d = 0.0;
  for (Eigen::Index v = 0; v < b.rows(); ++v) {
    const Eigen::Vector3d p(a[3 * static_cast<std::size_t>(v)], a[3 * static_cast<std::size_t>(v) + 1], a[3 * static_cast<std::size_t>(v) + 2]);
    d = std::max(d, (p - b.row(v).transpose()).norm());
  }
  return d;
}

// The small block rig of small_rig.hpp with one region ('floor') and nothing else.
Rig blockWithOneRegion(const TempDir& dir) {
  rigbuild::BuildRigInputs in;
  in.mesh = test::writeBlockTetMesh(dir, "lone");
  in.description = rigbuild::parseRigDescription(R"({ "name": "lone region", "mesh_unit": "m", "mesh_up": "y",
    "region_handles": [ { "name": "floor", "oriented": true,
                          "select": { "box": { "min": [-1, -0.01, -1], "max": [1, 0.01, 1] }, "min_corners": 3 } } ] })",
                                                 dir.path() / "lone.json");
  return rigbuild::buildRig(in);
}

TEST(PoseRig, RestAndRigidMotionOfALoneRegion) {
  const TempDir dir;
  const Rig rig = blockWithOneRegion(dir);
  ASSERT_EQ(rig.region_handle_names, std::vector<std::string>{"floor"});
  const double diag = boundingBoxDiagonal(rig.fine_vertices);
  // No transform given: everything at rest (energy 0, converged at the first check).
  const rigbuild::PoseResult rest = rigbuild::poseRig(rig, {});
  EXPECT_TRUE(rest.converged);
  EXPECT_EQ(rest.iterations, 10);
  EXPECT_LT(maxDistance(rest.fine_positions, rig.fine_vertices), 1e-12 * diag);
  EXPECT_EQ(rest.inverted_tets, 0);
  // The only handle moved rigidly: the whole body follows rigidly (zero energy), x = R p + t.
  RigidTransform m;
  m.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.6, Eigen::Vector3d(1, 2, 0.5).normalized()));
  m.translation = Eigen::Vector3d(0.3, -0.2, 0.15);
  const rigbuild::PoseResult moved = rigbuild::poseRig(rig, {{"floor", m}});
  EXPECT_TRUE(moved.converged);
  const Vertices expected = (rig.fine_vertices * m.rotation.toRotationMatrix().transpose()).rowwise() + m.translation.transpose();
  EXPECT_LT(maxDistance(moved.fine_positions, expected), 1e-5 * diag) << moved.iterations << " iterations";
  EXPECT_LT(moved.energy, 1e-10);
  EXPECT_EQ(moved.inverted_tets, 0);
}

TEST(PoseRig, FixedCountsBatchesAndRefusals) {
  const TempDir dir;
  const Rig rig = test::buildSmallRig(dir);  // region 'floor', markers, a point handle, a rigid group
  RigidTransform lift;
  lift.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()));
  lift.translation = Eigen::Vector3d(0, 0.02, 0);
  const rigbuild::PoseResult converged = rigbuild::poseRig(rig, {{"floor", lift}});
  ASSERT_TRUE(converged.converged);
  EXPECT_LE(converged.last_batch_step, 2e-7);
  EXPECT_GT(converged.iterations, 10);
  EXPECT_EQ(converged.iterations % 10, 0);
  // Markers (vertex handles) stayed at rest, the floor region took the transform.
  for (const RigMarker& mk : rig.markers) {
    const Eigen::Vector3d p(converged.tet_positions[3 * static_cast<std::size_t>(mk.tet_vertex)],
                            converged.tet_positions[3 * static_cast<std::size_t>(mk.tet_vertex) + 1],
                            converged.tet_positions[3 * static_cast<std::size_t>(mk.tet_vertex) + 2]);
    EXPECT_LT((p - rig.tet_mesh.vertices.row(mk.tet_vertex).transpose()).norm(), 1e-12) << mk.label;
  }
  for (const std::int32_t t : rig.setup.region_handles[0].tets) {
    for (int k = 0; k < 4; ++k) {
      const std::int32_t v = rig.tet_mesh.tets(t, k);
      const Eigen::Vector3d p(converged.tet_positions[3 * static_cast<std::size_t>(v)], converged.tet_positions[3 * static_cast<std::size_t>(v) + 1],
                              converged.tet_positions[3 * static_cast<std::size_t>(v) + 2]);
      EXPECT_LT((p - (lift.rotation * rig.tet_mesh.vertices.row(v).transpose() + lift.translation)).norm(), 1e-12);
    }
  }
  // A fixed count of the same length gives the same pose (batches are one continued run), a
  // shorter one a different pose.
  rigbuild::PoseOptions fixed;
  fixed.iterations = converged.iterations;
  const rigbuild::PoseResult same = rigbuild::poseRig(rig, {{"floor", lift}}, fixed);
  EXPECT_EQ(same.iterations, converged.iterations);
  EXPECT_EQ(same.tet_positions, converged.tet_positions);
  EXPECT_EQ(same.fine_positions, converged.fine_positions);
  fixed.iterations = 3;
  const rigbuild::PoseResult three = rigbuild::poseRig(rig, {{"floor", lift}}, fixed);
  EXPECT_EQ(three.iterations, 3);
  EXPECT_TRUE(three.converged);
  EXPECT_NE(three.tet_positions, converged.tet_positions);
  // Bounded: one batch is not enough here, so converged is false.
  rigbuild::PoseOptions short_run;
  short_run.max_iterations = 10;
  const rigbuild::PoseResult bounded = rigbuild::poseRig(rig, {{"floor", lift}}, short_run);
  EXPECT_FALSE(bounded.converged);
  EXPECT_EQ(bounded.iterations, 10);

  auto refused = [&rig](const std::vector<std::pair<std::string, RigidTransform>>& regions) {
    try {
      (void)rigbuild::poseRig(rig, regions);
    } catch (const rigbuild::RigBuildError& e) {
      return std::string(e.what());
    }
    return std::string("(accepted)");
  };
  EXPECT_CONTAINS(refused({{"flor", lift}}), "no region handle named 'flor' in the rig (its regions: 'floor')");
  EXPECT_CONTAINS(refused({{"floor", lift}, {"floor", lift}}), "region handle 'floor' is posed twice");
  RigidTransform broken = lift;
  broken.translation.x() = std::nan("");
  EXPECT_CONTAINS(refused({{"floor", broken}}), "not a finite rigid motion");
  RigidTransform absurd = lift;
  absurd.translation.x() = 1e9;
  EXPECT_CONTAINS(refused({{"floor", absurd}}), "refused the pose's targets");
}

TEST(PoseRig, ObjTextHasTheFineMeshInItsOrder) {
  const TempDir dir;
  const Rig rig = blockWithOneRegion(dir);
  const rigbuild::PoseResult rest = rigbuild::poseRig(rig, {});
  const std::string text = rigbuild::fineMeshObjText(rig, rest.fine_positions, "line one\nline two");
  std::istringstream in(text);
  std::string line;
  std::vector<std::string> comments;
  std::vector<Eigen::Vector3d> v;
  std::vector<std::array<int, 3>> f;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    std::string tag;
    s >> tag;
    if (tag == "#") comments.push_back(line);
    if (tag == "v") {
      Eigen::Vector3d p;
      s >> p.x() >> p.y() >> p.z();
      v.push_back(p);
    }
    if (tag == "f") {
      std::array<int, 3> t{};
      s >> t[0] >> t[1] >> t[2];
      f.push_back(t);
    }
  }
  EXPECT_EQ(comments, (std::vector<std::string>{"# line one", "# line two"}));
  ASSERT_EQ(static_cast<Eigen::Index>(v.size()), rig.fine_vertices.rows());
  ASSERT_EQ(static_cast<Eigen::Index>(f.size()), rig.fine_triangles.rows());
  for (std::size_t i = 0; i < v.size(); ++i) {
    EXPECT_LT((v[i] - rig.fine_vertices.row(static_cast<Eigen::Index>(i)).transpose()).norm(), 1e-9) << i;
  }
  for (std::size_t i = 0; i < f.size(); ++i) {
    for (int k = 0; k < 3; ++k) EXPECT_EQ(f[i][static_cast<std::size_t>(k)], rig.fine_triangles(static_cast<Eigen::Index>(i), k) + 1);
  }
  EXPECT_THROW((void)rigbuild::fineMeshObjText(rig, std::vector<double>(3), ""), rigbuild::RigBuildError);
  const std::filesystem::path out = dir.path() / "rest.obj";
  rigbuild::writeObjAtomically(out, rig, rest.fine_positions, "line one\nline two");
  std::ifstream file(out);
  std::stringstream read;
  read << file.rdbuf();
  EXPECT_EQ(read.str(), text);
}

// ---- tetrig pose through the binary ----

using CliRun = test::CommandRun;

CliRun runTetrig(const std::string& args, const TempDir& dir) { return test::runCommand(TETRIG_EXE, args, dir.path()); }

std::vector<double> readObjVertices(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::vector<double> x;
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("v ", 0) != 0) continue;
    std::istringstream s(line.substr(2));
    double a = 0, b = 0, c = 0;
    s >> a >> b >> c;
    x.insert(x.end(), {a, b, c});
  }
  return x;
}

// The survey rig JSON of test_rig_deformation_survey: the .sel's fixed (0) and handle (2)
// statuses as two oriented region handles, min_corners 4.
std::string surveyJson(const std::string& name, const std::filesystem::path& sel) {
  return R"({ "name": ")" + name + R"(", "mesh_unit": "m", "mesh_up": "y",
    "region_handles": [
      { "name": "fixed", "oriented": true, "select": { "sel_file": ")" + sel.string() + R"(", "sel_values": [0], "min_corners": 4 } },
      { "name": "handle", "oriented": true, "select": { "sel_file": ")" + sel.string() + R"(", "sel_values": [2], "min_corners": 4 } } ] })";
}

class PoseCli : public ::testing::TestWithParam<const char*> {};

TEST_P(PoseCli, SurveyEditFromTheCommandLineMatchesTheInProcessResult) {
  const std::string name = GetParam();
  const std::string base = "meshes/deformation-survey/" + name;
  TETRIG_REQUIRE_DATA(mesh, base + ".off");
  TETRIG_REQUIRE_DATA(sel, base + ".sel");
  TETRIG_REQUIRE_DATA(def, base + ".def");
  const TempDir dir;
  const std::filesystem::path json = dir.write("survey.json", surveyJson(name, sel));
  const std::string rig_path = (dir.path() / (name + ".rig")).string();
  const std::string obj = (dir.path() / "posed.obj").string();
  const CliRun b = runTetrig("build-rig --mesh '" + mesh.string() + "' --rig '" + json.string() + "' --tet-vertices 800 --out '" +
                                 rig_path + "' --quiet",
                             dir);
  ASSERT_EQ(b.status, 0) << b.err;
  // inspect reports the tets' quality (body tets): parse the median back.
  const CliRun inspect = runTetrig("inspect '" + rig_path + "'", dir);
  ASSERT_EQ(inspect.status, 0) << inspect.err;
  const std::size_t at = inspect.out.find("tet quality:   radius ratio min ");
  ASSERT_NE(at, std::string::npos) << inspect.out;
  const std::size_t median_at = inspect.out.find("median ", at);
  ASSERT_NE(median_at, std::string::npos) << inspect.out;
  EXPECT_GT(std::stod(inspect.out.substr(median_at + 7)), 0.4) << inspect.out;
  const CliRun p = runTetrig("pose '" + rig_path + "' --region 'handle=" + def.string() + "' --out '" + obj + "'", dir);
  ASSERT_EQ(p.status, 0) << p.err;
  EXPECT_CONTAINS(p.out, "converged");
  EXPECT_CONTAINS(p.out, " 0 of ");  // no inverted tet
  EXPECT_CONTAINS(p.out, "wrote " + obj);
  EXPECT_EQ(p.err, "");

  // In process, as test_rig_deformation_survey does it: the same rig, the same pose.
  rigbuild::BuildRigInputs in;
  in.mesh = mesh;
  in.description = rigbuild::parseRigDescription(surveyJson(name, sel), dir.path() / "survey.json");
  in.tet_vertices = 800;
  const Rig rig = rigbuild::buildRig(in);
  const Rig loaded = loadRigFile(rig_path);
  EXPECT_EQ(loaded.tet_mesh.vertices, rig.tet_mesh.vertices) << "the build is deterministic";
  EXPECT_EQ(loaded.tet_mesh.tets, rig.tet_mesh.tets);
  const rigbuild::PoseResult r = rigbuild::poseRig(rig, {{"handle", rigbuild::readDefFile(def).rigid}});
  ASSERT_TRUE(r.converged);
  const std::vector<double> posed = readObjVertices(obj);
  ASSERT_EQ(posed.size(), r.fine_positions.size());
  double worst = 0.0;
  for (std::size_t k = 0; k < posed.size(); ++k) worst = std::max(worst, std::abs(posed[k] - r.fine_positions[k]));
  const double diag = boundingBoxDiagonal(rig.fine_vertices);
  EXPECT_LT(worst, 1e-8 * diag) << "the OBJ holds the in-process pose to its 10 printed digits";
  // And it is the edit: the handle's vertices on the .def's transform (file vertex i = OBJ vertex i).
  const rigbuild::DefTransform d = rigbuild::readDefFile(def);
  std::ifstream sel_in(sel);
  double handle_error = 0.0;
  std::size_t i = 0;
  for (std::string line; std::getline(sel_in, line);) {
    if (line.empty() || line[0] == '#') continue;
    if (std::stoi(line) == 2) {
      const Eigen::Vector3d rest = rig.fine_vertices.row(static_cast<Eigen::Index>(i)).transpose();
      const Eigen::Vector3d x(posed[3 * i], posed[3 * i + 1], posed[3 * i + 2]);
      handle_error = std::max(handle_error, (x - (d.matrix.topLeftCorner<3, 3>() * rest + d.matrix.topRightCorner<3, 1>())).norm() / diag);
    }
    ++i;
  }
  EXPECT_EQ(i, static_cast<std::size_t>(rig.fine_vertices.rows()));
  EXPECT_LT(handle_error, 6e-3);
  std::printf("[ measured ] tetrig pose %s at 800: %d iterations, OBJ vs in-process max difference %.2e of the diagonal, handle error "
              "max %.2e\n", name.c_str(), r.iterations, worst / diag, handle_error);
}

INSTANTIATE_TEST_SUITE_P(Data, PoseCli, ::testing::Values("cylinder", "cactus"),
                         [](const ::testing::TestParamInfo<const char*>& param_info) { return std::string(param_info.param); });

TEST(PoseCliErrors, OneLineNonZeroAndNoFile) {
  const TempDir dir;
  const std::filesystem::path node = test::writeBlockTetMesh(dir, "block");
  const std::filesystem::path json = dir.write("small.json", test::smallRigJson());
  const std::filesystem::path clip = test::writeSmallClip(dir);
  const std::string rig = (dir.path() / "small.rig").string();
  ASSERT_EQ(runTetrig("build-rig --mesh '" + node.string() + "' --rig '" + json.string() + "' --markers '" + clip.string() + "' --out '" +
                          rig + "' --quiet",
                      dir)
                .status,
            0);
  const std::filesystem::path good = dir.write("lift.def", "# lift\n1 0 0 0\n0 1 0 0.02\n0 0 1 0\n0 0 0 1\n");
  const std::string obj = (dir.path() / "out.obj").string();
  auto one_line_error = [&](const std::string& args, const std::string& needle) {
    const CliRun r = runTetrig(args, dir);
    EXPECT_NE(r.status, 0) << args;
    EXPECT_EQ(r.err.rfind("tetrig pose: error: ", 0), 0u) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_CONTAINS(r.err, needle);
    EXPECT_FALSE(std::filesystem::exists(obj)) << args;
  };
  one_line_error("pose '" + rig + "' --region 'flor=" + good.string() + "' --out '" + obj + "'",
                 "no region handle named 'flor' in the rig (its regions: 'floor')");
  one_line_error("pose '" + rig + "' --region '" + good.string() + "' --out '" + obj + "'", "--region expects NAME=FILE.def");
  one_line_error("pose '" + rig + "' --region 'floor=' --out '" + obj + "'", "--region expects NAME=FILE.def");
  one_line_error("pose '" + rig + "' --region 'floor=" + (dir.path() / "none.def").string() + "' --out '" + obj + "'",
                 "none.def: no such .def file");
  const std::filesystem::path word = dir.write("word.def", "1 0 0 0\n0 1 0 up\n0 0 1 0\n0 0 0 1\n");
  one_line_error("pose '" + rig + "' --region 'floor=" + word.string() + "' --out '" + obj + "'", "word.def:2: expected a finite number");
  const std::filesystem::path scaled = dir.write("scaled.def", "2 0 0 0\n0 2 0 0\n0 0 2 0\n0 0 0 1\n");
  one_line_error("pose '" + rig + "' --region 'floor=" + scaled.string() + "' --out '" + obj + "'", "not a rotation");
  one_line_error("pose '" + rig + "' --region 'floor=" + good.string() + "' --region 'floor=" + good.string() + "' --out '" + obj + "'",
                 "posed twice");
  one_line_error("pose /nonexistent/x.rig --region 'floor=" + good.string() + "' --out '" + obj + "'", "/nonexistent/x.rig");
  one_line_error("pose '" + rig + "' --region 'floor=" + good.string() + "' --max-iterations 10 --out '" + obj + "'",
                 "did not converge in 10 iterations");
  // An output directory that does not exist: refused by the atomic writer, nothing left behind.
  const CliRun nodir =
      runTetrig("pose '" + rig + "' --region 'floor=" + good.string() + "' --out '" + (dir.path() / "no/dir/x.obj").string() + "'", dir);
  EXPECT_NE(nodir.status, 0);
  EXPECT_EQ(nodir.err.rfind("tetrig pose: error: ", 0), 0u) << nodir.err;
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "no"));
  // --region and --out are required (CLI11's own message), and --help names the options.
  EXPECT_NE(runTetrig("pose '" + rig + "' --out '" + obj + "'", dir).status, 0);
  EXPECT_NE(runTetrig("pose '" + rig + "' --region 'floor=" + good.string() + "'", dir).status, 0);
  const CliRun help = runTetrig("pose --help", dir);
  EXPECT_EQ(help.status, 0);
  for (const char* flag : {"RIG", "--region", "--out", "--iterations", "--max-iterations"}) EXPECT_CONTAINS(help.out, flag);
  // A fixed count runs exactly that many and writes the file.
  const CliRun fixed = runTetrig("pose '" + rig + "' --region 'floor=" + good.string() + "' --iterations 7 --out '" + obj + "'", dir);
  ASSERT_EQ(fixed.status, 0) << fixed.err;
  EXPECT_CONTAINS(fixed.out, "7 iterations (fixed count");
  const Rig loaded = loadRigFile(rig);
  EXPECT_EQ(readObjVertices(obj).size(), static_cast<std::size_t>(loaded.fine_vertices.rows()) * 3);
}

}  // namespace
}  // namespace tetrig
