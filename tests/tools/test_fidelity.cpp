// tetrig_fidelity (bench/tools/fidelity.cpp, docs/fidelity.md) on real data: the SMPL rig driven by
// the HDM05 clip for a few hundred frames. What a user of the tool relies on: the JSON holds one run
// per iteration count with the documented keys; more iterations per frame land nearer the converged
// pose; the converged reference is never above the budgeted result's energy; the temporal prediction
// of the warm start (the default) lands nearer than the plain warm start (--no-predict); bad
// arguments exit non-zero with one line naming the problem.
#include "run_command.hpp"
#include "small_rig.hpp"
#include "test_data.hpp"

#include "tetrig/drivers/c3d_playback.hpp"
#include "tetrig/live_rig.hpp"
#include "tetrig/polar.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/rig_description.hpp"
#include "tetrig/rigbuild/build_rig.hpp"

#include <gtest/gtest.h>

#include <sys/wait.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <limits>
#include <map>
#include <set>
#include <span>
#include <vector>
#include <fstream>
#include <sstream>
#include <string>
#include <string_view>

namespace tetrig {
namespace {

using test::TempDir;

using ToolRun = test::CommandRun;

// The tests measure each mechanism against the plain chain: every run starts from
// SolverSettings::plain() by flags (a later numeric flag overrides these). `keep` leaves one switch
// of the plain chain out, so the tool's default turns that mechanism on: "prediction" (no
// --no-predict), "volume" (no --no-keep-volume), or "defaults" (no plain flags at all: the tool's
// defaults, the accurate settings every tool shares).
ToolRun fidelity(const std::string& args, const TempDir& dir, std::string_view keep = {}) {
  std::string plain;
  if (keep != "defaults") {
    if (keep != "prediction") plain += "--no-predict ";
    if (keep != "volume") plain += "--no-keep-volume ";
    plain += "--inversion-guard 0 --inversion-guard-solves 0 --inversion-guard-threshold 0.5 ";
  }
  return test::runCommand(TETRIG_FIDELITY_EXE, plain + args, dir.path());
}

class FidelityTool : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    const auto man = test::dataPath("meshes/odedstein-meshes/human_man.obj");
    clip_ = new std::filesystem::path(test::dataPath("mocap/hdm05/HDM_mm_01-02_03_120.c3d"));
    if (!std::filesystem::exists(man) || !std::filesystem::exists(*clip_)) return;
    dir_ = new TempDir();
    rigbuild::BuildRigInputs in;
    in.mesh = man;
    in.clip = *clip_;
    in.tet_vertices = 800;
    in.max_marker_distance = 0.15;
    in.check_deformer = false;
    const std::vector<std::uint8_t> bytes = serializeRig(rigbuild::buildRig(in));
    rig_ = new std::filesystem::path(dir_->writeBytes("smpl.rig", bytes));
    in.tet_vertices = 300;  // the coarse level, built as build-rig builds the one it puts inside a rig
    in.coarse_level = true;
    coarse_ = new std::filesystem::path(dir_->writeBytes("smpl_coarse.rig", serializeRig(rigbuild::buildRig(in))));
    in.tet_vertices = 800;  // the same rig with its coarse level inside (build-rig --coarse-tet-vertices 300)
    in.coarse_level = false;
    in.coarse_tet_vertices = 300;
    embedded_ = new std::filesystem::path(dir_->writeBytes("smpl_embedded.rig", serializeRig(rigbuild::buildRig(in))));
  }
  static void TearDownTestSuite() {
    delete rig_;
    delete clip_;
    delete coarse_;
    delete embedded_;
    delete dir_;
    rig_ = clip_ = coarse_ = embedded_ = nullptr;
    dir_ = nullptr;
  }
  void SetUp() override {
    TETRIG_REQUIRE_DATA(man, "meshes/odedstein-meshes/human_man.obj");
    TETRIG_REQUIRE_DATA(clip, "mocap/hdm05/HDM_mm_01-02_03_120.c3d");
    ASSERT_NE(rig_, nullptr);
  }
  // The rig `tetrig build-rig --mesh human_man.obj --clip HDM05 --max-marker-distance 0.15` builds
  // (its default 2505 tet vertices, rigid marker groups, coarse level).
  static Rig defaultRig() {
    rigbuild::BuildRigInputs in;
    in.mesh = test::dataPath("meshes/odedstein-meshes/human_man.obj");
    in.clip = *clip_;
    in.max_marker_distance = 0.15;
    in.check_deformer = false;
    return rigbuild::buildRig(in);
  }
  // The fixture's 800-tet-vertex SMPL rig built with a rig description from assets/.
  static Rig withAsset(const char* description) {
    return withDescription(rigbuild::readRigDescription(std::filesystem::path(TETRIG_SOURCE_DIR) / "assets" / description));
  }
  static Rig withDescription(const rigbuild::RigDescription& description) {
    rigbuild::BuildRigInputs in;
    in.mesh = test::dataPath("meshes/odedstein-meshes/human_man.obj");
    in.clip = *clip_;
    in.tet_vertices = 800;
    in.max_marker_distance = 0.15;
    in.check_deformer = false;
    in.description = description;
    return rigbuild::buildRig(in);
  }
  static std::string common_all() { return "--rig '" + rig_->string() + "' --c3d '" + clip_->string() + "' -q "; }
  static std::string common() { return common_all() + "--frames 240 --reference-every 20 "; }
  static inline TempDir* dir_ = nullptr;
  static inline std::filesystem::path* rig_ = nullptr;
  static inline std::filesystem::path* clip_ = nullptr;
  static inline std::filesystem::path* coarse_ = nullptr;
  static inline std::filesystem::path* embedded_ = nullptr;
};

nlohmann::json readJson(const std::filesystem::path& p) {
  std::ifstream in(p);
  return nlohmann::json::parse(in);
}

// A tet's centroid in the rig's rest pose.
Eigen::Vector3d restCentroid(const Rig& rig, std::int32_t t) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int k = 0; k < 4; ++k) c += 0.25 * rig.tet_mesh.vertices.row(rig.tet_mesh.tets(t, k)).transpose();
  return c;
}

// Where the volume goes and the tets invert (each reference frame's `regions`), by the rig marker
// nearest each body tet: the regions' inverted tets add up to the frame's count (counted apart, by
// the energy's measure), and the regions that lost the most volume come first, each a few percent of
// the body at most. Returns the number of poses (budgeted or converged) with inverted tets.
int checkRegions(const Rig& rig, const nlohmann::json& run) {
  std::set<std::string> labels;
  for (const auto& m : rig.markers) labels.insert(m.label);
  int with_inversions = 0;
  for (const auto& f : run["reference"]) {
    for (const char* pose : {"budgeted", "converged"}) {
      const auto& t = f["regions"][pose];
      int inverted = 0;
      for (const auto& [label, n] : t["inverted_near"].items()) {
        EXPECT_TRUE(labels.count(label)) << label;
        EXPECT_GT(n.get<int>(), 0);
        inverted += n.get<int>();
      }
      EXPECT_EQ(inverted, f[std::string(pose) == "budgeted" ? "inverted_body_tets" : "inverted_body_tets_converged"].get<int>())
          << "frame " << f["frame"] << " " << pose;
      // Each inverted tet listed: a body tet, inverted (det F <= 0), of a valid rest shape, in a
      // region that counts it, with its corners; as many as counted.
      std::map<std::string, int> listed;
      std::set<int> tets;
      for (const auto& tet : t["inverted_tets"]) {
        const int id = tet["tet"].get<int>();
        EXPECT_GE(id, 0);
        EXPECT_LT(id, rig.body_tet_count);
        EXPECT_TRUE(tets.insert(id).second) << "tet " << id << " listed twice";
        EXPECT_LE(tet["volume_ratio"].get<double>(), 0.0);
        EXPECT_GT(tet["rest_radius_ratio"].get<double>(), 0.0);
        EXPECT_LE(tet["rest_radius_ratio"].get<double>(), 1.0 + 1e-9);
        ++listed[tet["near"].get<std::string>()];
        for (int k = 0; k < 4; ++k) EXPECT_EQ(tet["corners"][static_cast<std::size_t>(k)].get<int>(), rig.tet_mesh.tets(id, k));
      }
      EXPECT_EQ(static_cast<int>(tets.size()), inverted) << "frame " << f["frame"] << " " << pose;
      for (const auto& [label, n] : t["inverted_near"].items()) EXPECT_EQ(listed[label], n.get<int>()) << label;
      with_inversions += inverted > 0;
      EXPECT_LE(t["volume_change_near"].size(), 3u);
      double previous = -1.0;
      for (const auto& region : t["volume_change_near"]) {
        EXPECT_TRUE(labels.count(region["label"].get<std::string>()));
        const double c = region["change"].get<double>();
        EXPECT_LT(c, 0.0);
        EXPECT_GT(c, -0.05) << "one region lost more than 5 % of the body: frame " << f["frame"];
        EXPECT_GE(c, previous) << "most lost first";
        previous = c;
      }
    }
    EXPECT_FALSE(f["regions"]["converged"]["volume_change_near"].empty()) << "a real pose loses volume somewhere";
  }
  return with_inversions;
}

// Every body tet the budgeted pose inverted in any played frame (`inverted_body_tets_any_frame`):
// listed once, a body tet, in as many frames as the run has frames with any (or fewer), first
// <= last within the run, inverted (lowest det F <= 0), named by its region; and on a reference
// frame every inverted tet the regions list is in it. Returns the entries.
nlohmann::json checkAnyFrame(const Rig& rig, const nlohmann::json& run, std::size_t first_frame) {
  const nlohmann::json& list = run["inverted_body_tets_any_frame"];
  std::set<int> tets;
  std::size_t most = 0;
  for (const auto& t : list) {
    const int id = t["tet"].get<int>();
    EXPECT_TRUE(tets.insert(id).second) << "tet " << id << " listed twice";
    EXPECT_GE(id, 0);
    EXPECT_LT(id, rig.body_tet_count);
    const std::size_t frames = t["frames"].get<std::size_t>();
    EXPECT_GE(frames, 1u);
    most = std::max(most, frames);
    EXPECT_GE(t["first_frame"].get<std::size_t>(), first_frame);
    EXPECT_LE(t["first_frame"].get<std::size_t>(), t["last_frame"].get<std::size_t>());
    EXPECT_LT(t["last_frame"].get<std::size_t>(), first_frame + run["frames"].get<std::size_t>());
    EXPECT_LE(t["last_frame"].get<std::size_t>() - t["first_frame"].get<std::size_t>() + 1, run["frames"].get<std::size_t>());
    EXPECT_LE(t["lowest_volume_ratio"].get<double>(), 0.0);
    EXPECT_FALSE(t["near"].get<std::string>().empty());
  }
  EXPECT_LE(most, run["frames_with_inverted_body_tets"].get<std::size_t>());
  EXPECT_EQ(list.empty(), run["frames_with_inverted_body_tets"].get<std::size_t>() == 0);
  for (const auto& f : run["reference"])
    for (const auto& tet : f["regions"]["budgeted"]["inverted_tets"]) EXPECT_TRUE(tets.count(tet["tet"].get<int>())) << tet["tet"];
  return list;
}

TEST_F(FidelityTool, MoreIterationsLandNearerAndTheReferenceIsConverged) {
  const TempDir dir;
  const auto json = dir.path() / "f.json";
  const ToolRun r = fidelity(common() + "--iterations 1,5 --json '" + json.string() + "'", dir);
  ASSERT_EQ(r.status, 0) << r.err;
  const nlohmann::json j = readJson(json);
  ASSERT_EQ(j["runs"].size(), 2u);
  const auto& one = j["runs"][0];
  const auto& five = j["runs"][1];
  EXPECT_EQ(one["iterations"], 1);
  EXPECT_EQ(five["iterations"], 5);
  for (const auto* run : {&one, &five}) {
    EXPECT_EQ((*run)["clip"], "HDM_mm_01-02_03_120.c3d");
    EXPECT_EQ((*run)["reference_frames"], 12);
    for (const char* key : {"rms_error_mm", "max_error_mm", "energy_excess"})
      for (const char* q : {"median", "p90", "p99", "max"}) ASSERT_TRUE((*run)[key].contains(q)) << key << " " << q;
    EXPECT_TRUE((*run)["inverted_body_tets_max"].is_number_integer());
    // The frame of the most inverted tets is a played frame; frames with any are at most all of them.
    EXPECT_LT((*run)["inverted_body_tets_max_frame"].get<std::size_t>(), (*run)["frames"].get<std::size_t>());
    EXPECT_LE((*run)["frames_with_inverted_body_tets"].get<std::size_t>(), (*run)["frames"].get<std::size_t>());
    EXPECT_EQ((*run)["frames_with_inverted_body_tets"].get<std::size_t>() == 0, (*run)["inverted_body_tets_max"].get<int>() == 0);
    EXPECT_TRUE((*run)["volume_change_max"].is_number());
    EXPECT_EQ((*run)["rejected_poses"].get<std::size_t>(), 0u) << "a working chain never has a pose refused as implausible";
    // The converged reference is a minimum the budgeted result does not undercut.
    for (const auto& f : (*run)["reference"]) EXPECT_GE(f["energy"].get<double>(), f["energy_converged"].get<double>() * (1 - 1e-6));
    for (const auto& f : (*run)["reference"]) {
      // Where the worst vertex is: the rig marker nearest it at rest, and that region's share of the error.
      EXPECT_TRUE(f["worst_near"].is_string());
      EXPECT_GE(f["worst_region_share"].get<double>(), 0.0);
      EXPECT_LE(f["worst_region_share"].get<double>(), 1.0);
      EXPECT_GT(f["reference_iterations"].get<double>(), 0.0);
      EXPECT_LE(f["inverted_body_tets"].get<int>(), (*run)["inverted_body_tets_max"].get<int>());
      EXPECT_LE(f["inverted_body_tets_converged"].get<int>(), (*run)["inverted_body_tets_converged_max"].get<int>());
      // A reference frame's volume changes are within the run's largest, and a real pose changes it.
      EXPECT_LE(std::abs(f["volume_change"].get<double>()), (*run)["volume_change_max"].get<double>());
      EXPECT_LE(std::abs(f["volume_change_converged"].get<double>()), (*run)["volume_change_converged_max"].get<double>());
    }
    // The percentiles are of |V/V_rest - 1| over every played frame: ordered, the max is the largest.
    const auto& vc = (*run)["volume_change"];
    EXPECT_EQ(vc["count"].get<std::size_t>(), (*run)["frames"].get<std::size_t>());
    EXPECT_GE(vc["median"].get<double>(), 0.0);
    EXPECT_LE(vc["median"].get<double>(), vc["p99"].get<double>());
    EXPECT_DOUBLE_EQ(vc["max"].get<double>(), (*run)["volume_change_max"].get<double>());
    EXPECT_GT(vc["max"].get<double>(), 0.0);
    // The reference converged (stopped by its tolerance, not its cap).
    EXPECT_LT((*run)["reference_iterations"]["max"].get<double>(), 3000);
  }
  const Rig rig = loadRigFile(*rig_);
  for (const auto* run : {&one, &five}) {
    checkRegions(rig, *run);
    checkAnyFrame(rig, *run, 0);
  }
  EXPECT_LT(five["rms_error_mm"]["median"].get<double>(), one["rms_error_mm"]["median"].get<double>());
  EXPECT_LT(five["energy_excess"]["median"].get<double>(), one["energy_excess"]["median"].get<double>());
  EXPECT_GT(one["rms_error_mm"]["median"].get<double>(), 0.0);
}

// A run started mid-clip jumps from rest on its first frame: one iteration there (frame 1600 of
// HDM05, arms swung far from the T-pose) inverts tets at the forearms, and the regions name them.
TEST_F(FidelityTool, TheRegionsNameWhereTetsInvertAndVolumeIsLost) {
  const TempDir dir;
  const auto json = dir.path() / "f.json";
  const ToolRun r = fidelity("--rig '" + rig_->string() + "' --c3d '" + clip_->string() +
                                 "' --first-frame 1600 --frames 1 --iterations 1 -q --json '" + json.string() + "'",
                             dir);
  ASSERT_EQ(r.status, 0) << r.err;
  const nlohmann::json run = readJson(json)["runs"][0];
  ASSERT_GT(run["reference"][0]["inverted_body_tets"].get<int>(), 0) << "the jump must invert tets for the test to mean anything";
  const Rig rig = loadRigFile(*rig_);
  EXPECT_GT(checkRegions(rig, run), 0);
  // The one frame's inverted tets are the whole list, each in that frame, its det F the volume ratio.
  const nlohmann::json any = checkAnyFrame(rig, run, 1600);
  const auto& listed = run["reference"][0]["regions"]["budgeted"]["inverted_tets"];
  ASSERT_EQ(any.size(), listed.size());
  for (std::size_t i = 0; i < any.size(); ++i) {
    EXPECT_EQ(any[i]["tet"], listed[i]["tet"]);
    EXPECT_EQ(any[i]["frames"].get<std::size_t>(), 1u);
    EXPECT_EQ(any[i]["first_frame"].get<std::size_t>(), 1600u);
    EXPECT_NEAR(any[i]["lowest_volume_ratio"].get<double>(), listed[i]["volume_ratio"].get<double>(), 1e-9);
    EXPECT_EQ(any[i]["near"], listed[i]["near"]);
  }
}

// The feet turn with their markers. With a soft binding (invisible stiffness 0.1, 3 faces per
// marker, no rigid regions) the feet hang on soft invisible tets 5-10 cm long and do not: at frame
// 400 of HDM05 the right foot's best-fit rotation is 40 degrees from its three markers' (800-vertex
// rig, frames 0-400 at 3 iterations through the live rig). The builder's default binding (stiffness
// 10, 6 faces per marker) turns them within a few degrees, and feet driven as oriented regions by
// their markers (assets/human_man_feet.json) take the markers' fit exactly.
TEST_F(FidelityTool, FeetDrivenByTheirMarkersTurnWithThem) {
  const Rig feet = withAsset("human_man_feet.json");
  ASSERT_EQ(feet.marker_regions.size(), 2u);
  const Rig fitted = loadRigFile(*rig_);
  rigbuild::RigDescription soft_description;
  soft_description.markers.invisible_stiffness = 0.1;
  soft_description.markers.faces_per_marker = 3;
  soft_description.markers.rigid_regions = false;
  const Rig soft = withDescription(soft_description);
  const auto clip = drivers::C3DClip::load(*clip_);
  drivers::C3DPlaybackOptions options;
  options.pacing = drivers::Pacing::kAsFastAsPossible;
  const drivers::C3DPlayback playback(clip, options);
  std::vector<std::string> labels(static_cast<std::size_t>(clip.pointCount()));
  for (const int p : playback.selectedPoints()) labels[static_cast<std::size_t>(p)] = clip.labels()[static_cast<std::size_t>(p)];
  // Best-fit rotation from rest to current of a point set (Kabsch, via the closest rotation).
  const auto fit = [](const std::vector<Eigen::Vector3d>& rest, const std::vector<Eigen::Vector3d>& now) {
    return bestRigidFit(rest.size(), [&](std::size_t i) { return rest[i]; }, [&](std::size_t i) { return now[i]; }).rotation;
  };
  // The right foot's turn against its markers' at frame 400, in degrees.
  const auto foot_error_deg = [&](const Rig& rig) {
    LiveRig live(rig);
    live.bindLabels(labels);
    std::vector<float> x(static_cast<std::size_t>(live.fineVertexCount()) * 3);
    auto frame = std::make_unique<MarkerFrame>();
    for (std::size_t f = 0; f <= 400; ++f) {
      playback.fillFrame(f, f, *frame);
      live.processFrame(*frame, StepBudget{3}, x.data(), nullptr);
    }
    std::vector<Eigen::Vector3d> marker_rest, marker_now, foot_rest, foot_now;
    for (const char* label : {"RTOE", "RHEE", "RMT5"}) {
      for (std::size_t m = 0; m < rig.markers.size(); ++m) {
        if (rig.markers[m].label != label) continue;
        marker_rest.push_back(rig.markers[m].rest_position);
        marker_now.push_back(live.vertexTargets()[static_cast<std::size_t>(rig.markers[m].vertex_handle)]);
      }
    }
    EXPECT_EQ(marker_rest.size(), 3u);
    // The right foot: body vertices below 5 cm on the right side (the region's box).
    const std::span<const double> pos = live.deformer().positions();
    for (std::int32_t v = 0; v < rig.body_vertex_count; ++v) {
      const Eigen::Vector3d p = rig.tet_mesh.vertices.row(v).transpose();
      if (p.x() > 0.0 || p.y() > 0.05) continue;
      foot_rest.push_back(p);
      const std::size_t i = 3 * static_cast<std::size_t>(v);
      foot_now.emplace_back(pos[i], pos[i + 1], pos[i + 2]);
    }
    EXPECT_GT(foot_rest.size(), 20u);
    return fit(foot_rest, foot_now).angularDistance(fit(marker_rest, marker_now)) * 180.0 / M_PI;
  };
  const double soft_deg = foot_error_deg(soft), fitted_deg = foot_error_deg(fitted), feet_deg = foot_error_deg(feet);
  std::printf("frame 400, right foot against its markers: %.1f degrees with a soft binding, %.1f with the default one, %.1f driven\n",
              soft_deg, fitted_deg, feet_deg);
  EXPECT_GT(soft_deg, 30.0);
  EXPECT_LT(fitted_deg, 5.0);
  EXPECT_LT(feet_deg, 5.0);
}

// The skin a rigid marker group drives stops short of the next body part's markers, so the joint
// between them stays with the solve. HDM05's pelvis markers (LFWT RFWT LBWT RBWT) move as one rigid
// body; when their region reached the hip crease, the thigh folded against it in the squats and
// kneeling and the budgeted pose inverted tets there (near RTHI and RFWT, in some 260 frames of
// the first 3071). The rig build-rig builds by default (2505 tet vertices), the default settings,
// frames 0-3070.
TEST_F(FidelityTool, TheRigidPelvisLeavesTheHipCreaseToTheSolve) {
  const TempDir dir;
  const Rig rig = defaultRig();
  const std::string pelvis = "markers:LFWT+RFWT+LBWT+RBWT";
  const auto named = std::find(rig.region_handle_names.begin(), rig.region_handle_names.end(), pelvis);
  ASSERT_NE(named, rig.region_handle_names.end()) << "the pelvis markers drive no region";
  EXPECT_FALSE(rig.setup.region_handles[static_cast<std::size_t>(named - rig.region_handle_names.begin())].tets.empty());
  const auto rig_path = dir.writeBytes("default.rig", serializeRig(rig));
  const auto json = dir.path() / "squats.json";
  const ToolRun run = test::runCommand(TETRIG_FIDELITY_EXE,
                                       "--rig '" + rig_path.string() + "' --c3d '" + clip_->string() +
                                           "' --frames 3071 --reference-every 1000 --iterations 3 -q --json '" +
                                           json.string() + "'",
                                       dir.path());
  ASSERT_EQ(run.status, 0) << run.err;
  const nlohmann::json r = readJson(json)["runs"][0];
  const std::set<std::string> hip = {"LFWT", "RFWT", "LBWT", "RBWT", "LTHI", "RTHI"};
  int hip_frames = 0, other_frames = 0;
  for (const auto& tet : r["inverted_body_tets_any_frame"]) {
    (hip.count(tet["near"].get<std::string>()) ? hip_frames : other_frames) += tet["frames"].get<int>();
  }
  std::printf("HDM05 frames 0-3070, the default rig and settings: inverted body tets near the pelvis and thigh markers in %d "
              "frame-tets, elsewhere %d\n", hip_frames, other_frames);
  EXPECT_EQ(hip_frames, 0);
  EXPECT_LE(r["inverted_body_tets_max"].get<int>(), 1);
}

// Untangling the published pose (DeformerOptions::untangle, docs/deformation.md): after each frame's
// last iteration the corners of body tets nearly or wholly inside out are relaxed on the same
// energy. HDM05 frames 0-999 on the default rig with the default settings: a tet at the left armpit
// (near LUPA) is inside out in some 60 budgeted frames without it and a few with it;
// the converged reference is the same in both runs (it does not untangle; it starts from the budgeted
// pose, so it lands within its tolerance, not to the bit).
TEST_F(FidelityTool, UntanglingLeavesFewerInvertedTetsAndTheConvergedPoseAlone) {
  const TempDir dir;
  const auto rig_path = dir.writeBytes("default.rig", serializeRig(defaultRig()));
  const std::string args = "--rig '" + rig_path.string() + "' --c3d '" + clip_->string() +
                           "' --frames 1000 --reference-every 250 --iterations 3 -q ";
  const auto on = dir.path() / "on.json", off = dir.path() / "off.json";
  ASSERT_EQ(fidelity(args + "--json '" + on.string() + "'", dir, "defaults").status, 0);
  ASSERT_EQ(fidelity(args + "--no-untangle --json '" + off.string() + "'", dir, "defaults").status, 0);
  const nlohmann::json jon = readJson(on), joff = readJson(off);
  EXPECT_TRUE(jon["solver"]["untangle"].get<bool>());
  EXPECT_FALSE(joff["solver"]["untangle"].get<bool>());
  const auto frames = [](const nlohmann::json& j) { return j["runs"][0]["frames_with_inverted_body_tets"].get<int>(); };
  std::printf("HDM05 frames 0-999, the default rig and settings: frames with an inverted body tet %d untangled, %d not\n",
              frames(jon), frames(joff));
  ASSERT_GT(frames(joff), 20) << "the window must invert tets without untangling for the test to mean anything";
  EXPECT_LT(frames(jon), frames(joff) / 2);
  const nlohmann::json& ron = jon["runs"][0]["reference"];
  const nlohmann::json& roff = joff["runs"][0]["reference"];
  ASSERT_EQ(ron.size(), roff.size());
  ASSERT_GT(ron.size(), 2u);
  for (std::size_t i = 0; i < ron.size(); ++i) {
    const double e = roff[i]["energy_converged"].get<double>();
    EXPECT_NEAR(ron[i]["energy_converged"].get<double>(), e, 1e-6 * e) << "reference frame " << ron[i]["frame"];
    EXPECT_EQ(ron[i]["inverted_body_tets_converged"].get<int>(), roff[i]["inverted_body_tets_converged"].get<int>());
  }
}

// assets/human_man_fitted.json (docs/rig-format.md, "Volume"): its volume boxes hold the parts they name on this mesh and
// marker fit (each elbow marker in its elbow box, the sternum and the 10th thoracic vertebra in the
// torso box), the torso tets take 0.5 and the elbow tets 0.3, nothing else takes the term (not the
// knees since session 25: with --keep-volume the constraint keeps them, and their term only slowed
// the iteration there), and the binding is the stiff one it asks for (stiffness 1, up to 6 faces).
TEST_F(FidelityTool, TheFittedAssetPutsItsVolumeTermAtTheJoints) {
  const Rig rig = withAsset("human_man_fitted.json");
  const auto marker = [&](const char* label) {
    for (const RigMarker& m : rig.markers)
      if (m.label == label) return m.rest_position;
    ADD_FAILURE() << label << " is not a marker of the rig";
    return Eigen::Vector3d(0, 0, 0);
  };
  const double knee_height = std::min(marker("LKNE").y(), marker("RKNE").y());
  for (const char* elbow : {"LELB", "RELB"}) {
    EXPECT_GT(std::abs(marker(elbow).x()), 0.38) << elbow;
    EXPECT_LT(std::abs(marker(elbow).x()), 0.56) << elbow;
    EXPECT_GT(marker(elbow).y(), 1.1) << elbow;
    EXPECT_LT(marker(elbow).y(), 1.7) << elbow;
  }
  EXPECT_GT(marker("LELB").x(), 0.0);  // left is +x on this mesh, as the left_elbow box says
  for (const char* trunk : {"STRN", "T10"}) {
    EXPECT_LT(std::abs(marker(trunk).x()), 0.2) << trunk;
    EXPECT_GT(marker(trunk).y(), 0.95) << trunk;
    EXPECT_LT(marker(trunk).y(), 1.45) << trunk;
  }
  ASSERT_EQ(rig.setup.volume_weights.size(), static_cast<std::size_t>(rig.tet_mesh.tetCount()));
  int knees = 0, elbows = 0, torso = 0;
  double lowest = std::numeric_limits<double>::infinity();
  for (std::int32_t t = 0; t < rig.tet_mesh.tetCount(); ++t) {
    const double w = rig.setup.volume_weights[static_cast<std::size_t>(t)];
    if (w == 0.0) continue;
    ASSERT_LT(t, rig.body_tet_count) << "an invisible tet took the volume term";
    const Eigen::Vector3d c = restCentroid(rig, t);
    lowest = std::min(lowest, c.y());
    if (c.y() < 0.8) {
      ++knees;
    } else if (w == 0.5) {
      ++torso;
      EXPECT_TRUE(std::abs(c.x()) < 0.25 && c.y() > 0.9 && c.y() < 1.5) << "tet " << t;
    } else {
      ++elbows;
      EXPECT_EQ(w, 0.3);
      EXPECT_TRUE(std::abs(c.x()) > 0.33 && std::abs(c.x()) < 0.61 && c.y() > 1.05 && c.y() < 1.75) << "tet " << t;
    }
  }
  std::printf("fitted asset, 800 tet vertices: volume term on %d knee, %d elbow and %d torso tets of %d body tets; the lowest at "
              "height %.2f, the knee markers at %.2f\n",
              knees, elbows, torso, rig.body_tet_count, lowest, knee_height);
  EXPECT_EQ(knees, 0) << "no tet of the legs takes the term";
  EXPECT_GT(lowest, knee_height + 0.3);
  EXPECT_GT(elbows, 0);
  EXPECT_GT(torso, 0);
  EXPECT_LT(knees + elbows + torso, rig.body_tet_count / 2);
  for (std::int32_t t = rig.body_tet_count; t < rig.tet_mesh.tetCount(); ++t) {
    ASSERT_EQ(rig.setup.stiffness.empty() ? 1.0 : rig.setup.stiffness[static_cast<std::size_t>(t)], 1.0) << "invisible tet " << t;
  }
  int most_faces = 0;  // faces_per_marker 6 (the default binds 3)
  for (const RigMarker& m : rig.markers) most_faces = std::max(most_faces, m.bound_faces);
  EXPECT_EQ(most_faces, 6);
}

TEST_F(FidelityTool, TemporalPredictionLandsNearerThanThePlainWarmStart) {
  const TempDir dir;
  const auto plain = dir.path() / "plain.json", predicted = dir.path() / "predicted.json";
  ASSERT_EQ(fidelity(common() + "--iterations 3 --json '" + plain.string() + "'", dir).status, 0);
  ASSERT_EQ(fidelity(common() + "--iterations 3 --json '" + predicted.string() + "'", dir, "prediction").status, 0);
  const double p = readJson(plain)["runs"][0]["rms_error_mm"]["median"].get<double>();
  const double q = readJson(predicted)["runs"][0]["rms_error_mm"]["median"].get<double>();
  std::printf("SMPL (800 tet vertices) + HDM05, frames 0-239, 3 iterations: median body RMS error to converged %.2f mm plain, "
              "%.2f mm with the temporal prediction\n", p, q);
  EXPECT_LT(q, 0.5 * p);
}

// The coarse level (--coarse-rig: the same mesh and markers at 300 tet vertices) lands nearer the
// converged pose than the live default alone, and with the temporal prediction nearer still.
TEST_F(FidelityTool, TheCoarseLevelLandsNearerThanTheLiveDefault) {
  const TempDir dir;
  const auto plain = dir.path() / "plain.json", coarse = dir.path() / "coarse.json", both = dir.path() / "both.json";
  const std::string with_coarse = "--coarse-rig '" + coarse_->string() + "' ";
  ASSERT_EQ(fidelity(common() + "--iterations 3 --json '" + plain.string() + "'", dir).status, 0);
  const ToolRun rc = fidelity(common() + with_coarse + "--iterations 3 --json '" + coarse.string() + "'", dir);
  ASSERT_EQ(rc.status, 0) << rc.err;
  ASSERT_EQ(fidelity(common() + with_coarse + "--iterations 3 --json '" + both.string() + "'", dir, "prediction").status, 0);
  const nlohmann::json jc = readJson(coarse);
  EXPECT_EQ(jc["coarse_iterations"], tetrig::SolverSettings{}.coarse_iterations);
  EXPECT_GT(jc["coarse_tets"].get<int>(), 0);
  EXPECT_LT(jc["coarse_tets"].get<int>(), jc["tets"].get<int>() / 2);
  const auto median = [](const nlohmann::json& j) { return j["runs"][0]["rms_error_mm"]["median"].get<double>(); };
  const double p = median(readJson(plain)), c = median(jc), b = median(readJson(both));
  std::printf("SMPL (800 tet vertices) + HDM05, frames 0-239, 3 iterations: median body RMS error to converged %.2f mm (live "
              "default), %.2f mm with the coarse level, %.2f mm with the coarse level and the temporal prediction\n", p, c, b);
  EXPECT_LT(c, 0.6 * p);
  EXPECT_LT(b, c);
  // The same coarse level built into the rig (build-rig --coarse-tet-vertices) is used without
  // --coarse-rig, with the same result; --no-coarse turns it off.
  const auto embedded = dir.path() / "embedded.json", off = dir.path() / "off.json";
  const std::string rig_embedded = "--rig '" + embedded_->string() + "' --c3d '" + clip_->string() + "' --frames 240 --reference-every 20 -q ";
  ASSERT_EQ(fidelity(rig_embedded + "--iterations 3 --json '" + embedded.string() + "'", dir).status, 0);
  ASSERT_EQ(fidelity(rig_embedded + "--no-coarse --iterations 3 --json '" + off.string() + "'", dir).status, 0);
  const nlohmann::json je = readJson(embedded);
  EXPECT_EQ(je["coarse_rig"], "(the rig's own)");
  EXPECT_EQ(je["coarse_tets"], jc["coarse_tets"]);
  EXPECT_EQ(median(je), c);
  EXPECT_FALSE(readJson(off).contains("coarse_rig"));
  EXPECT_EQ(median(readJson(off)), p);
  // A coarse rig that is not there is refused.
  const ToolRun bad = fidelity(common() + "--coarse-rig '" + rig_->string() + "x' --iterations 3", dir);
  EXPECT_NE(bad.status, 0);
}

// --volume-weight gives the live rig and the reference the volume term (docs/deformation.md): the
// converged pose, and the budgeted one at a budget that nearly converges, keep more of the fine
// mesh's volume than without it; the JSON names the weight; a weight of 1 is refused. (Frames
// 400-459: the clip's first frames are the T-pose, where nothing loses volume.)
TEST_F(FidelityTool, TheVolumeTermKeepsTheVolume) {
  const TempDir dir;
  const auto plain = dir.path() / "plain.json", kept = dir.path() / "kept.json";
  const std::string args = "--rig '" + rig_->string() + "' --c3d '" + clip_->string() +
                           "' --first-frame 400 --frames 60 --reference-every 30 --max-reference-iterations 20000 --iterations 30 -q ";
  ASSERT_EQ(fidelity(args + "--json '" + plain.string() + "'", dir).status, 0);
  const ToolRun r = fidelity(args + "--volume-weight 0.9 --json '" + kept.string() + "'", dir);
  ASSERT_EQ(r.status, 0) << r.err;
  const nlohmann::json jp = readJson(plain), jk = readJson(kept);
  EXPECT_EQ(jp["solver"]["volume_weight"].get<double>(), 0.0);
  EXPECT_EQ(jk["solver"]["volume_weight"].get<double>(), 0.9);
  EXPECT_EQ(jk["solver"]["inversion_guard"].get<double>(), 0.0);
  const auto value = [](const nlohmann::json& j, const char* key) { return j["runs"][0][key].get<double>(); };
  const double plain_conv = value(jp, "volume_change_converged_max"), kept_conv = value(jk, "volume_change_converged_max");
  const double plain_budget = value(jp, "volume_change_max"), kept_budget = value(jk, "volume_change_max");
  std::printf("SMPL (800 tet vertices) + HDM05, frames 400-459, 30 iterations: fine volume change max %.2f %% budgeted, %.2f %% "
              "converged; with the volume term (w 0.9) %.2f %% and %.2f %%\n",
              100 * plain_budget, 100 * plain_conv, 100 * kept_budget, 100 * kept_conv);
  ASSERT_GT(plain_conv, 0.005) << "the rig must lose volume without the term for the test to mean anything";
  EXPECT_LT(kept_conv, 0.5 * plain_conv);
  EXPECT_LT(kept_budget, plain_budget);
  const ToolRun bad = fidelity(args + "--volume-weight 1", dir);
  EXPECT_NE(bad.status, 0);
  EXPECT_NE(bad.err.find("--volume-weight"), std::string::npos) << bad.err;
  const ToolRun bad_guard = fidelity(args + "--inversion-guard 2", dir);  // unstable beyond 1 (docs/deformation.md)
  EXPECT_NE(bad_guard.status, 0);
  EXPECT_NE(bad_guard.err.find("--inversion-guard must be in [0, 1] (above 1 only with --inversion-guard-solves"), std::string::npos)
      << bad_guard.err;
}

// --reference-guard-solves: the reference solves the same guarded energy with more conjugate-gradient
// steps than the live rig; it means nothing without the implicit guard, and is refused there.
TEST_F(FidelityTool, TheReferenceMaySolveTheImplicitGuardFurther) {
  const TempDir dir;
  const auto out = dir.path() / "ref.json", same = dir.path() / "same.json";
  const std::string args = common_all() + "--frames 3 --reference-every 2 --iterations 1 --inversion-guard 2 --inversion-guard-solves 1 ";
  const ToolRun r = fidelity(args + "--reference-guard-solves 3 --json '" + out.string() + "'", dir);
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_EQ(readJson(out)["solver"]["inversion_guard_solves"].get<int>(), 1);
  EXPECT_EQ(readJson(out)["reference_guard_solves"].get<int>(), 3);
  ASSERT_EQ(fidelity(args + "--json '" + same.string() + "'", dir).status, 0);
  EXPECT_EQ(readJson(same)["reference_guard_solves"].get<int>(), 4);  // by default
  const auto more = dir.path() / "more.json";
  ASSERT_EQ(fidelity(args + "--inversion-guard-solves 6 --json '" + more.string() + "'", dir).status, 0);
  EXPECT_EQ(readJson(more)["reference_guard_solves"].get<int>(), 6);  // never fewer than the live rig's
  const ToolRun explicit_guard = fidelity(common_all() + "--frames 3 --inversion-guard 1 --reference-guard-solves 3", dir);
  EXPECT_NE(explicit_guard.status, 0);
  EXPECT_NE(explicit_guard.err.find("--reference-guard-solves needs the implicit inversion guard"), std::string::npos)
      << explicit_guard.err;
  const ToolRun zero = fidelity(args + "--reference-guard-solves 0", dir);
  EXPECT_NE(zero.status, 0);
  EXPECT_NE(zero.err.find("--reference-guard-solves"), std::string::npos) << zero.err;
}

// The volume constraint (--keep-volume, the default; tetrig/volume_constraint.hpp): the live
// rig keeps the fine mesh's enclosed volume in every frame, and the reference converges to the
// constrained minimum. Frames 0-1700 of HDM05 (the arms swing down, the performer bends) on the
// 800-tet-vertex rig, 3 iterations: measured 4.2 % plain and 0.20 % with the constraint; converged
// 3.2 % and 0.00 %.
TEST_F(FidelityTool, TheVolumeConstraintKeepsTheFineVolumeInEveryFrame) {
  const TempDir dir;
  const auto plain = dir.path() / "plain.json", kept = dir.path() / "kept.json";
  const std::string args = common_all() + "--frames 1701 --reference-every 850 --iterations 3 ";
  ASSERT_EQ(fidelity(args + "--json '" + plain.string() + "'", dir).status, 0);
  const ToolRun r = fidelity(args + "--json '" + kept.string() + "'", dir, "volume");
  ASSERT_EQ(r.status, 0) << r.err;
  const nlohmann::json jp = readJson(plain), jk = readJson(kept);
  EXPECT_EQ(jp["solver"]["keep_volume"].get<bool>(), false);
  EXPECT_EQ(jk["solver"]["keep_volume"].get<bool>(), true);
  const auto value = [](const nlohmann::json& j, const char* key) { return j["runs"][0][key].get<double>(); };
  std::printf("HDM05 frames 0-1700, 800 tet vertices, 3 iterations: fine volume change max %.2f %% (converged %.2f %%) plain, "
              "%.2f %% (%.4f %%) with the constraint\n",
              100 * value(jp, "volume_change_max"), 100 * value(jp, "volume_change_converged_max"),
              100 * value(jk, "volume_change_max"), 100 * value(jk, "volume_change_converged_max"));
  ASSERT_GT(value(jp, "volume_change_max"), 0.02) << "the clip must lose volume without the constraint for the test to mean anything";
  EXPECT_LT(value(jk, "volume_change_max"), 0.005);  // every frame (the first is at rest)
  EXPECT_LT(value(jk, "volume_change_converged_max"), 1e-4);
  EXPECT_EQ(jk["runs"][0]["rejected_poses"].get<std::size_t>(), 0u);
}

// The constraint holds from the very first frame: a live rig that starts at rest and whose first
// frame is a deep pose (HDM05 frame 1600, the performer bent over) keeps the fine volume in that
// frame too, within #12's 1 % (measured: -6.5 % plain, +0.46 % with the constraint). Set only after
// a frame, it left that frame unconstrained (CMU 85_02's cold start lost 8 %; docs/fidelity.md);
// linearized at rest it gave +6.2 %, and once after the first iteration +2.6 %: a cold frame now
// linearizes it again before each iteration after the first.
TEST_F(FidelityTool, TheVolumeConstraintHoldsFromTheFirstFrame) {
  const TempDir dir;
  const auto plain = dir.path() / "plain.json", kept = dir.path() / "kept.json";
  const std::string args = common_all() + "--first-frame 1600 --frames 1 --iterations 3 ";
  ASSERT_EQ(fidelity(args + "--json '" + plain.string() + "'", dir).status, 0);
  const ToolRun r = fidelity(args + "--json '" + kept.string() + "'", dir, "volume");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto first = [](const std::filesystem::path& f) { return readJson(f)["runs"][0]["reference"][0]["volume_change"].get<double>(); };
  const double lost_plain = first(plain), lost_kept = first(kept);
  std::printf("HDM05 frame 1600 from rest, 800 tet vertices, 3 iterations: fine volume change %.2f %% plain, %.3f %% with the constraint\n",
              100 * lost_plain, 100 * lost_kept);
  ASSERT_GT(std::abs(lost_plain), 0.02) << "the jump must lose volume without the constraint for the test to mean anything";
  EXPECT_LT(std::abs(lost_kept), 0.01);
}

// A rig's own per-tet volume weights (the description's `volume`, section VOLW) reach both the live
// rig and the tool's exact energy: a rig whose every tet carries w 0.6 measures exactly as the plain
// rig with --volume-weight 0.6, reference frame by reference frame (if the exact energy ignored the
// rig's weights, its energies would be the plain ones).
TEST_F(FidelityTool, TheRigsOwnVolumeWeightsAreMeasured) {
  const TempDir dir;
  Rig weighted = loadRigFile(*rig_);
  weighted.setup.volume_weights.assign(static_cast<std::size_t>(weighted.tet_mesh.tetCount()), 0.6);
  const auto weighted_rig = dir.writeBytes("weighted.rig", serializeRig(weighted));
  const auto by_option = dir.path() / "option.json", by_rig = dir.path() / "rig.json", plain = dir.path() / "plain.json";
  const std::string args = "' --c3d '" + clip_->string() + "' --first-frame 400 --frames 40 --reference-every 20 --iterations 3 -q ";
  ASSERT_EQ(fidelity("--rig '" + rig_->string() + args + "--volume-weight 0.6 --json '" + by_option.string() + "'", dir).status, 0);
  ASSERT_EQ(fidelity("--rig '" + weighted_rig.string() + args + "--json '" + by_rig.string() + "'", dir).status, 0);
  ASSERT_EQ(fidelity("--rig '" + rig_->string() + args + "--json '" + plain.string() + "'", dir).status, 0);
  const nlohmann::json a = readJson(by_option)["runs"][0]["reference"];
  const nlohmann::json b = readJson(by_rig)["runs"][0]["reference"];
  const nlohmann::json p = readJson(plain)["runs"][0]["reference"];
  ASSERT_EQ(a.size(), 2u);
  ASSERT_EQ(b.size(), a.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    for (const char* key : {"energy", "energy_converged", "rms_mm", "volume_change"}) {
      EXPECT_EQ(a[i][key].get<double>(), b[i][key].get<double>()) << key << ", reference frame " << a[i]["frame"];
    }
    EXPECT_NE(p[i]["energy_converged"].get<double>(), b[i]["energy_converged"].get<double>());  // the term is there at all
  }
}

// The shipped asset keeps no volume term at the knees (session 25): with the volume kept by the
// constraint (--keep-volume), the knees' term (w 0.5 in a band at knee height, as the asset had it)
// only slows the iteration where the legs bend, and the chain lands farther from its converged pose.
// The asset's rig against the same rig with that band put back, the landing configuration with the
// constraint, HDM05's fast stretch (frames 2100-2300, every 20th frame). The guard of that finding
// (k 3 below 0.7); with the defaults' (k 4 below 0.6) the two land alike (RMS median 1.83 / 1.81 mm).
TEST_F(FidelityTool, WithTheVolumeKeptTheKneesLandNearerWithoutTheirTerm) {
  const TempDir dir;
  const Rig asset = withAsset("human_man_fitted.json");
  Rig knees = asset;
  knees.setup.volume_weights.resize(static_cast<std::size_t>(knees.tet_mesh.tetCount()), 0.0);
  int banded = 0;
  for (std::int32_t t = 0; t < knees.body_tet_count; ++t) {
    const double height = restCentroid(knees, t).y();
    if (height >= 0.30 && height <= 0.60) {
      knees.setup.volume_weights[static_cast<std::size_t>(t)] = 0.5;
      ++banded;
    }
  }
  ASSERT_GT(banded, 100);
  const auto asset_rig = dir.writeBytes("asset.rig", serializeRig(asset));
  const auto knees_rig = dir.writeBytes("knees.rig", serializeRig(knees));
  const std::string args = "' --c3d '" + clip_->string() +
                           "' --first-frame 2100 --frames 201 --reference-every 20 --iterations 3 -q --reference-guard-solves 1 "
                           "--inversion-guard 3 --inversion-guard-threshold 0.7 --json '";
  const auto a = dir.path() / "asset.json", k = dir.path() / "knees.json";
  ASSERT_EQ(fidelity("--rig '" + asset_rig.string() + args + a.string() + "'", dir, "defaults").status, 0);
  ASSERT_EQ(fidelity("--rig '" + knees_rig.string() + args + k.string() + "'", dir, "defaults").status, 0);
  const nlohmann::json ja = readJson(a)["runs"][0], jk = readJson(k)["runs"][0];
  const auto q = [](const nlohmann::json& r, const char* key, const char* p) { return r[key][p].get<double>(); };
  std::printf("HDM05 frames 2100-2300, 800 tet vertices, the volume kept: RMS median %.2f mm, worst median %.2f mm without the knees' "
              "term, %.2f and %.2f mm with it\n",
              q(ja, "rms_error_mm", "median"), q(ja, "max_error_mm", "median"), q(jk, "rms_error_mm", "median"),
              q(jk, "max_error_mm", "median"));
  EXPECT_LT(q(ja, "rms_error_mm", "median"), 0.85 * q(jk, "rms_error_mm", "median"));
  EXPECT_LT(q(ja, "max_error_mm", "median"), 0.85 * q(jk, "max_error_mm", "median"));
  EXPECT_LT(ja["volume_change_max"].get<double>(), 0.01);
}

TEST_F(FidelityTool, BadArgumentsExitNonZeroWithOneLine) {
  const TempDir dir;
  const ToolRun r = fidelity(common() + "--iterations 0,3", dir);
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.err.find("--iterations"), std::string::npos) << r.err;
  const ToolRun missing = fidelity("--rig /nonexistent.rig --c3d /nonexistent.c3d", dir);
  EXPECT_NE(missing.status, 0);
  EXPECT_NE(missing.err.find("nonexistent"), std::string::npos) << missing.err;
}

}  // namespace
}  // namespace tetrig
