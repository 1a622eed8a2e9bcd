// The project's one way to write a file: under a fresh temporary name beside the target, moved
// over the target only when complete. Readers of the target see the old file or the whole new
// one, never a partial one; a failure or an abandoned write leaves the target untouched and no
// temporary behind.
//
//   - The temporary is created with O_CREAT | O_EXCL (never an existing file, never through a
//     symbolic link planted at its name) under an unpredictable name ".<target name>.tmp-XXXXXX"
//     in the target's directory (so the rename stays on one file system).
//   - Mode: a new target gets 0666 minus the process umask (as any newly created file); an
//     existing regular target keeps its permission bits (and, where allowed, its owner and group).
//     A symbolic link at the target is replaced by the new file; the file it points to is not
//     touched.
//   - commit(): flush, fsync the file, rename it over the target, fsync the directory.
//   - Destroyed without commit(), or after any failure: the temporary is removed.
//
// Offline, POSIX, one thread per object, allocates, throws AtomicFileError naming the target,
// the step and the system error. Used by tools/ (writeFileAtomically: rigs, OBJ, JSON) and by
// drivers/ (RawRecorder), never on the frame path.
#pragma once

#include <cstdio>
#include <filesystem>
#include <stdexcept>
#include <string>

namespace tetrig {

class AtomicFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class AtomicFile {
 public:
  // Creates the temporary beside `target`. Throws AtomicFileError (directory missing or not
  // writable, ...).
  explicit AtomicFile(const std::filesystem::path& target);
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;
  ~AtomicFile();  // abort() unless committed

  // Appends bytes (unbuffered write(2) calls). Throws AtomicFileError.
  void write(const void* data, std::size_t bytes);
  // A buffered stdio stream on the temporary, owned here (commit() flushes and closes it); for
  // writers of many small pieces. Do not fclose it. Throws AtomicFileError when fdopen fails.
  std::FILE* stream();
  // Makes the file the target (see above). Throws AtomicFileError; the temporary is removed then.
  void commit();
  // Removes the temporary; the target is untouched. Idempotent, never throws.
  void abort() noexcept;

  const std::filesystem::path& target() const { return target_; }
  const std::filesystem::path& temporaryPath() const { return temporary_; }
  bool committed() const { return committed_; }

 private:
  [[noreturn]] void fail(const std::string& step, int err);
  std::filesystem::path target_;
  std::filesystem::path temporary_;
  int fd_ = -1;
  std::FILE* stream_ = nullptr;
  bool committed_ = false;
};

}  // namespace tetrig
