// Several performers in one `tetrig run` (tools/run.hpp; docs/live.md, "Several performers").
//
// The two-performer clip is made here from the HDM05 clip: its markers under two subject names,
// "alice:LABEL" as recorded and "bob:LABEL" 1 m to the side, in one C3D file (nothing is copied
// into the repository). Asserted, on the SMPL rig built from HDM05:
//  - both performers of one stage publish, frame for frame, exactly (CRC-32C of the positions) what
//    a run of that performer alone publishes from the same clip; and the two differ;
//  - markers of the other subject are neither bound nor counted as unknown;
//  - one performer's source ending does not stop the other;
//  - a clip carrying two subjects is refused without subject=, and so is an unknown subject;
//  - the --performer text, the stage file and the stage checks refuse what cannot run, one line each;
//  - the command runs a stage file and writes one stats object per performer plus the totals.
// Every run is lockstep (--as-fast-as-possible) with a budget no step reaches, so that the
// iteration count alone decides each pose.
#include "run.hpp"

#include "c3d_test_writer.hpp"
#include "run_command.hpp"
#include "temp_dir.hpp"
#include "test_data.hpp"

#include "tetrig/drivers/c3d_reader.hpp"
#include "tetrig/drivers/marker_stream.hpp"
#include "tetrig/drivers/raw_recording.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/build_rig.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <unistd.h>

#include <cstdint>
#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <iterator>
#include <fstream>
#include <memory>
#include <span>
#include <set>
#include <string>
#include <vector>

namespace tetrig {
namespace {

namespace drv = tetrig::drivers;
using test::TempDir;

constexpr const char* kMan = "meshes/odedstein-meshes/human_man.obj";
constexpr const char* kClip = "mocap/hdm05/HDM_mm_01-02_03_120.c3d";
constexpr std::size_t kFirstFrame = 900;  // walking: every frame a new pose
constexpr std::size_t kFrames = 180;
constexpr float kBobOffsetMm = 1000.0f;

std::string segmentName(const std::string& what) { return "tetrig-stage-" + what + "-" + std::to_string(getpid()); }

// The rig and the clips, built once for the binary.
struct Scene {
  TempDir dir{"tetrig-stage"};
  std::filesystem::path rig, two_subjects, alice_short, alice_with_gap;
  bool ok = false;
};

// "alice:" + the clip's points as recorded and "bob:" + the same points moved by `offset_mm` along
// x, frames [first, first + frames); or one subject without a prefix.
std::vector<std::uint8_t> subjectsClip(const drv::C3DClip& clip, std::size_t first, std::size_t frames,
                                       const std::vector<std::pair<std::string, float>>& subjects) {
  test::TestC3DSpec spec;
  spec.rate = static_cast<float>(clip.frameRate());
  spec.frames = frames;
  const double to_mm = clip.unitsToMm();
  for (const auto& [prefix, dx] : subjects)
    for (const std::string& label : clip.labels()) {
      // HDM05 names its one subject ("meinard:LFHD"): each performer gets its own instead.
      const std::string marker = label.substr(label.rfind(':') == std::string::npos ? 0 : label.rfind(':') + 1);
      spec.labels.push_back(prefix.empty() ? label : prefix + ":" + marker);
    }
  for (std::size_t f = first; f < first + frames; ++f)
    for (const auto& [prefix, dx] : subjects)
      for (int p = 0; p < clip.pointCount(); ++p) {
        const float* x = clip.positions(f) + static_cast<std::size_t>(p) * 3;
        spec.xyz.push_back({static_cast<float>(x[0] * to_mm) + dx, static_cast<float>(x[1] * to_mm), static_cast<float>(x[2] * to_mm)});
        spec.valid.push_back(clip.isValid(f, p));
      }
  return test::writeTestC3D(spec);
}

// A marker-stream device's recording (tetrig's raw format, replayed as `replay:`): the clip's labels,
// then frames [kFirstFrame, + kGapFrames) at 120 Hz, 600 ms of silence, then as many frames again.
constexpr std::size_t kGapFrames = 60;
void writeRecordingWithGap(const drv::C3DClip& clip, const std::filesystem::path& path) {
  drv::RawRecordingHeader header;
  header.vendor_id = 0x1209;
  header.product_id = 0x7e7f;
  header.description = "test: HDM05 with a 600 ms gap";
  drv::RawRecorder rec(path, header);
  std::vector<drv::MarkerLabel> labels;
  for (int p = 0; p < clip.pointCount(); ++p) labels.push_back({static_cast<std::uint16_t>(p), clip.labels()[static_cast<std::size_t>(p)]});
  std::vector<std::uint8_t> bytes(drv::kMarkerStreamMaxMessageSize);
  const std::size_t n = drv::encodeMarkerStreamDescriptor(labels, 1, bytes);
  ASSERT_GT(n, 0u);
  rec.write(0, 0, std::span<const std::uint8_t>(bytes.data(), n));
  auto frame = std::make_unique<MarkerFrame>();
  const std::int64_t period = 1'000'000'000 / 120;
  for (std::size_t k = 0; k < 2 * kGapFrames; ++k) {
    const std::size_t f = kFirstFrame + k;
    frame->frame_counter = k + 1;
    frame->device_timestamp_ns = static_cast<std::int64_t>(k) * period;
    frame->marker_count = static_cast<std::uint16_t>(clip.pointCount());
    for (int p = 0; p < clip.pointCount(); ++p) {
      Marker& m = frame->markers[static_cast<std::size_t>(p)];
      for (int a = 0; a < 3; ++a) m.position_mm[a] = static_cast<float>(clip.positions(f)[p * 3 + a] * clip.unitsToMm());
      m.id = static_cast<std::uint16_t>(p);
      m.valid = clip.isValid(f, p) ? 1 : 0;
    }
    const std::size_t len = drv::encodeMarkerStreamFrame(*frame, {}, bytes);
    ASSERT_GT(len, 0u);
    const std::int64_t at = period * static_cast<std::int64_t>(k + 1) + (k >= kGapFrames ? 600'000'000 : 0);
    rec.write(0, at, std::span<const std::uint8_t>(bytes.data(), len));
  }
  rec.close();
}

void buildScene(Scene& sc) {
    const std::filesystem::path man = test::dataPath(kMan), clip_path = test::dataPath(kClip);
    if (!std::filesystem::exists(man) || !std::filesystem::exists(clip_path)) return;
    rigbuild::BuildRigInputs in;
    in.mesh = man;
    in.clip = clip_path;
    in.tet_vertices = 1500;
    in.max_marker_distance = 0.15;
    in.check_deformer = false;
    sc.rig = sc.dir.writeBytes("smpl_hdm05.rig", serializeRig(rigbuild::buildRig(in)));
    const drv::C3DClip clip = drv::C3DClip::load(clip_path);
    sc.two_subjects = sc.dir.writeBytes("two.c3d", subjectsClip(clip, kFirstFrame, kFrames, {{"alice", 0.0f}, {"bob", kBobOffsetMm}}));
    sc.alice_short = sc.dir.writeBytes("alice_short.c3d", subjectsClip(clip, kFirstFrame, kFrames / 3, {{"", 0.0f}}));
    sc.alice_with_gap = sc.dir.path() / "alice_gap.raw";
    writeRecordingWithGap(clip, sc.alice_with_gap);
    sc.ok = true;
}

const Scene& scene() {
  static Scene s;
  static const bool built = (buildScene(s), true);
  (void)built;
  return s;
}

#define REQUIRE_SCENE()                       \
  TETRIG_REQUIRE_DATA(man_path_, kMan);       \
  TETRIG_REQUIRE_DATA(clip_path_, kClip);     \
  ASSERT_TRUE(scene().ok) << "building the scene failed"

tools::RunOptions lockstep() {
  tools::RunOptions o;
  o.as_fast_as_possible = true;
  o.budget_ms = 60000;  // no step reaches it: the iteration count alone decides
  o.quiet = true;
  o.status_line = false;
  o.lock_memory = false;
  o.frame_log_capacity = 4096;
  o.frame_log_positions_crc = true;
  return o;
}

tools::PerformerSpec performer(const std::string& name, const std::filesystem::path& clip, const std::string& subject) {
  tools::PerformerSpec p;
  p.name = name;
  p.rig_path = scene().rig.string();
  p.source = "c3d:" + clip.string();
  p.subject = subject;
  p.publish = segmentName(name);
  return p;
}

std::vector<std::uint32_t> crcs(const tools::RunOutcome& o) {
  std::vector<std::uint32_t> v;
  for (const FrameLogEntry& e : o.frame_log) v.push_back(e.positions_crc);
  return v;
}

tools::RunOutcome runAlone(const tools::PerformerSpec& p) {
  tools::RunOptions o = lockstep();
  o.performers = {p};
  tools::RunOutcome out;
  EXPECT_EQ(tools::runLive(o, &out), 0);
  return out;
}

TEST(Stage, TwoSubjectsOfOneClipPublishWhatEachAloneWouldBitForBit) {
  REQUIRE_SCENE();
  tools::RunOptions o = lockstep();
  o.performers = {performer("alice", scene().two_subjects, "alice"), performer("bob", scene().two_subjects, "bob")};
  tools::RunOutcome stage;
  ASSERT_EQ(tools::runLive(o, &stage), 0);
  ASSERT_EQ(stage.performers.size(), 2u);
  const tools::RunOutcome alice = runAlone(performer("alice-alone", scene().two_subjects, "alice"));
  const tools::RunOutcome bob = runAlone(performer("bob-alone", scene().two_subjects, "bob"));

  ASSERT_EQ(stage.performers[0].frame_log.size(), kFrames);
  ASSERT_EQ(stage.performers[1].frame_log.size(), kFrames);
  EXPECT_EQ(crcs(stage.performers[0]), crcs(alice)) << "alice on the stage = alice alone, every frame";
  EXPECT_EQ(crcs(stage.performers[1]), crcs(bob)) << "bob on the stage = bob alone, every frame";
  const std::vector<std::uint32_t> a = crcs(alice), b = crcs(bob);
  std::size_t differ = 0;
  for (std::size_t i = 0; i < kFrames; ++i) differ += a[i] != b[i];
  EXPECT_EQ(differ, kFrames) << "bob stands 1 m from alice: no frame of theirs is the same pose";
  EXPECT_GT(std::set<std::uint32_t>(a.begin(), a.end()).size(), kFrames - 2) << "alice walks: her poses change";

  const nlohmann::json& j = stage.stats;
  ASSERT_TRUE(j.contains("performers") && j.contains("totals")) << j.dump();
  ASSERT_EQ(j["performers"].size(), 2u);
  for (const nlohmann::json& p : j["performers"]) {
    EXPECT_EQ(p["frames"].get<std::uint64_t>(), kFrames) << p.dump();
    EXPECT_EQ(p["unknown_marker_frames"].get<std::uint64_t>(), 0u) << "the other subject's markers are not unknown";
    EXPECT_EQ(p["rig"]["markers_bound"].get<int>(), p["rig"]["markers"].get<int>()) << p.dump();
    EXPECT_EQ(p["dropped_frames"].get<std::uint64_t>(), 0u);
  }
  EXPECT_EQ(j["performers"][0]["name"], "alice");
  EXPECT_EQ(j["performers"][1]["subject"], "bob");
  EXPECT_EQ(j["totals"]["frames"].get<std::uint64_t>(), 2 * kFrames);
  EXPECT_EQ(j["performers"][0]["source"]["frames_published"].get<std::uint64_t>(), kFrames) << "the clip was read once for both";
}

TEST(Stage, OnePerformersSourceEndingDoesNotStopTheOther) {
  REQUIRE_SCENE();
  tools::RunOptions o = lockstep();
  o.performers = {performer("alice", scene().alice_short, ""), performer("bob", scene().two_subjects, "bob")};
  tools::RunOutcome stage;
  ASSERT_EQ(tools::runLive(o, &stage), 0);
  ASSERT_EQ(stage.performers.size(), 2u);
  EXPECT_EQ(stage.performers[0].frame_log.size(), kFrames / 3);
  EXPECT_EQ(stage.performers[0].stats["end"], "source ended");
  ASSERT_EQ(stage.performers[1].frame_log.size(), kFrames) << "bob goes on after alice's clip ended";
  EXPECT_EQ(stage.performers[1].stats["end"], "source ended");
  const tools::RunOutcome bob = runAlone(performer("bob-alone", scene().two_subjects, "bob"));
  EXPECT_EQ(crcs(stage.performers[1]), crcs(bob));
}

// Real-time pacing: alice's device goes silent for 600 ms in the middle (her segment says stale),
// bob's clip plays on to its end.
TEST(Stage, OnePerformersSourceGoingStaleDoesNotStopTheOther) {
  REQUIRE_SCENE();
  tools::RunOptions o = lockstep();
  o.as_fast_as_possible = false;
  o.stale_ms = 250;
  tools::PerformerSpec alice = performer("alice", scene().alice_with_gap, "");
  alice.source = "replay:" + scene().alice_with_gap.string();
  o.performers = {alice, performer("bob", scene().two_subjects, "bob")};
  tools::RunOutcome stage;
  ASSERT_EQ(tools::runLive(o, &stage), 0);
  ASSERT_EQ(stage.performers.size(), 2u);
  const nlohmann::json& a = stage.performers[0].stats;
  const nlohmann::json& b = stage.performers[1].stats;
  EXPECT_EQ(a["stale_periods"].get<std::uint64_t>(), 1u) << a.dump();
  EXPECT_EQ(a["frames"].get<std::uint64_t>() + a["dropped_frames"].get<std::uint64_t>(), 2 * kGapFrames) << a.dump();
  // Bob's own stale periods are not asserted: on a loaded machine (a sanitizer build solves a frame
  // in ~20 ms) his solver alone can starve the driver threads for a stale period.
  EXPECT_EQ(b["frames"].get<std::uint64_t>() + b["dropped_frames"].get<std::uint64_t>(), kFrames) << b.dump();
  EXPECT_EQ(b["end"], "source ended");
}

#if TETRIG_HAVE_DDS
// --dds with several performers: one DDS bridge per performer, each on the topics named from its
// own segment, each writing its performer's frames (Cyclone on the loopback interface only, a
// domain of this test's own: dds/config/loopback.xml with Id 175).
TEST(Stage, EachPerformerPublishesOnItsOwnDdsTopics) {
  REQUIRE_SCENE();
  std::ifstream in(std::filesystem::path(TETRIG_SOURCE_DIR) / "dds/config/loopback.xml");
  std::string xml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string any = "Id=\"any\"";
  ASSERT_NE(xml.find(any), std::string::npos);
  xml.replace(xml.find(any), any.size(), "Id=\"175\"");
  const TempDir dir;
  const std::filesystem::path config = dir.path() / "loopback.xml";
  std::ofstream(config) << xml;
  ASSERT_EQ(setenv("CYCLONEDDS_URI", ("file://" + config.string()).c_str(), 1), 0);
  tools::RunOptions o = lockstep();
  o.dds = true;
  o.performers = {performer("alice", scene().two_subjects, "alice"), performer("bob", scene().two_subjects, "bob")};
  tools::RunOutcome stage;
  const int status = tools::runLive(o, &stage);
  unsetenv("CYCLONEDDS_URI");
  ASSERT_EQ(status, 0);
  ASSERT_EQ(stage.performers.size(), 2u);
  std::set<std::string> topics;
  for (const tools::RunOutcome& p : stage.performers) {
    const nlohmann::json& j = p.stats;
    ASSERT_TRUE(j.contains("dds")) << j.dump();
    const std::string topic = j["dds"]["frame_topic"].get<std::string>();
    std::string base = j["segment"].get<std::string>();
    std::replace(base.begin(), base.end(), '-', '_');
    EXPECT_NE(topic.find(base), std::string::npos) << topic << " is named from the performer's segment " << base;
    topics.insert(topic);
    EXPECT_GE(j["dds"]["frames_written"].get<std::uint64_t>(), 1u) << j.dump();
    EXPECT_EQ(j["dds"]["frames_written"].get<std::uint64_t>() + j["dds"]["frames_skipped"].get<std::uint64_t>(), kFrames) << j.dump();
    EXPECT_EQ(j["dds"]["write_errors"].get<std::uint64_t>(), 0u);
  }
  EXPECT_EQ(topics.size(), 2u);
}
#endif

TEST(Stage, AClipOfSeveralSubjectsNeedsTheSubjectNamed) {
  REQUIRE_SCENE();
  tools::RunOptions o = lockstep();
  o.rig_path = scene().rig.string();
  o.source = "c3d:" + scene().two_subjects.string();
  o.publish = segmentName("nosubject");
  try {
    tools::runLive(o);
    FAIL() << "a clip of two subjects driven without a subject must be refused";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("carries several performers (subjects alice, bob)"), std::string::npos) << e.what();
  }
  o.performers = {performer("carol", scene().two_subjects, "carol")};
  try {
    tools::runLive(o);
    FAIL() << "an unknown subject must be refused";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("has no subject 'carol' (its subjects: alice, bob)"), std::string::npos) << e.what();
  }
}

TEST(Stage, PerformerTextStageFileAndChecksRefuseWhatCannotRun) {
  const tools::PerformerSpec p = tools::parsePerformerSpec("rig=a.rig,source=c3d:x.c3d,publish=seg,subject=alice,cpu=1,name=A,coarse-rig=c.rig");
  EXPECT_EQ(p.rig_path, "a.rig");
  EXPECT_EQ(p.source, "c3d:x.c3d");
  EXPECT_EQ(p.publish, "seg");
  EXPECT_EQ(p.subject, "alice");
  EXPECT_EQ(p.cpu, 1);
  EXPECT_EQ(p.name, "A");
  EXPECT_EQ(p.coarse_rig_path, "c.rig");
  const auto refused = [](const std::string& text, const std::string& says) {
    try {
      tools::parsePerformerSpec(text);
      ADD_FAILURE() << text << " was accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
    }
  };
  refused("rig=a.rig,sorce=x", "unknown key 'sorce'");
  refused("rig=a.rig,rig=b.rig", "rig given twice");
  refused("rig=a.rig,cpu=two", "cpu must be a CPU number");
  refused("rig", "'rig' is not KEY=VALUE");

  const TempDir dir;
  const auto stageFile = [&](const std::string& text) {
    const std::filesystem::path path = dir.path() / "stage.json";
    std::ofstream(path) << text;
    return path.string();
  };
  const std::vector<tools::PerformerSpec> stage = tools::loadStageFile(stageFile(
      R"({"performers": [{"rig": "man.rig", "source": "c3d:takes/two.c3d", "subject": "alice", "publish": "a", "cpu": 0},
                         {"rig": "/abs/man.rig", "source": "synthetic", "publish": "b"}]})"));
  ASSERT_EQ(stage.size(), 2u);
  EXPECT_EQ(stage[0].rig_path, (dir.path() / "man.rig").string()) << "relative to the stage file's folder";
  EXPECT_EQ(stage[0].source, "c3d:" + (dir.path() / "takes/two.c3d").string());
  EXPECT_EQ(stage[0].cpu, 0);
  EXPECT_EQ(stage[1].rig_path, "/abs/man.rig");
  EXPECT_EQ(stage[1].source, "synthetic");
  const auto stageRefused = [&](const std::string& text, const std::string& says) {
    try {
      tools::loadStageFile(stageFile(text));
      ADD_FAILURE() << text << " was accepted";
    } catch (const std::exception& e) {
      EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
    }
  };
  stageRefused(R"({"performers": [{"rig": "a", "sorce": "x"}]})", "performer 0: unknown key 'sorce'");
  stageRefused(R"({"performer": []})", "expected {\"performers\"");
  stageRefused(R"({"performers": [{"rig": 3}]})", "rig must be a string");
  stageRefused("{", "is not valid JSON");

  const auto checkRefused = [](std::vector<tools::PerformerSpec> s, const std::string& says) {
    try {
      tools::checkStage(s);
      ADD_FAILURE() << "accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
    }
  };
  tools::PerformerSpec a = tools::parsePerformerSpec("rig=a.rig,source=c3d:x.c3d,publish=seg,subject=alice");
  tools::PerformerSpec b = tools::parsePerformerSpec("rig=a.rig,source=c3d:x.c3d,publish=seg2,subject=bob");
  std::vector<tools::PerformerSpec> fine = {a, b};
  EXPECT_NO_THROW(tools::checkStage(fine));
  EXPECT_EQ(fine[0].name, "alice") << "the subject names a performer by default";
  checkRefused({}, "no performer");
  checkRefused({a, tools::parsePerformerSpec("rig=a.rig,source=c3d:y.c3d,publish=/seg")}, "segment '/seg', which another performer already uses");
  std::vector<tools::PerformerSpec> twice = {a, tools::parsePerformerSpec("rig=b.rig,source=c3d:x.c3d,publish=seg3,subject=alice,name=creature")};
  EXPECT_NO_THROW(tools::checkStage(twice)) << "one performer may drive two characters";
  checkRefused({tools::parsePerformerSpec("source=c3d:x.c3d,publish=s")}, "has no rig");
}

// The command: a stage file, a stats file with one object per performer and the totals; and the
// single-performer flags refused beside a stage.
TEST(Stage, TheCommandRunsAStageFile) {
  REQUIRE_SCENE();
  const TempDir dir;
  const std::string a = segmentName("cli-a"), b = segmentName("cli-b");
  const std::filesystem::path stage = dir.path() / "stage.json";
  std::ofstream(stage) << nlohmann::json{{"performers",
                                          {{{"rig", scene().rig.string()}, {"source", "c3d:" + scene().two_subjects.string()}, {"subject", "alice"}, {"publish", a}},
                                           {{"rig", scene().rig.string()}, {"source", "c3d:" + scene().two_subjects.string()}, {"subject", "bob"}, {"publish", b}}}}}
                              .dump();
  const std::filesystem::path stats = dir.path() / "stats.json";
  const test::CommandRun r = test::runCommand(TETRIG_EXE, "run --stage '" + stage.string() + "' --as-fast-as-possible --no-mlock --stats-json '" +
                                                              stats.string() + "'", dir.path());
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("performer alice: segment '" + a + "', subject alice"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("performer bob: source ended after"), std::string::npos) << r.out;
  std::ifstream in(stats);
  const nlohmann::json j = nlohmann::json::parse(in);
  ASSERT_EQ(j["performers"].size(), 2u);
  EXPECT_EQ(j["performers"][0]["frames"].get<std::uint64_t>(), kFrames);
  EXPECT_EQ(j["performers"][1]["frames"].get<std::uint64_t>(), kFrames);
  EXPECT_EQ(j["totals"]["frames"].get<std::uint64_t>(), 2 * kFrames);

  const test::CommandRun both = test::runCommand(TETRIG_EXE, "run --stage '" + stage.string() + "' --rig x.rig", dir.path());
  EXPECT_EQ(both.status, 1);
  EXPECT_NE(both.err.find("each performer names its rig"), std::string::npos) << both.err;
  const test::CommandRun none = test::runCommand(TETRIG_EXE, "run --clip x.c3d", dir.path());
  EXPECT_NE(none.status, 0);
  EXPECT_NE(none.err.find("no rig: give --rig RIG"), std::string::npos) << none.err;
}

}  // namespace
}  // namespace tetrig
