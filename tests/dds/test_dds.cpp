// Frames over Cyclone DDS (docs/dds.md), across processes and over loopback only: `tetrig run
// --dds` publishes, tetrig-dds-cat subscribes, tetrig-shm-cat reads the same run's segment. Every
// test writes its own Cyclone configuration (dds/config/loopback.xml with its own domain id: the
// lo interface, no multicast, the peer 127.0.0.1) into CYCLONEDDS_URI, which the children inherit.
#include "find_on_path.hpp"
#include "run_command.hpp"
#include "shm_dump.hpp"
#include "../tools/small_rig.hpp"
#include "temp_dir.hpp"
#include "test_data.hpp"
#include "tetrig/dds/frame_publisher.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig_shm.h"

#include <gtest/gtest.h>

#include <signal.h>
#include <spawn.h>
#include <sys/mman.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace {

using tetrig::test::TempDir;
using Clock = std::chrono::steady_clock;

std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Points CYCLONEDDS_URI at a copy of dds/config/loopback.xml whose domain is `domain` (each test
// its own, so that tests running at once never share discovery traffic).
void useLoopbackDomain(const TempDir& dir, int domain) {
  std::string xml = slurp(std::filesystem::path(TETRIG_SOURCE_DIR) / "dds/config/loopback.xml");
  const std::string any = "Id=\"any\"";
  const auto at = xml.find(any);
  ASSERT_NE(at, std::string::npos);
  xml.replace(at, any.size(), "Id=\"" + std::to_string(domain) + "\"");
  const auto path = dir.write("cyclonedds.xml", xml);
  setenv("CYCLONEDDS_URI", ("file://" + path.string()).c_str(), 1);
}

// `exec`s the shell command line (so the pid is the program's), stdout and stderr into files.
pid_t spawn(const std::string& command) {
  const std::string line = "exec " + command;
  std::vector<char*> argv = {const_cast<char*>("/bin/sh"), const_cast<char*>("-c"), const_cast<char*>(line.c_str()), nullptr};
  pid_t pid = -1;
  if (posix_spawn(&pid, "/bin/sh", nullptr, nullptr, argv.data(), environ) != 0) return -1;
  return pid;
}

// The exit status of `pid` within `timeout` (-2: still running, then killed; -1: killed by a signal).
int waitExit(pid_t pid, std::chrono::milliseconds timeout) {
  const auto end = Clock::now() + timeout;
  int status = 0;
  while (Clock::now() < end) {
    const pid_t r = waitpid(pid, &status, WNOHANG);
    if (r == pid) return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  kill(pid, SIGKILL);
  waitpid(pid, &status, 0);
  return -2;
}

std::string q(const std::filesystem::path& p) { return "'" + p.string() + "'"; }

struct Files {
  std::filesystem::path out, err, dump;
};
Files files(const TempDir& dir, const std::string& tag) {
  return {dir.path() / (tag + ".out"), dir.path() / (tag + ".err"), dir.path() / (tag + ".dump")};
}

// tetrig-dds-cat NAME with `args`, output into files tagged `tag`.
pid_t startDdsCat(const std::string& name, const std::string& args, const Files& f) {
  return spawn(q(TETRIG_DDS_CAT_EXE) + " " + name + " --dump " + q(f.dump) + " " + args + " >" + q(f.out) + " 2>" + q(f.err));
}

std::vector<tetrig::test::DumpRecord> readDump(const std::filesystem::path& p) {
  bool ok = false;
  auto records = tetrig::test::parseDump(slurp(p), ok);
  EXPECT_TRUE(ok) << p;
  return records;
}

std::string smallRig(const TempDir& dir) {
  return dir.writeBytes("small.rig", tetrig::serializeRig(tetrig::test::buildSmallRig(dir))).string();
}

// `tetrig run` on the small rig, the synthetic source at 100 Hz (real time), segment + DDS.
std::string runArgs(const std::string& rig, const std::string& name, int frames) {
  return q(TETRIG_EXE) + " run --rig '" + rig + "' --source synthetic --rate 100 --frames " + std::to_string(frames) +
         " --publish " + name + " --dds --no-mlock -q";
}

// Waits until `path` holds `needle` (a child's output), at most `timeout`.
bool waitForText(const std::filesystem::path& path, const std::string& needle, std::chrono::milliseconds timeout) {
  const auto end = Clock::now() + timeout;
  while (Clock::now() < end) {
    if (slurp(path).find(needle) != std::string::npos) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return false;
}

// Each record's frame id strictly above the previous one's within one instance.
void expectIncreasingIds(const std::vector<tetrig::test::DumpRecord>& records) {
  for (std::size_t i = 1; i < records.size(); ++i)
    if (records[i].instance == records[i - 1].instance) {
      EXPECT_GT(records[i].frame_id, records[i - 1].frame_id) << "record " << i;
    }
}

// Every record of `dds` whose frame id `shm` also has holds exactly the segment's positions; returns how many matched.
std::size_t expectSamePositions(const std::vector<tetrig::test::DumpRecord>& dds, const std::vector<tetrig::test::DumpRecord>& shm) {
  std::map<std::pair<std::uint64_t, std::uint64_t>, const tetrig::test::DumpRecord*> by_id;
  for (const auto& r : shm) by_id[{r.instance, r.frame_id}] = &r;
  std::size_t matched = 0;
  for (const auto& r : dds) {
    const auto it = by_id.find({r.instance, r.frame_id});
    if (it == by_id.end()) continue;
    ++matched;
    EXPECT_EQ(r.positions.size(), it->second->positions.size()) << "frame " << r.frame_id;
    if (r.positions.size() != it->second->positions.size()) continue;
    EXPECT_EQ(std::memcmp(r.positions.data(), it->second->positions.data(), r.positions.size() * sizeof(float)), 0)
        << "frame " << r.frame_id << " differs from the segment's";
  }
  return matched;
}

// (a) A subscriber in another process gets the segment's frames, bit for bit, in order.
TEST(Dds, SubscriberGetsTheSegmentsFramesInOrder) {
  const TempDir dir("tetrig-dds");
  useLoopbackDomain(dir, 161);
  const std::string rig = smallRig(dir);
  const std::string name = "tetrig-dds-a-" + std::to_string(getpid());
  const Files shm = files(dir, "shm"), dds = files(dir, "dds");
  const pid_t shm_cat = spawn(q(TETRIG_SHM_CAT_EXE) + " " + name + " --quiet --timeout-ms 20000 --dump " + q(shm.dump) + " >" +
                              q(shm.out) + " 2>" + q(shm.err));
  const pid_t dds_cat = startDdsCat(name, "--quiet --timeout-ms 20000 --latency-json " + q(dir.path() / "lat.json"), dds);
  ASSERT_GT(shm_cat, 0);
  ASSERT_GT(dds_cat, 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the subscriber's participant is up
  const auto run = tetrig::test::runCommand(TETRIG_EXE, "run --rig '" + rig + "' --source synthetic --rate 100 --frames 150 --publish " + name +
                                                            " --dds --no-mlock --stats-json " + q(dir.path() / "stats.json"),
                                            dir.path());
  ASSERT_EQ(run.status, 0) << run.err;
  EXPECT_NE(run.out.find("publishing over DDS too: topics tetrig/" + tetrig::dds::topicBaseName(name) + "/frame"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("DDS (tetrig/"), std::string::npos) << run.out;
  EXPECT_EQ(waitExit(shm_cat, std::chrono::seconds(10)), 0) << slurp(shm.err);
  EXPECT_EQ(waitExit(dds_cat, std::chrono::seconds(10)), 0) << slurp(dds.err);
  const auto shm_records = readDump(shm.dump), dds_records = readDump(dds.dump);
  ASSERT_GE(shm_records.size(), 100u);
  ASSERT_GE(dds_records.size(), 100u) << slurp(dds.err);
  expectIncreasingIds(dds_records);
  for (const auto& r : dds_records) EXPECT_EQ(r.instance, shm_records.front().instance);
  EXPECT_GE(expectSamePositions(dds_records, shm_records), 100u);
  const std::string stats = slurp(dir.path() / "stats.json");
  EXPECT_NE(stats.find("\"dds\""), std::string::npos) << stats;
  EXPECT_NE(stats.find("\"write_errors\": 0"), std::string::npos) << stats;
  const std::string lat = slurp(dir.path() / "lat.json");
  EXPECT_NE(lat.find("\"frames_refused\": 0"), std::string::npos) << lat;
  EXPECT_NE(lat.find("\"frames_before_static\": 0"), std::string::npos) << lat;  // held until the static data came
  EXPECT_NE(lat.find("\"receive_to_seen\": {\"count\": " + std::to_string(dds_records.size())), std::string::npos) << lat;
}

// (b) A subscriber that starts after the static data was written still gets it (transient local).
TEST(Dds, LateSubscriberGetsTheStaticData) {
  const TempDir dir("tetrig-dds");
  useLoopbackDomain(dir, 162);
  const std::string rig = smallRig(dir);
  const std::string name = "tetrig-dds-b-" + std::to_string(getpid());
  const pid_t producer = spawn(runArgs(rig, name, 400) + " >" + q(dir.path() / "run.out") + " 2>" + q(dir.path() / "run.err"));
  ASSERT_GT(producer, 0);
  // The segment tells the rig's name and vertex count; the subscriber starts a second later.
  TetrigShmReader reader;
  const auto end = Clock::now() + std::chrono::seconds(10);
  int rc = TETRIG_SHM_E_NOT_FOUND;
  while (Clock::now() < end && (rc = tetrig_shm_open(&reader, ("/" + name).c_str())) != TETRIG_SHM_OK)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ASSERT_EQ(rc, TETRIG_SHM_OK) << slurp(dir.path() / "run.err");
  const std::uint32_t vertices = tetrig_shm_vertex_count(&reader);
  const std::string rig_name = tetrig_shm_rig_name(&reader);
  tetrig_shm_close(&reader);
  std::this_thread::sleep_for(std::chrono::seconds(1));
  const Files late = files(dir, "late");
  const pid_t cat = startDdsCat(name, "--frames 20 --quiet --timeout-ms 10000", late);
  EXPECT_EQ(waitExit(cat, std::chrono::seconds(15)), 0) << slurp(late.err);
  EXPECT_NE(slurp(late.err).find("static data: rig '" + rig_name + "', " + std::to_string(vertices) + " vertices"), std::string::npos)
      << slurp(late.err);
  const auto records = readDump(late.dump);
  EXPECT_EQ(records.size(), 20u);
  for (const auto& r : records) EXPECT_EQ(r.positions.size(), 3u * vertices);
  EXPECT_EQ(waitExit(producer, std::chrono::seconds(10)), 0) << slurp(dir.path() / "run.err");
}

// (c) A publisher killed with SIGKILL is reported lost within the liveliness lease (1 s) plus a margin.
TEST(Dds, KilledPublisherIsNoticedWithinTheLease) {
  const TempDir dir("tetrig-dds");
  useLoopbackDomain(dir, 163);
  const std::string rig = smallRig(dir);
  const std::string name = "tetrig-dds-c-" + std::to_string(getpid());
  const Files sub = files(dir, "sub");
  const pid_t cat = startDdsCat(name, "--timeout-ms 20000", sub);
  const pid_t producer = spawn(runArgs(rig, name, 0) + " >" + q(dir.path() / "run.out") + " 2>" + q(dir.path() / "run.err"));
  ASSERT_GT(producer, 0);
  ASSERT_TRUE(waitForText(sub.out, "frame 30 ", std::chrono::seconds(15))) << slurp(sub.err) << slurp(dir.path() / "run.err");
  const auto killed = Clock::now();
  kill(producer, SIGKILL);
  waitpid(producer, nullptr, 0);
  const int status = waitExit(cat, std::chrono::seconds(10));
  const double seconds = std::chrono::duration<double>(Clock::now() - killed).count();
  shm_unlink(("/" + name).c_str());  // a killed producer leaves its segment
  EXPECT_EQ(status, 3) << slurp(sub.err);
  EXPECT_NE(slurp(sub.err).find("publisher lost: no sign of it for the liveliness lease (1000 ms)"), std::string::npos) << slurp(sub.err);
  EXPECT_LT(seconds, 2.5) << "lost liveliness reported " << seconds << " s after SIGKILL";
  std::fprintf(stderr, "killed publisher reported lost after %.3f s\n", seconds);
}

// (d) A publisher that stops and starts again under the same name is picked up (--follow).
TEST(Dds, RestartedPublisherIsPickedUp) {
  const TempDir dir("tetrig-dds");
  useLoopbackDomain(dir, 164);
  const std::string rig = smallRig(dir);
  const std::string name = "tetrig-dds-d-" + std::to_string(getpid());
  const Files sub = files(dir, "sub");
  const pid_t cat = startDdsCat(name, "--follow --quiet --frames 70 --timeout-ms 20000", sub);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const auto first = tetrig::test::runCommand(TETRIG_EXE, "run --rig '" + rig + "' --source synthetic --rate 100 --frames 50 --publish " + name +
                                                              " --dds --no-mlock -q",
                                              dir.path());
  ASSERT_EQ(first.status, 0) << first.err;
  const pid_t second = spawn(runArgs(rig, name, 300) + " >" + q(dir.path() / "run.out") + " 2>" + q(dir.path() / "run.err"));
  EXPECT_EQ(waitExit(cat, std::chrono::seconds(20)), 0) << slurp(sub.err);
  kill(second, SIGINT);
  EXPECT_EQ(waitExit(second, std::chrono::seconds(10)), 0) << slurp(dir.path() / "run.err");
  const auto records = readDump(sub.dump);
  ASSERT_EQ(records.size(), 70u);
  std::set<std::uint64_t> instances;
  for (const auto& r : records) instances.insert(r.instance);
  EXPECT_EQ(instances.size(), 2u);
  expectIncreasingIds(records);
  EXPECT_NE(slurp(sub.err).find("publisher restarted: instance "), std::string::npos) << slurp(sub.err);
}

// (e) Four subscribers at once all get the frames, the same bits.
TEST(Dds, FourSubscribersAtOnce) {
  const TempDir dir("tetrig-dds");
  useLoopbackDomain(dir, 165);
  const std::string rig = smallRig(dir);
  const std::string name = "tetrig-dds-e-" + std::to_string(getpid());
  std::vector<Files> subs;
  std::vector<pid_t> cats;
  for (int k = 0; k < 4; ++k) {
    subs.push_back(files(dir, "sub" + std::to_string(k)));
    cats.push_back(startDdsCat(name, "--quiet --timeout-ms 20000", subs.back()));
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(400));
  const auto run = tetrig::test::runCommand(TETRIG_EXE, "run --rig '" + rig + "' --source synthetic --rate 100 --frames 120 --publish " + name +
                                                            " --dds --no-mlock -q",
                                            dir.path());
  ASSERT_EQ(run.status, 0) << run.err;
  std::vector<std::vector<tetrig::test::DumpRecord>> dumps;
  for (int k = 0; k < 4; ++k) {
    EXPECT_EQ(waitExit(cats[static_cast<std::size_t>(k)], std::chrono::seconds(10)), 0) << slurp(subs[static_cast<std::size_t>(k)].err);
    dumps.push_back(readDump(subs[static_cast<std::size_t>(k)].dump));
    EXPECT_GE(dumps.back().size(), 80u) << "subscriber " << k;
    expectIncreasingIds(dumps.back());
  }
  for (int k = 1; k < 4; ++k) EXPECT_GE(expectSamePositions(dumps[static_cast<std::size_t>(k)], dumps[0]), 60u) << "subscriber " << k;
}

// (f) Malformed samples written on the topic are refused with a clear line and counted; the good ones pass.
TEST(Dds, MalformedSamplesAreRefused) {
  const TempDir dir("tetrig-dds");
  useLoopbackDomain(dir, 166);
  const std::string name = "tetrig_dds_f_" + std::to_string(getpid());
  const Files sub = files(dir, "sub");
  const pid_t cat = startDdsCat(name, "--frames 3 --timeout-ms 15000 --latency-json " + q(dir.path() / "lat.json"), sub);
  tetrig::dds::FramePublisher pub(name, tetrig::dds::DdsOptions{});
  ASSERT_TRUE(pub.waitForFrameReaders(1, 10'000'000'000)) << slurp(sub.err);
  const std::vector<std::uint32_t> triangles = {0, 1, 2, 0, 2, 3};
  const std::vector<float> rest = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
  const std::vector<std::string> labels = {"M1"};
  tetrig::dds::StaticView s;
  s.instance_id = 42;
  s.rig_name = "quad";
  s.vertex_count = 4;
  s.triangles = triangles;
  s.rest_positions = rest;
  s.marker_labels = labels;
  pub.publishStatic(s);
  ASSERT_TRUE(waitForText(sub.err, "static data: rig 'quad', 4 vertices, 2 triangles, 1 markers", std::chrono::seconds(10))) << slurp(sub.err);
  const std::vector<float> good = rest, short_positions(9, 0.5f), normals_bad(6, 0.0f);
  std::vector<float> nan = rest;
  nan[4] = std::numeric_limits<float>::quiet_NaN();
  struct Sample {
    std::uint64_t id;
    const std::vector<float>* positions;
    const std::vector<float>* normals;
  };
  const Sample samples[] = {{1, &good, nullptr}, {2, &short_positions, nullptr}, {3, &nan, nullptr}, {4, &good, &normals_bad},
                            {5, &good, nullptr}, {3, &good, nullptr},            {6, &good, nullptr}};
  for (const Sample& x : samples) {
    tetrig::dds::FrameView f;
    f.instance_id = 42;
    f.frame_id = x.id;
    f.positions = *x.positions;
    if (x.normals) f.normals = *x.normals;
    ASSERT_EQ(pub.writeFrame(f), 0);
    std::this_thread::sleep_for(std::chrono::milliseconds(60));  // keep-last-1 reader: one sample at a time
  }
  EXPECT_EQ(waitExit(cat, std::chrono::seconds(10)), 0) << slurp(sub.err);
  const std::string err = slurp(sub.err);
  EXPECT_NE(err.find("frame 2 refused: 9 position floats for 4 vertices (need 12) (1 refused so far)"), std::string::npos) << err;
  EXPECT_NE(err.find("frame 3 refused: a non-finite value (2 refused so far)"), std::string::npos) << err;
  EXPECT_NE(err.find("frame 4 refused: 6 normal floats (need 0 or 12) (3 refused so far)"), std::string::npos) << err;
  EXPECT_NE(err.find("frame 3 refused: frame id not above the last one accepted (5) (4 refused so far)"), std::string::npos) << err;
  EXPECT_NE(slurp(dir.path() / "lat.json").find("\"frames_refused\": 4"), std::string::npos) << slurp(dir.path() / "lat.json");
  const auto records = readDump(sub.dump);
  ASSERT_EQ(records.size(), 3u);
  EXPECT_EQ(records[0].frame_id, 1u);
  EXPECT_EQ(records[1].frame_id, 5u);
  EXPECT_EQ(records[2].frame_id, 6u);
  EXPECT_EQ(records[2].positions, good);
}

// Static data that does not hold together is refused, and frames of its instance wait (never shown).
TEST(Dds, MalformedStaticDataIsRefused) {
  const TempDir dir("tetrig-dds");
  useLoopbackDomain(dir, 167);
  const std::string name = "tetrig_dds_g_" + std::to_string(getpid());
  const Files sub = files(dir, "sub");
  const pid_t cat = startDdsCat(name, "--timeout-ms 1500 --latency-json " + q(dir.path() / "lat.json"), sub);
  tetrig::dds::FramePublisher pub(name, tetrig::dds::DdsOptions{});
  ASSERT_TRUE(pub.waitForFrameReaders(1, 10'000'000'000)) << slurp(sub.err);
  const std::vector<std::uint32_t> triangles = {0, 1, 7};
  const std::vector<float> rest = {0, 0, 0, 1, 0, 0, 1, 1, 0};
  tetrig::dds::StaticView s;
  s.instance_id = 7;
  s.rig_name = "bad";
  s.vertex_count = 3;
  s.triangles = triangles;
  s.rest_positions = rest;
  pub.publishStatic(s);
  ASSERT_TRUE(waitForText(sub.err, "static data refused: triangle index 7 >= vertex count 3", std::chrono::seconds(10))) << slurp(sub.err);
  tetrig::dds::FrameView f;
  f.instance_id = 7;
  f.frame_id = 1;
  f.positions = rest;
  ASSERT_EQ(pub.writeFrame(f), 0);
  EXPECT_EQ(waitExit(cat, std::chrono::seconds(10)), 2) << slurp(sub.err);  // no frame accepted: timeout
  EXPECT_NE(slurp(dir.path() / "lat.json").find("\"frames_seen\": 0"), std::string::npos);
  EXPECT_NE(slurp(dir.path() / "lat.json").find("\"static_refused\": 1"), std::string::npos) << slurp(dir.path() / "lat.json");
}

// Bad names and options: one line and a non-zero exit.
TEST(Dds, BadInputIsOneLine) {
  const TempDir dir("tetrig-dds");
  useLoopbackDomain(dir, 168);
  const auto bad_name = tetrig::test::runCommand(TETRIG_DDS_CAT_EXE, "'a b'", dir.path());
  EXPECT_EQ(bad_name.status, 1);
  EXPECT_EQ(bad_name.err, "tetrig-dds-cat: DDS topic name: the segment name has a character DDS topic names cannot hold (' '): use letters, digits, "
                          "'_', '-' or '.'\n");
  const auto bad_frames = tetrig::test::runCommand(TETRIG_DDS_CAT_EXE, "x --frames -3", dir.path());
  EXPECT_EQ(bad_frames.status, 1);
  EXPECT_EQ(bad_frames.err, "tetrig-dds-cat: --frames needs a number >= 1\n");
  EXPECT_EQ(tetrig::dds::topicBaseName("/tetrig-man.v2"), "tetrig_man_v2");
  // tetrig run refuses the name in one line, leaving no segment behind.
  const std::string rig = smallRig(dir);
  const std::string segment = "tetrig-dds-bad:" + std::to_string(getpid());
  const auto run = tetrig::test::runCommand(TETRIG_EXE, "run --rig '" + rig + "' --source synthetic --frames 5 --publish '" + segment + "' --dds --no-mlock -q",
                                            dir.path());
  EXPECT_EQ(run.status, 1);
  EXPECT_EQ(run.err, "tetrig run: error: --dds: DDS topic name: the segment name has a character DDS topic names cannot hold (':'): use letters, "
                     "digits, '_', '-' or '.'\n");
  EXPECT_FALSE(std::filesystem::exists("/dev/shm/" + segment));
  // A configuration Cyclone cannot use: Cyclone's own line, then ours, exit 1.
  setenv("CYCLONEDDS_URI", "file:///nonexistent/cyclonedds.xml", 1);
  const auto no_config = tetrig::test::runCommand(TETRIG_DDS_CAT_EXE, "x --timeout-ms 100", dir.path());
  EXPECT_EQ(no_config.status, 1);
  EXPECT_NE(no_config.err.find("tetrig-dds-cat: DDS subscriber for 'x': cannot create a DDS participant (Error): check CYCLONEDDS_URI"),
            std::string::npos)
      << no_config.err;
  EXPECT_THROW(tetrig::dds::topicBaseName("/"), tetrig::dds::DdsError);
}

}  // namespace

namespace {

using tetrig::test::findOnPath;

// `tetrig view --dds NAME` under xvfb-run draws the frames it gets over DDS (the static data
// builds the mesh) and writes its screenshot. Skipped with a message without xvfb-run/xauth,
// FAIL under CI=true; one at a time with test_view (RESOURCE_LOCK xvfb_run).
TEST(DdsView, ViewerDrawsTheFramesItGetsOverDds) {
  const auto xvfb_run = findOnPath("xvfb-run");
  if (!xvfb_run || !findOnPath("xauth")) {
    if (tetrig::test::runningInCi()) FAIL() << "xvfb-run or xauth not found in CI (apt-get install xvfb xauth)";
    GTEST_SKIP() << "xvfb-run or xauth not found: apt-get install xvfb xauth to run the viewer headless";
  }
  const TempDir dir("tetrig-dds");
  useLoopbackDomain(dir, 169);
  const std::string rig = smallRig(dir);
  const std::string name = "tetrig-dds-view-" + std::to_string(getpid());
  const pid_t producer = spawn(runArgs(rig, name, 1000) + " >" + q(dir.path() / "run.out") + " 2>" + q(dir.path() / "run.err"));
  ASSERT_GT(producer, 0);
  const auto shot = dir.path() / "shot.png";
  const auto view = tetrig::test::runCommand(xvfb_run->string(), "-a -s '-screen 0 640x480x24' " + q(TETRIG_EXE) + " view --dds " + name +
                                                                   " --screenshot " + q(shot) + " --after-frames 20 --timeout 30 --width 320 --height 240",
                                             dir.path());
  kill(producer, SIGINT);
  EXPECT_EQ(waitExit(producer, std::chrono::seconds(10)), 0) << slurp(dir.path() / "run.err");
  ASSERT_EQ(view.status, 0) << view.err;
  EXPECT_NE(view.err.find("tetrig/" + tetrig::dds::topicBaseName(name) + "/frame: rig 'small block', 34 vertices"), std::string::npos) << view.err;
  EXPECT_NE(view.out.find("(over DDS), 20 frames taken"), std::string::npos) << view.out;
  const std::string png = slurp(shot);
  ASSERT_GT(png.size(), 8u);
  EXPECT_EQ(png.compare(1, 3, "PNG"), 0);
}

}  // namespace

#include "tetrig/dds/frame_subscriber.hpp"
#include "tetrig/dds/segment_bridge.hpp"
#include "tetrig/shm_publisher.hpp"

namespace {

// A SegmentBridge that follows a segment by name (no in-process publisher: it polls) writes each
// committed frame as committed, with the static data first, and ends by itself, saying so, when the
// segment's producer stops; a subscriber in the same process gets the frames unchanged.
TEST(DdsBridge, FollowsASegmentByNameAndEndsWhenItsProducerStops) {
  const TempDir dir("tetrig-dds");
  useLoopbackDomain(dir, 170);
  const std::string name = "/tetrig-dds-bridge-" + std::to_string(getpid());
  const std::vector<std::int32_t> triangles = {0, 1, 2, 0, 2, 3};
  const std::vector<float> rest = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
  const std::vector<std::string> labels = {"A", "B"};
  auto shm = std::make_unique<tetrig::ShmPublisher>(tetrig::ShmPublisherOptions{.name = name}, 4,
                                                    tetrig::ShmStaticData{triangles, rest, "quad", labels});
  const std::string base = tetrig::dds::topicBaseName(name);
  tetrig::dds::FrameSubscriber sub(base, tetrig::dds::DdsOptions{});
  tetrig::dds::SegmentBridge bridge(name, base, nullptr, tetrig::dds::SegmentBridgeOptions{});
  const auto deadline = Clock::now() + std::chrono::seconds(10);
  while (bridge.matchedReaders() < 1 && Clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ASSERT_GE(bridge.matchedReaders(), 1);
  std::vector<tetrig::dds::SubscriberEvent> events;
  std::map<std::uint64_t, std::vector<float>> frames;
  std::optional<tetrig::dds::ReceivedStatic> static_data;
  for (int k = 1; k <= 5; ++k) {
    float* p = shm->beginPositions();
    for (int i = 0; i < 12; ++i) p[i] = rest[static_cast<std::size_t>(i)] + 0.01f * static_cast<float>(k * 100 + i);
    shm->commit(tetrig::ShmFrameInfo{.source_frame = static_cast<std::uint64_t>(k), .receive_ns = 1});
    const auto until = Clock::now() + std::chrono::seconds(3);
    while (frames.count(static_cast<std::uint64_t>(k)) == 0 && Clock::now() < until) {
      events.clear();
      sub.poll(10'000'000, events);
      for (const auto& e : events) {
        if (e.kind == tetrig::dds::SubscriberEvent::kFrame) frames[e.frame.frame_id] = e.frame.positions;
        if (e.kind == tetrig::dds::SubscriberEvent::kStatic) static_data = e.static_data;
      }
    }
    ASSERT_EQ(frames.count(static_cast<std::uint64_t>(k)), 1u) << "frame " << k << " did not come";
    EXPECT_EQ(frames[static_cast<std::uint64_t>(k)], std::vector<float>(p, p + 12)) << "frame " << k;
  }
  // The static data is reliable but not ordered with the frames: it may come after them.
  const auto static_until = Clock::now() + std::chrono::seconds(5);
  while (!static_data && Clock::now() < static_until) {
    events.clear();
    sub.poll(10'000'000, events);
    for (const auto& e : events)
      if (e.kind == tetrig::dds::SubscriberEvent::kStatic) static_data = e.static_data;
  }
  ASSERT_TRUE(static_data.has_value());
  EXPECT_EQ(static_data->rig_name, "quad");
  EXPECT_EQ(static_data->vertex_count, 4u);
  EXPECT_EQ(static_data->triangles, std::vector<std::uint32_t>(triangles.begin(), triangles.end()));
  EXPECT_EQ(static_data->rest_positions, rest);
  EXPECT_EQ(static_data->marker_labels, labels);
  EXPECT_EQ(static_data->instance_id, shm->instanceId());
  // The bridge counts a frame once dds_write has returned, which may be after the subscriber got it.
  const auto count_until = Clock::now() + std::chrono::seconds(5);
  while (bridge.stats().frames_written < 5 && Clock::now() < count_until) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  EXPECT_EQ(bridge.stats().frames_written, 5u);
  EXPECT_EQ(bridge.stats().write_errors, 0u);
  EXPECT_EQ(bridge.end(), "");
  shm.reset();  // the producer stops: state stopped, name unlinked
  const auto until = Clock::now() + std::chrono::seconds(5);
  while (bridge.end().empty() && Clock::now() < until) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  EXPECT_EQ(bridge.end(), "the segment's producer stopped");
  bridge.stop();
  EXPECT_EQ(bridge.end(), "the segment's producer stopped");
}

}  // namespace
