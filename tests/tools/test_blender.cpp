// The Blender add-on (tools/blender/tetrig_live.py) in Debian's headless Blender, driven by the
// scripts in tests/tools/blender/:
//  - a C++ producer (ShmPublisher) publishes known frames of the small rig's fine mesh while
//    Blender's add-on follows the segment: every frame the object showed holds exactly the
//    positions published under that frame id (read back from Blender's mesh and evaluated mesh),
//    ids only grow, and the object's triangles are the segment's;
//  - `tetrig run` (synthetic source on the small rig) publishes while Blender follows it and a C++
//    reader (tetrig_shm.h) records every frame it sees: each frame Blender showed equals the frame
//    of that id as the C reader read it;
//  - a `tetrig export` PC2 imported through the add-on (OBJ + Mesh Cache modifier) reproduces the
//    exported samples at several scene frames (evaluated depsgraph mesh), with scene frame = clip
//    frame and the scene rate set from the export;
//  - exports of a rig built from a UV-mapped OBJ (uv_box_asset.hpp): Blender's glTF importer and
//    its OBJ importer (the PC2's rest mesh) show the asset's texture coordinates on every polygon
//    loop, its materials and its texture file, and the PC2 still plays on the textured rest mesh.
// Blender: $TETRIG_BLENDER or `blender` on PATH. Missing, the tests are skipped with a message,
// and fail under CI=true (CI installs it: apt-get install blender python3-numpy).
#include "export.hpp"
#include "moving_clip.hpp"
#include "small_rig.hpp"
#include "uv_box_asset.hpp"
#include "tetrig/live_rig.hpp"
#include "tetrig/shm_publisher.hpp"
#include "tetrig_shm.h"
#include "test_data.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <thread>

extern char** environ;

namespace tetrig {
namespace {

using test::TempDir;

std::optional<std::filesystem::path> findBlender() {
  if (const char* env = std::getenv("TETRIG_BLENDER"); env != nullptr && env[0] != '\0') {
    if (access(env, X_OK) == 0) return std::filesystem::path(env);
    return std::nullopt;
  }
  const char* path = std::getenv("PATH");
  std::string dirs = path ? path : "/usr/bin:/bin";
  std::size_t start = 0;
  while (start <= dirs.size()) {
    const std::size_t end = std::min(dirs.find(':', start), dirs.size());
    const std::filesystem::path candidate = std::filesystem::path(dirs.substr(start, end - start)) / "blender";
    if (access(candidate.c_str(), X_OK) == 0) return candidate;
    start = end + 1;
  }
  return std::nullopt;
}

#define TETRIG_REQUIRE_BLENDER(var)                                                                         \
  const std::optional<std::filesystem::path> var = findBlender();                                          \
  if (!var) {                                                                                               \
    if (::tetrig::test::runningInCi()) FAIL() << "blender not found in CI (apt-get install blender python3-numpy)"; \
    GTEST_SKIP() << "blender not found ($TETRIG_BLENDER, else PATH): apt-get install blender python3-numpy, or set TETRIG_BLENDER"; \
  }

const std::filesystem::path kAddonDir = std::filesystem::path(TETRIG_SOURCE_DIR) / "tools" / "blender";
const std::filesystem::path kScripts = std::filesystem::path(TETRIG_SOURCE_DIR) / "tests" / "tools" / "blender";

struct Child {
  pid_t pid = -1;
};

// Starts argv[0] with stdout and stderr into `log`, the environment plus `extra_env` ("K=V").
Child spawn(const std::vector<std::string>& args, const std::filesystem::path& log, const std::vector<std::string>& extra_env = {}) {
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, STDOUT_FILENO, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&fa, STDOUT_FILENO, STDERR_FILENO);
  std::vector<char*> argv;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  std::vector<char*> env;
  for (char** e = environ; *e != nullptr; ++e) env.push_back(*e);
  for (const std::string& e : extra_env) env.push_back(const_cast<char*>(e.c_str()));
  env.push_back(nullptr);
  Child c;
  const int rc = posix_spawn(&c.pid, argv[0], &fa, nullptr, argv.data(), env.data());
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) c.pid = -1;
  return c;
}

// Waits up to `timeout` for the child (killed after it); returns its exit status, -1 otherwise.
int wait(Child c, std::chrono::seconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  int status = 0;
  while (std::chrono::steady_clock::now() < end) {
    const pid_t r = waitpid(c.pid, &status, WNOHANG);
    if (r == c.pid) return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  kill(c.pid, SIGKILL);
  waitpid(c.pid, &status, 0);
  return -1;
}

std::string slurpText(const std::filesystem::path& p) {
  std::ifstream in(p);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// Blender with one of the check scripts; returns (exit status, log).
std::pair<int, std::string> runBlender(const std::filesystem::path& blender, const std::string& script, const std::vector<std::string>& args,
                                       const TempDir& dir, const std::vector<std::string>& extra_env = {}) {
  std::vector<std::string> argv = {blender.string(), "-b", "--factory-startup", "--python-exit-code", "1",
                                   "--python", (kScripts / script).string(), "--"};
  argv.insert(argv.end(), args.begin(), args.end());
  const std::filesystem::path log = dir.path() / (script + ".log");
  const Child c = spawn(argv, log, extra_env);
  EXPECT_GT(c.pid, 0) << "cannot start " << blender;
  const int status = c.pid > 0 ? wait(c, std::chrono::seconds(120)) : -1;
  return {status, slurpText(log)};
}

struct DumpFrame {
  std::uint64_t instance = 0, frame = 0;
  std::vector<float> positions;
};

// tetrig-shm-cat's --dump layout (docs/shm.md, section 7).
std::vector<DumpFrame> readDump(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::vector<DumpFrame> out;
  char magic[8] = {};
  in.read(magic, 8);
  EXPECT_EQ(std::string(magic, 8), "TSHMDMP1");
  while (true) {
    DumpFrame f;
    std::uint32_t count = 0, zero = 1;
    in.read(reinterpret_cast<char*>(&f.instance), 8);
    in.read(reinterpret_cast<char*>(&f.frame), 8);
    in.read(reinterpret_cast<char*>(&count), 4);
    in.read(reinterpret_cast<char*>(&zero), 4);
    if (!in) break;
    EXPECT_EQ(zero, 0u);
    f.positions.resize(std::size_t{count} * 3);
    in.read(reinterpret_cast<char*>(f.positions.data()), static_cast<std::streamsize>(f.positions.size() * 4));
    if (!in) {
      ADD_FAILURE() << "truncated dump " << p;
      break;
    }
    out.push_back(std::move(f));
  }
  return out;
}

std::vector<std::int32_t> readTris(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::vector<std::int32_t> t(std::filesystem::file_size(p) / 4);
  in.read(reinterpret_cast<char*>(t.data()), static_cast<std::streamsize>(t.size() * 4));
  return t;
}

// The small rig and the moving clip, built once per binary (the directory is removed at exit).
struct Scene {
  Scene() : rig(test::buildSmallRig(dir)) {
    rig_path = dir.writeBytes("small.rig", serializeRig(rig));
    clip_path = dir.writeBytes("moving.c3d", test::movingClip());
    const LiveRig live(rig);
    rest.assign(live.restPositions().begin(), live.restPositions().end());
    triangles.assign(live.fineTriangles().begin(), live.fineTriangles().end());
  }
  TempDir dir;
  Rig rig;
  std::filesystem::path rig_path, clip_path;
  std::vector<float> rest;
  std::vector<std::int32_t> triangles;
};
const Scene& scene() {
  static const Scene s;
  return s;
}

// Frame `id` of the C++ producer: the rest pose with every vertex moved by its own wave.
void producerFrame(std::uint64_t id, std::span<const float> rest, float* out) {
  for (std::size_t i = 0; i < rest.size(); ++i)
    out[i] = rest[i] + 0.02f * std::sin(0.05f * static_cast<float>(id) + 0.3f * static_cast<float>(i));
}

std::string segmentName(const char* what) { return "tetrig-blender-" + std::string(what) + "-" + std::to_string(getpid()); }

// The add-on's two copy paths: numpy (np.frombuffer + foreach_set) and array.array (no numpy).
class BlenderCopyPath : public ::testing::TestWithParam<bool> {};

TEST_P(BlenderCopyPath, LiveObjectHoldsEachPublishedFrame) {
  TETRIG_REQUIRE_BLENDER(blender);
  const bool numpy = GetParam();
  const Scene& sc = scene();
  const TempDir dir;
  const std::string name = segmentName(numpy ? "live-np" : "live-array");
  const std::vector<std::string> labels = {"TOP"};
  ShmPublisher pub({.name = "/" + name}, static_cast<std::int32_t>(sc.rest.size() / 3),
                   {sc.triangles, sc.rest, "small block", labels});
  std::atomic<bool> stop{false};
  std::thread producer([&] {
    while (!stop.load()) {
      producerFrame(pub.framesPublished() + 1, sc.rest, pub.beginPositions());
      ShmFrameInfo info;
      info.source_frame = pub.framesPublished() + 1;
      (void)pub.commit(info);
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  });
  const auto out = dir.path() / "live.dump";
  const auto [status, log] = runBlender(*blender, "check_live.py", {kAddonDir.string(), name, "60", out.string(), "60"}, dir,
                                       {numpy ? "TETRIG_LIVE_NUMPY=1" : "TETRIG_LIVE_NUMPY=0"});
  stop = true;
  producer.join();
  ASSERT_EQ(status, 0) << log;
  const auto frames = readDump(out);
  ASSERT_GE(frames.size(), 60u) << log;
  std::vector<float> expected(sc.rest.size());
  std::uint64_t previous = 0;
  for (const DumpFrame& f : frames) {
    EXPECT_EQ(f.instance, pub.instanceId());
    EXPECT_GT(f.frame, previous);  // ids never go back
    previous = f.frame;
    producerFrame(f.frame, sc.rest, expected.data());
    EXPECT_EQ(f.positions, expected) << "frame " << f.frame;
  }
  EXPECT_EQ(readTris(out.string() + ".tris"), sc.triangles);
  std::printf("%s", log.substr(log.find("check_live:")).c_str());
}

INSTANTIATE_TEST_SUITE_P(Blender, BlenderCopyPath, ::testing::Values(true, false),
                         [](const ::testing::TestParamInfo<bool>& p) { return p.param ? std::string("numpy") : std::string("array"); });

TEST(Blender, LiveObjectFollowsTetrigRun) {
  TETRIG_REQUIRE_BLENDER(blender);
  const Scene& sc = scene();
  const TempDir dir;
  const std::string name = segmentName("run");
  const Child run = spawn({TETRIG_EXE, "run", "--rig", sc.rig_path.string(), "--source", "synthetic", "--rate", "120", "--publish", name,
                           "--no-mlock", "--quiet"},
                          dir.path() / "run.log");
  ASSERT_GT(run.pid, 0);
  // A C reader beside Blender: every frame it sees, by id.
  std::mutex mutex;
  std::map<std::uint64_t, std::vector<float>> seen;
  std::uint64_t instance = 0;
  std::atomic<bool> stop{false};
  std::thread reader([&] {
    TetrigShmReader r;
    const std::string shm = "/" + name;
    while (!stop.load() && tetrig_shm_open(&r, shm.c_str()) != TETRIG_SHM_OK) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    if (stop.load()) return;
    instance = r.instance_id;
    std::vector<float> x(std::size_t{tetrig_shm_vertex_count(&r)} * 3);
    while (!stop.load()) {
      TetrigShmFrameInfo info;
      if (tetrig_shm_latest_frame_id(&r) > r.last_frame_id && tetrig_shm_read_latest(&r, x.data(), x.size(), nullptr, 0, &info) == TETRIG_SHM_OK) {
        const std::lock_guard<std::mutex> lock(mutex);
        seen[info.frame_id] = x;
      }
      std::this_thread::sleep_for(std::chrono::microseconds(100));
    }
    tetrig_shm_close(&r);
  });
  const auto out = dir.path() / "run.dump";
  const auto [status, log] = runBlender(*blender, "check_live.py", {kAddonDir.string(), name, "40", out.string(), "60"}, dir);
  stop = true;
  reader.join();
  kill(run.pid, SIGINT);
  EXPECT_EQ(wait(run, std::chrono::seconds(20)), 0) << slurpText(dir.path() / "run.log");
  ASSERT_EQ(status, 0) << log;
  const auto frames = readDump(out);
  ASSERT_GE(frames.size(), 40u);
  std::size_t compared = 0;
  for (const DumpFrame& f : frames) {
    EXPECT_EQ(f.instance, instance);
    const auto it = seen.find(f.frame);
    if (it == seen.end()) continue;  // published and replaced between two polls of the C reader
    ++compared;
    EXPECT_EQ(f.positions, it->second) << "frame " << f.frame;
  }
  // At 120 Hz the C reader (polling every 0.1 ms) sees nearly every frame.
  EXPECT_GE(compared, 30u) << "C reader saw " << seen.size() << " frames";
  // The synthetic source moves the mesh: Blender did not just hold the rest pose.
  double moved = 0;
  for (std::size_t i = 0; i < sc.rest.size(); ++i) moved = std::max(moved, std::abs(double{frames.back().positions[i]} - sc.rest[i]));
  EXPECT_GT(moved, 1e-4);
  EXPECT_EQ(readTris(out.string() + ".tris"), sc.triangles);
}

TEST(Blender, ExportedPc2PlaysThroughTheMeshCacheModifier) {
  TETRIG_REQUIRE_BLENDER(blender);
  const Scene& sc = scene();
  const TempDir dir;
  tools::ExportOptions o;
  o.rig_path = sc.rig_path;
  o.clip_path = sc.clip_path;
  o.out = dir.path() / "walk.pc2";
  o.frames = "2:10";  // start frame 2: scene frame = clip frame
  o.quiet = true;
  (void)tools::exportClip(o);
  // The samples as written (PC2: 32-byte header, then float32 xyz per point per sample).
  std::ifstream in(o.out, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), {});
  const std::size_t values = sc.rest.size();
  ASSERT_EQ(bytes.size(), 32 + 8 * values * 4);
  auto sample = [&](std::size_t k) {
    std::vector<float> v(values);
    std::memcpy(v.data(), bytes.data() + 32 + k * values * 4, values * 4);
    return v;
  };
  const auto out = dir.path() / "pc2.dump";
  const auto [status, log] = runBlender(*blender, "check_pc2.py", {kAddonDir.string(), o.out.string(), "2,3,6,9", out.string()}, dir);
  ASSERT_EQ(status, 0) << log;
  const auto frames = readDump(out);
  ASSERT_EQ(frames.size(), 4u) << log;
  for (const DumpFrame& f : frames) {
    ASSERT_GE(f.frame, 2u);
    EXPECT_EQ(f.positions, sample(f.frame - 2)) << "scene frame " << f.frame;
  }
  EXPECT_NE(frames[0].positions, frames[3].positions);  // the cache animates
  const auto settings = nlohmann::json::parse(slurpText(out.string() + ".json"));
  EXPECT_EQ(settings["modifier"], "MESH_CACHE");
  EXPECT_EQ(settings["cache_format"], "PC2");
  EXPECT_EQ(settings["frame_start"], 2.0);
  EXPECT_EQ(settings["scene_frame_start"], 2);
  EXPECT_EQ(settings["scene_frame_end"], 9);
  EXPECT_EQ(settings["fps"], 100);
  EXPECT_EQ(settings["fps_base"], 1.0);
  EXPECT_NEAR(settings["rotation_x"].get<double>(), M_PI / 2, 1e-6);  // the Y-up rig stands on Blender's floor
  EXPECT_EQ(settings["vertices"], values / 3);
}

// ---- the asset's texture coordinates and materials (uv_box_asset.hpp) ----

struct UvScene {
  UvScene() : asset(test::writeUvBoxAsset(asset_dir)), rig(test::buildUvBoxRig(dir, asset)) {
    rig_path = dir.writeBytes("uv.rig", serializeRig(rig));
  }
  TempDir asset_dir, dir;
  test::UvBoxAsset asset;
  Rig rig;
  std::filesystem::path rig_path;
};
const UvScene& uvScene() {
  static const UvScene s;
  return s;
}

// The polygons Blender shows (check_*.py's "surface"): each a triangle on one face of the asset
// (its vertices found by position, `to_rig` taking Blender's basis coordinates to the rig's), each
// loop's uv the asset's vt of that face at that vertex (within float rounding), the polygon's
// material the face's; every quad covered by two triangles; the textured material's image is the
// asset's texture file. With `same_order` a loop's vertex index is the asset's vertex index.
void expectTheAssetsUvs(const nlohmann::json& surface, const test::UvBoxAsset& asset,
                        const std::function<std::array<double, 3>(double, double, double)>& to_rig, bool same_order) {
  EXPECT_EQ(surface["uv_layers"], 1);
  const auto& polygons = surface["polygons"];
  ASSERT_EQ(polygons.size(), 2 * asset.faces.size());
  std::vector<int> covered(asset.faces.size(), 0);
  double worst = 0;
  for (const auto& polygon : polygons) {
    const auto& loops = polygon["loops"];
    ASSERT_EQ(loops.size(), 3u);
    std::array<int, 3> v{-1, -1, -1};
    for (std::size_t k = 0; k < 3; ++k) {
      const auto p = to_rig(loops[k][1].get<double>(), loops[k][2].get<double>(), loops[k][3].get<double>());
      for (std::size_t i = 0; i < asset.vertices.size(); ++i) {
        const double d = std::abs(p[0] - asset.vertices[i][0]) + std::abs(p[1] - asset.vertices[i][1]) + std::abs(p[2] - asset.vertices[i][2]);
        if (d < 1e-6) v[k] = static_cast<int>(i);
      }
      ASSERT_GE(v[k], 0) << "a loop at no vertex of the asset";
      if (same_order) {
        EXPECT_EQ(loops[k][0].get<int>(), v[k]);
      }
    }
    int face = -1;
    for (std::size_t f = 0; f < asset.faces.size() && face < 0; ++f) {
      int found = 0;
      for (const int x : v)
        for (const auto& corner : asset.faces[f]) found += corner[0] == x ? 1 : 0;
      if (found == 3) face = static_cast<int>(f);
    }
    ASSERT_GE(face, 0) << "a polygon on no face of the asset";
    ++covered[static_cast<std::size_t>(face)];
    EXPECT_EQ(polygon["material"], asset.face_materials[static_cast<std::size_t>(face)]);
    for (std::size_t k = 0; k < 3; ++k) {
      for (const auto& corner : asset.faces[static_cast<std::size_t>(face)]) {
        if (corner[0] != v[k]) continue;
        const auto& uv = asset.uvs[static_cast<std::size_t>(corner[1])];
        worst = std::max({worst, std::abs(loops[k][4].get<double>() - uv[0]), std::abs(loops[k][5].get<double>() - uv[1])});
      }
    }
  }
  EXPECT_LT(worst, 1e-6);  // float uvs (glTF: 1 - (1 - v) in float)
  EXPECT_EQ(covered, std::vector<int>(asset.faces.size(), 2));
  ASSERT_TRUE(surface["images"].contains("skin")) << surface["images"].dump();
  ASSERT_EQ(surface["images"]["skin"].size(), 1u) << surface["images"].dump();
  EXPECT_EQ(std::filesystem::weakly_canonical(surface["images"]["skin"][0].get<std::string>()), std::filesystem::weakly_canonical(asset.texture));
}

// The glTF export of the UV rig through Blender's glTF importer (the add-on's import): one object
// with the asset's uvs on every loop, its two materials and the texture, and a shape key per frame.
TEST(BlenderUv, GltfImporterShowsTheAssetsTextureCoordinates) {
  TETRIG_REQUIRE_BLENDER(blender);
  const UvScene& uv = uvScene();
  const TempDir dir;
  tools::ExportOptions o;
  o.rig_path = uv.rig_path;
  o.clip_path = scene().clip_path;
  o.iterations = 3;
  o.quiet = true;
  o.out = dir.path() / "walk.glb";
  (void)tools::exportClip(o);
  const auto out = dir.path() / "gltf.dump";
  const auto [status, log] = runBlender(*blender, "check_gltf.py", {kAddonDir.string(), o.out.string(), "0,5", out.string()}, dir);
  ASSERT_EQ(status, 0) << log;
  const auto settings = nlohmann::json::parse(slurpText(out.string() + ".json"));
  EXPECT_EQ(settings["shape_keys"], 13);
  // glTF's +Y up became Blender's +Z up: (x, y, z)_glTF = (x, z, -y)_Blender; the rig is Y up.
  expectTheAssetsUvs(settings["surface"], uv.asset, [](double x, double y, double z) { return std::array<double, 3>{x, z, -y}; }, false);
}

// The PC2 export of the UV rig: its rest OBJ (mtllib, vt, usemtl, f v/vt) through Blender's OBJ
// importer keeps the vertex order, so the Mesh Cache plays the samples exactly, and shows the
// asset's uvs, materials and texture.
TEST(BlenderUv, Pc2OnTheTexturedRestObjStillPlays) {
  TETRIG_REQUIRE_BLENDER(blender);
  const UvScene& uv = uvScene();
  const TempDir dir;
  tools::ExportOptions o;
  o.rig_path = uv.rig_path;
  o.clip_path = scene().clip_path;
  o.out = dir.path() / "walk.pc2";
  o.frames = "2:10";
  o.iterations = 3;
  o.quiet = true;
  (void)tools::exportClip(o);
  std::ifstream in(o.out, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), {});
  const std::size_t values = uv.asset.vertices.size() * 3;
  ASSERT_EQ(bytes.size(), 32 + 8 * values * 4);
  const auto out = dir.path() / "pc2.dump";
  const auto [status, log] = runBlender(*blender, "check_pc2.py", {kAddonDir.string(), o.out.string(), "2,6,9", out.string()}, dir);
  ASSERT_EQ(status, 0) << log;
  const auto frames = readDump(out);
  ASSERT_EQ(frames.size(), 3u) << log;
  for (const DumpFrame& f : frames) {
    std::vector<float> sample(values);
    std::memcpy(sample.data(), bytes.data() + 32 + (f.frame - 2) * values * 4, values * 4);
    EXPECT_EQ(f.positions, sample) << "scene frame " << f.frame;
  }
  const auto settings = nlohmann::json::parse(slurpText(out.string() + ".json"));
  expectTheAssetsUvs(settings["surface"], uv.asset, [](double x, double y, double z) { return std::array<double, 3>{x, y, z}; }, true);
}

// A glTF export through Blender's own glTF importer (called by the add-on, which sets the scene
// rate from the export first): one object, one shape key per frame plus the basis, and at scene
// frame k the evaluated mesh is frame k of the export (glTF's Y-up turned into Blender's Z-up by
// the importer: (x, y, z) -> (x, -z, y)).
class BlenderGltf : public ::testing::TestWithParam<const char*> {};

TEST_P(BlenderGltf, ImportedShapeKeysPlayTheFrames) {
  TETRIG_REQUIRE_BLENDER(blender);
  const Scene& sc = scene();
  const TempDir dir;
  tools::ExportOptions o;
  o.rig_path = sc.rig_path;
  o.clip_path = sc.clip_path;
  o.iterations = 3;
  o.quiet = true;
  o.out = dir.path() / "walk.pc2";
  (void)tools::exportClip(o);
  o.out = dir.path() / (std::string("walk.") + GetParam());
  (void)tools::exportClip(o);
  std::ifstream in(dir.path() / "walk.pc2", std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), {});
  const std::size_t values = sc.rest.size();
  auto sampleInBlender = [&](std::size_t k) {
    std::vector<float> v(values);
    std::memcpy(v.data(), bytes.data() + 32 + k * values * 4, values * 4);
    for (std::size_t i = 0; i < values; i += 3) {
      const float y = v[i + 1], z = v[i + 2];
      v[i + 1] = -z;
      v[i + 2] = y;
    }
    return v;
  };
  const auto out = dir.path() / "gltf.dump";
  const auto [status, log] = runBlender(*blender, "check_gltf.py", {kAddonDir.string(), o.out.string(), "0,3,7,11", out.string()}, dir);
  ASSERT_EQ(status, 0) << log;
  const auto frames = readDump(out);
  ASSERT_EQ(frames.size(), 4u) << log;
  for (const DumpFrame& f : frames) {
    const std::vector<float> expected = sampleInBlender(f.frame);
    ASSERT_EQ(f.positions.size(), expected.size()) << "Blender's importer changed the vertex count";
    double worst = 0;
    for (std::size_t i = 0; i < values; ++i) worst = std::max(worst, std::abs(double{f.positions[i]} - expected[i]));
    EXPECT_LT(worst, 1e-6) << "scene frame " << f.frame;  // rest + (target - rest) in float
  }
  const auto settings = nlohmann::json::parse(slurpText(out.string() + ".json"));
  EXPECT_EQ(settings["shape_keys"], 13);  // basis + 12 frames
  EXPECT_EQ(settings["animated"], true);
  EXPECT_EQ(settings["fps"], 100);
  EXPECT_EQ(settings["scene_frame_start"], 0);
  EXPECT_EQ(settings["scene_frame_end"], 11);
}

INSTANTIATE_TEST_SUITE_P(Blender, BlenderGltf, ::testing::Values("glb", "gltf"),
                         [](const ::testing::TestParamInfo<const char*>& p) { return std::string(p.param); });

}  // namespace
}  // namespace tetrig
