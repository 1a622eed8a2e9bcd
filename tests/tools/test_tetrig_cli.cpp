// The `tetrig` command as scripts use it: --help for every subcommand, the flags scripts rely on,
// one-line errors with a non-zero exit and no partial output file, build-rig then inspect.
#include "small_rig.hpp"

#include <gtest/gtest.h>

#include <sys/wait.h>

#include <cstdio>
#include <fstream>
#include <sstream>

namespace tetrig {
namespace {

using test::TempDir;

struct CliRun {
  int status = -1;
  std::string out, err;
};

CliRun run(const std::string& args, const TempDir& dir) {
  const std::string out = (dir.path() / "stdout.txt").string(), err = (dir.path() / "stderr.txt").string();
  const std::string cmd = std::string("'") + TETRIG_EXE + "' " + args + " >'" + out + "' 2>'" + err + "'";
  CliRun r;
  const int raw = std::system(cmd.c_str());
  r.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  auto slurp = [](const std::string& p) {
    std::ifstream in(p);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  };
  r.out = slurp(out);
  r.err = slurp(err);
  std::filesystem::remove(out);
  std::filesystem::remove(err);
  return r;
}

#define EXPECT_CONTAINS(haystack, needle) \
  EXPECT_NE(std::string(haystack).find(needle), std::string::npos) << "text: " << (haystack)

TEST(TetrigCli, HelpForEveryCommand) {
  const TempDir dir;
  const CliRun top = run("--help", dir);
  EXPECT_EQ(top.status, 0);
  for (const char* cmd : {"build-rig", "inspect", "demo"}) EXPECT_CONTAINS(top.out, cmd);
  const CliRun build = run("build-rig --help", dir);
  EXPECT_EQ(build.status, 0);
  for (const char* flag : {"--mesh", "--out", "--rig", "--markers", "--tet-vertices", "--max-marker-distance", "--frame"}) {
    EXPECT_CONTAINS(build.out, flag);
  }
  const CliRun inspect = run("inspect --help", dir);
  EXPECT_EQ(inspect.status, 0);
  EXPECT_CONTAINS(inspect.out, "RIG");
  const CliRun demo = run("demo --help", dir);
  EXPECT_EQ(demo.status, 0);
  for (const char* flag : {"--frames", "--iterations", "--budget-ms", "--out"}) EXPECT_CONTAINS(demo.out, flag);
  EXPECT_NE(run("", dir).status, 0);  // a subcommand is required
  EXPECT_NE(run("build-rig --out x.rig", dir).status, 0);  // --mesh is required
}

TEST(TetrigCli, BadInputIsOneLineNonZeroAndNoFile) {
  const TempDir dir;
  const std::string out = (dir.path() / "bad.rig").string();
  const CliRun r = run("build-rig --mesh /nonexistent/mesh.obj --out '" + out + "' --quiet", dir);
  EXPECT_NE(r.status, 0);
  EXPECT_EQ(r.err.rfind("tetrig build-rig: error: ", 0), 0u) << r.err;
  EXPECT_CONTAINS(r.err, "/nonexistent/mesh.obj");
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out));

  // A marker beyond the limit: the build stops, names it, and writes nothing.
  const std::filesystem::path node = test::writeBlockTetMesh(dir, "block");
  const std::filesystem::path clip = test::writeSmallClip(dir);
  const std::filesystem::path json = dir.write("small.json", test::smallRigJson());
  const CliRun far = run("build-rig --mesh '" + node.string() + "' --rig '" + json.string() + "' --markers '" + clip.string() +
                          "' --out '" + out + "' --max-marker-distance 0.001 --quiet",
                      dir);
  EXPECT_NE(far.status, 0);
  EXPECT_EQ(far.err.rfind("tetrig build-rig: error: marker ", 0), 0u) << far.err;
  EXPECT_EQ(std::count(far.err.begin(), far.err.end(), '\n'), 1) << far.err;
  EXPECT_FALSE(std::filesystem::exists(out));

  // A corrupted rig: inspect refuses it in one line.
  const std::filesystem::path junk = dir.write("junk.rig", "TETRIGRF but not really a rig file, just text");
  const CliRun bad = run("inspect '" + junk.string() + "'", dir);
  EXPECT_NE(bad.status, 0);
  EXPECT_EQ(bad.err.rfind("tetrig inspect: error: ", 0), 0u) << bad.err;
}

TEST(TetrigCli, BuildThenInspect) {
  const TempDir dir;
  const std::filesystem::path node = test::writeBlockTetMesh(dir, "block");
  const std::filesystem::path clip = test::writeSmallClip(dir);
  const std::filesystem::path json = dir.write("small.json", test::smallRigJson());
  const std::string out = (dir.path() / "small.rig").string();
  const CliRun b = run("build-rig --mesh '" + node.string() + "' --rig '" + json.string() + "' --markers '" + clip.string() + "' --out '" +
                        out + "' --simple-progress",
                    dir);
  ASSERT_EQ(b.status, 0) << b.err;
  EXPECT_CONTAINS(b.err, "binding markers by invisible tets");  // plain progress lines on stderr
  ASSERT_TRUE(std::filesystem::exists(out));
  const CliRun i = run("inspect '" + out + "' --markers", dir);
  EXPECT_EQ(i.status, 0) << i.err;
  EXPECT_CONTAINS(i.out, "tet mesh:      41 vertices (36 body + 5 marker)");
  EXPECT_CONTAINS(i.out, "region handle 'floor'");
  EXPECT_CONTAINS(i.out, "TOP");
}

}  // namespace
}  // namespace tetrig
