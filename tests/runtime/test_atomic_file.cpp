// Tests of the project's file writer (tetrig/atomic_file.hpp): the mode a new file gets (the
// umask) and an existing one keeps, the temporary (fresh, beside the target, never through a
// planted link), the target replaced only by commit(), and no temporary left after any failure.
#include "file_checks.hpp"
#include "tetrig/atomic_file.hpp"

#include "temp_dir.hpp"

#include <gtest/gtest.h>

#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <csignal>
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

void write(const std::filesystem::path& target, const std::string& text) {
  AtomicFile f(target);
  f.write(text.data(), text.size());
  f.commit();
}

// Sets the process umask for a scope.
class UmaskScope {
 public:
  explicit UmaskScope(mode_t mask) : old_(::umask(mask)) {}
  ~UmaskScope() { ::umask(old_); }

 private:
  mode_t old_;
};

// Caps the size of files this process writes (RLIMIT_FSIZE; SIGXFSZ ignored, so write(2) fails
// with EFBIG instead): a disk that fills up, for one scope.
class FileSizeLimit {
 public:
  explicit FileSizeLimit(rlim_t bytes) {
    old_handler_ = std::signal(SIGXFSZ, SIG_IGN);
    ::getrlimit(RLIMIT_FSIZE, &old_);
    rlimit lim = old_;
    lim.rlim_cur = bytes;
    ::setrlimit(RLIMIT_FSIZE, &lim);
  }
  ~FileSizeLimit() {
    ::setrlimit(RLIMIT_FSIZE, &old_);
    std::signal(SIGXFSZ, old_handler_);
  }

 private:
  rlimit old_{};
  void (*old_handler_)(int) = nullptr;
};

TEST(AtomicFile, NewFileGetsTheUmask) {
  const TempDir dir("tetrig-atomic");
  for (const mode_t mask : {mode_t{077}, mode_t{022}, mode_t{027}, mode_t{0}}) {
    const UmaskScope scope(mask);
    const auto target = dir / ("new-" + std::to_string(mask));
    write(target, "content");
    EXPECT_EQ(modeOf(target), 0666 & ~mask) << "umask " << std::oct << mask;
    EXPECT_EQ(readText(target), "content");
  }
  EXPECT_TRUE(temporaries(dir.path()).empty());
}

TEST(AtomicFile, ExistingFileKeepsItsMode) {
  const TempDir dir("tetrig-atomic");
  const UmaskScope scope(077);  // would give 0600 to a new file
  for (const mode_t mode : {mode_t{0640}, mode_t{0755}, mode_t{0604}}) {
    const auto target = dir / ("old-" + std::to_string(mode));
    dir.write(target.filename().string(), "old");
    ASSERT_EQ(::chmod(target.c_str(), mode), 0);
    write(target, "new content");
    EXPECT_EQ(modeOf(target), mode) << std::oct << mode;
    EXPECT_EQ(readText(target), "new content");
  }
}

TEST(AtomicFile, TargetChangesOnlyAtCommitAndTemporariesAreFresh) {
  const TempDir dir("tetrig-atomic");
  const auto target = dir / "rig.bin";
  dir.write("rig.bin", "old");
  AtomicFile a(target);
  AtomicFile b(target);
  for (const AtomicFile* f : {&a, &b}) {
    EXPECT_EQ(f->temporaryPath().parent_path(), dir.path());
    EXPECT_EQ(f->temporaryPath().filename().string().rfind(".rig.bin.tmp-", 0), 0u) << f->temporaryPath();
    struct stat st {};
    ASSERT_EQ(::lstat(f->temporaryPath().c_str(), &st), 0);
    EXPECT_TRUE(S_ISREG(st.st_mode));
    EXPECT_EQ(st.st_size, 0);  // created here, not an existing file
  }
  EXPECT_NE(a.temporaryPath(), b.temporaryPath());
  a.write("new", 3);
  std::fputs(" and more", a.stream());
  a.write("!", 1);  // after the stream's text (write() flushes the stream first)
  EXPECT_EQ(readText(target), "old");  // readers still see the old file
  a.commit();
  EXPECT_TRUE(a.committed());
  EXPECT_EQ(readText(target), "new and more!");
  b.abort();
  EXPECT_TRUE(temporaries(dir.path()).empty());
  EXPECT_EQ(readText(target), "new and more!");
}

TEST(AtomicFile, PlantedLinksAreNotFollowed) {
  const TempDir dir("tetrig-atomic");
  const auto victim = dir.write("victim", "secret");
  const auto victim2 = dir.write("victim2", "secret2");
  const auto target = dir / "out.obj";
  // The predictable temporary name a plain writer would use, and a link at the target itself.
  std::filesystem::create_symlink(victim, dir / "out.obj.tmp");
  std::filesystem::create_symlink(victim2, target);
  write(target, "v 0 0 0\n");
  EXPECT_EQ(readText(victim), "secret");
  EXPECT_EQ(readText(victim2), "secret2");
  EXPECT_TRUE(std::filesystem::is_symlink(dir / "out.obj.tmp"));
  EXPECT_FALSE(std::filesystem::is_symlink(target));  // the link was replaced, its file untouched
  EXPECT_EQ(readText(target), "v 0 0 0\n");
  EXPECT_TRUE(temporaries(dir.path()).empty());
}

TEST(AtomicFile, FailuresLeaveNoTemporaryAndTheTargetUntouched) {
  const TempDir dir("tetrig-atomic");
  // The rename fails: the target is a directory.
  std::filesystem::create_directory(dir / "busy");
  dir.write("busy/inside", "x");
  {
    AtomicFile f(dir / "busy");
    f.write("abc", 3);
    try {
      f.commit();
      FAIL() << "no exception";
    } catch (const AtomicFileError& e) {
      EXPECT_NE(std::string(e.what()).find("cannot rename the temporary file into place"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("busy"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(f.committed());
  }
  EXPECT_EQ(readText(dir / "busy/inside"), "x");
  EXPECT_TRUE(temporaries(dir.path()).empty());

  // A write fails (the disk is "full"): the old file stays whole.
  const auto target = dir.write("data.bin", "old data");
  {
    AtomicFile f(target);
    const std::string big(64 * 1024, 'z');
    const FileSizeLimit limit(4096);
    EXPECT_THROW(f.write(big.data(), big.size()), AtomicFileError);
  }
  EXPECT_EQ(readText(target), "old data");
  EXPECT_TRUE(temporaries(dir.path()).empty());
  // The same through the buffered stream, failing at commit's flush (3000 bytes wait in the
  // stream's buffer when the limit is set).
  {
    AtomicFile f(target);
    const std::string text(3000, 'z');
    std::fwrite(text.data(), 1, text.size(), f.stream());
    const FileSizeLimit limit(1024);
    EXPECT_THROW(f.commit(), AtomicFileError);
  }
  EXPECT_EQ(readText(target), "old data");
  EXPECT_TRUE(temporaries(dir.path()).empty());

  // Abandoned (destroyed without commit).
  {
    AtomicFile f(target);
    f.write("half", 4);
  }
  EXPECT_EQ(readText(target), "old data");
  EXPECT_TRUE(temporaries(dir.path()).empty());

  // No such directory: refused at once, naming the file.
  try {
    AtomicFile f(dir / "missing" / "x.rig");
    FAIL() << "no exception";
  } catch (const AtomicFileError& e) {
    EXPECT_NE(std::string(e.what()).find("missing/x.rig: cannot create a temporary file"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tetrig
