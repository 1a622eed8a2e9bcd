// The tools' file writes (writeFileAtomically, tools/include/tetrig/rigbuild/write_file_atomic.hpp)
// and `tetrig demo --out` through them: the umask and an existing file's mode are honoured, a
// link planted at the old predictable "<out>.tmp" is not followed, and a failure leaves neither a
// temporary nor a partial file. (tetrig::AtomicFile itself: tests/runtime/test_atomic_file.cpp.)
#include "file_checks.hpp"
#include "tetrig/rigbuild/surface_mesh.hpp"
#include "tetrig/rigbuild/write_file_atomic.hpp"

#include "temp_dir.hpp"

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <sys/wait.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

namespace tetrig {
namespace {

using test::TempDir;
using ::tetrig::test::readText;
using ::tetrig::test::modeOf;
using ::tetrig::test::temporaries;

#define EXPECT_CONTAINS(haystack, needle) \
  EXPECT_NE(std::string(haystack).find(needle), std::string::npos) << "text: " << (haystack)

void writeText(const std::filesystem::path& p, const std::string& text) {
  rigbuild::writeFileAtomically(p, std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()));
}

TEST(WriteFileAtomically, ModesAndFailures) {
  const TempDir dir("tetrig-write");
  const mode_t old_mask = ::umask(077);
  writeText(dir / "new.rig", "abc");
  EXPECT_EQ(modeOf(dir / "new.rig"), 0600u);  // not a forced 0644
  dir.write("old.rig", "old");
  ASSERT_EQ(::chmod((dir / "old.rig").c_str(), 0640), 0);
  writeText(dir / "old.rig", "replaced");
  EXPECT_EQ(modeOf(dir / "old.rig"), 0640u);
  EXPECT_EQ(readText(dir / "old.rig"), "replaced");
  ::umask(old_mask);
  // A failure: the target is a directory. The error names it; nothing is left behind.
  std::filesystem::create_directory(dir / "busy.rig");
  try {
    writeText(dir / "busy.rig", "x");
    FAIL() << "no exception";
  } catch (const rigbuild::RigBuildError& e) {
    EXPECT_CONTAINS(e.what(), "busy.rig: cannot rename the temporary file into place");
  }
  EXPECT_TRUE(temporaries(dir.path()).empty());
}

#ifdef TETRIG_EXE
int shell(const std::string& cmd) {
  const int raw = std::system(cmd.c_str());
  return WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
}

TEST(WriteFileAtomically, DemoOutThroughTheAtomicWriter) {
  const TempDir dir("tetrig-demo-out");
  const auto victim = dir.write("victim", "secret");
  std::filesystem::create_symlink(victim, dir / "final.obj.tmp");  // where a plain writer put its temporary
  // The default character's rig is cached in the test's own folder.
  const std::string exe = "XDG_CACHE_HOME='" + (dir / "cache").string() + "' '" + TETRIG_EXE + "'";
  const std::string quiet = " >'" + (dir / "out.txt").string() + "' 2>'" + (dir / "err.txt").string() + "'";
  ASSERT_EQ(shell("umask 077; " + exe + " demo --frames 30 --quiet --no-report --out '" + (dir / "final.obj").string() + "'" + quiet), 0)
      << readText(dir / "err.txt");
  EXPECT_EQ(readText(victim), "secret");
  EXPECT_TRUE(std::filesystem::is_symlink(dir / "final.obj.tmp"));
  EXPECT_EQ(readText(dir / "final.obj").rfind("# tetrig: last published pose of ", 0), 0u);
  EXPECT_EQ(modeOf(dir / "final.obj"), 0600u);  // the umask of the shell that ran it
  EXPECT_TRUE(temporaries(dir.path()).empty());
  // A failing --out (a directory there): refused before the run (tools/rigbuild/output_guard.cpp),
  // one error line, exit 1, no temporary, no partial file.
  std::filesystem::create_directory(dir / "taken.obj");
  EXPECT_EQ(shell(exe + " demo --frames 10 --quiet --no-report --out '" + (dir / "taken.obj").string() + "'" + quiet), 1);
  const std::string err = readText(dir / "err.txt");
  const std::string line = "tetrig demo: error: --out " + (dir / "taken.obj").string() + " is a directory; give a file name\n";
  EXPECT_CONTAINS(err, line);
  EXPECT_EQ(err.find("error"), err.find(line) + 13) << err;  // the only error line
  EXPECT_TRUE(std::filesystem::is_empty(dir / "taken.obj"));
  EXPECT_TRUE(temporaries(dir.path()).empty());
}
#endif

}  // namespace
}  // namespace tetrig
