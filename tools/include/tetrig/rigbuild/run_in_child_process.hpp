// Isolation of third-party code that may crash, abort or run away on hostile or unlucky input:
// the work runs in a forked child process (POSIX) and sends its result back through a pipe, so a
// crash, an assertion abort, an exhausted memory limit or an exceeded CPU-time limit becomes an
// outcome the caller turns into a one-line error instead of taking the tool down. Used for TetGen
// (which frees its memory twice while it reports input errors) and for assimp's importers.
//
// The child: inherits the parent's memory copy-on-write (the work reads the caller's data
// directly), gets the limits below, never dumps core, and ends with _exit (no atexit handlers, no
// second flush of the parent's stdio buffers: stdout and stderr are flushed before the fork).
// Offline, any thread (glibc keeps malloc usable in the child of a multi-threaded parent; the work
// must not rely on other threads of the parent), allocates, throws RigBuildError when the pipe or
// the fork fails.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace tetrig::rigbuild {

struct ChildLimits {
  // Address space the child may ADD to what it inherits (RLIMIT_AS = inherited size + this);
  // 0: no limit. Not applied in sanitizer builds (their shadow memory cannot live under a limit).
  std::uint64_t memory_bytes = 0;
  // CPU time (RLIMIT_CPU, whole seconds, at least 1); 0: no limit. The child gets SIGXCPU.
  std::uint64_t cpu_seconds = 0;
};

struct ChildOutcome {
  std::vector<std::uint8_t> output;  // every byte the work wrote to its output descriptor
  bool exited = false;               // the child ended through _exit (else a signal ended it)
  int exit_code = -1;                // when exited: 0 when the work returned true
  int signal_number = 0;             // when not exited: the signal (SIGXCPU: CPU limit; SIGSEGV, SIGABRT: crash)
  std::string log;                   // the child's stdout when captured (at most 64 KiB)

  bool ok() const { return exited && exit_code == 0; }
  // For messages: "exited with code 2", "crashed with signal 6 (Aborted)", "was stopped by its CPU
  // time limit (signal 24)".
  std::string describe() const;
};

// Runs `work(output_fd)` in a child process and waits for it; the parent collects what the work
// writes to output_fd until the child ends. The child exits 0 when `work` returns true, 1 when
// it returns false, 2 when it throws. With `capture_stdout`, the child's stdout goes to a
// temporary file whose text is returned in ChildOutcome::log.
ChildOutcome runInChildProcess(const std::function<bool(int output_fd)>& work, const ChildLimits& limits = {},
                               bool capture_stdout = false);

// Writes all `bytes` to `fd` (retrying short writes and EINTR); false on error. For the work.
bool writeAllToFd(int fd, const void* data, std::size_t bytes);

}  // namespace tetrig::rigbuild
