// Work in a forked child process behind a pipe (fork, pipe, setrlimit, waitpid: POSIX.1-2008).
#include "tetrig/rigbuild/run_in_child_process.hpp"

#include "tetrig/rigbuild/surface_mesh.hpp"

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <fstream>

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define TETRIG_CHILD_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || __has_feature(memory_sanitizer)
#define TETRIG_CHILD_SANITIZED 1
#endif
#endif

namespace tetrig::rigbuild {
namespace {

constexpr std::size_t kMaxLog = 65536;

#ifndef TETRIG_CHILD_SANITIZED
// The child's current virtual memory size, from /proc/self/statm (pages); 0 when unknown.
std::uint64_t currentAddressSpace() {
  std::ifstream statm("/proc/self/statm");
  std::uint64_t pages = 0;
  if (!(statm >> pages)) return 0;
  const long page = ::sysconf(_SC_PAGESIZE);
  return pages * static_cast<std::uint64_t>(page > 0 ? page : 4096);
}
#endif

void applyLimits(const ChildLimits& limits) {
  const rlimit no_core{0, 0};
  (void)::setrlimit(RLIMIT_CORE, &no_core);
  if (limits.cpu_seconds > 0) {
    rlimit cpu{};
    (void)::getrlimit(RLIMIT_CPU, &cpu);
    const rlim_t soft = static_cast<rlim_t>(limits.cpu_seconds);
    if (cpu.rlim_max == RLIM_INFINITY || soft < cpu.rlim_max) {
      cpu.rlim_cur = soft;
      if (cpu.rlim_max == RLIM_INFINITY || soft + 1 < cpu.rlim_max) cpu.rlim_max = soft + 1;  // SIGKILL a second later
      (void)::setrlimit(RLIMIT_CPU, &cpu);
    }
  }
#ifndef TETRIG_CHILD_SANITIZED
  if (limits.memory_bytes > 0) {
    rlimit as{};
    (void)::getrlimit(RLIMIT_AS, &as);
    const std::uint64_t want = currentAddressSpace() + limits.memory_bytes;
    if (as.rlim_cur == RLIM_INFINITY || want < as.rlim_cur) {
      as.rlim_cur = static_cast<rlim_t>(want);
      (void)::setrlimit(RLIMIT_AS, &as);
    }
  }
#endif
}

}  // namespace

std::string ChildOutcome::describe() const {
  if (exited) return "exited with code " + std::to_string(exit_code);
  if (signal_number == SIGXCPU) return "was stopped by its CPU time limit (signal " + std::to_string(signal_number) + ")";
  if (signal_number == SIGKILL) return "was killed (signal 9: its CPU time limit, or the system ran out of memory)";
  const char* name = ::strsignal(signal_number);
  return "crashed with signal " + std::to_string(signal_number) + (name != nullptr ? std::string(" (") + name + ")" : std::string());
}

bool writeAllToFd(int fd, const void* data, std::size_t bytes) {
  const char* p = static_cast<const char*>(data);
  while (bytes > 0) {
    const ssize_t n = ::write(fd, p, bytes);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    p += n;
    bytes -= static_cast<std::size_t>(n);
  }
  return true;
}

ChildOutcome runInChildProcess(const std::function<bool(int output_fd)>& work, const ChildLimits& limits, bool capture_stdout) {
  std::FILE* log = capture_stdout ? std::tmpfile() : nullptr;
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) {
    const int err = errno;
    if (log != nullptr) std::fclose(log);
    throw RigBuildError(std::string("cannot create a pipe for a child process: ") + std::strerror(err));
  }
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t pid = ::fork();
  if (pid < 0) {
    const int err = errno;
    ::close(fds[0]);
    ::close(fds[1]);
    if (log != nullptr) std::fclose(log);
    throw RigBuildError(std::string("cannot start a child process: ") + std::strerror(err));
  }
  if (pid == 0) {
    ::close(fds[0]);
    if (log != nullptr) {
      ::dup2(::fileno(log), STDOUT_FILENO);
      std::setvbuf(stdout, nullptr, _IONBF, 0);
    }
    applyLimits(limits);
    int code = 2;
    try {
      code = work(fds[1]) ? 0 : 1;
    } catch (...) {
      code = 2;
    }
    ::close(fds[1]);
    ::_exit(code);
  }
  // Parent: collect the output until the child closes its end (it ends or dies).
  ::close(fds[1]);
  ChildOutcome outcome;
  char buffer[1 << 16];
  for (;;) {
    const ssize_t n = ::read(fds[0], buffer, sizeof buffer);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    outcome.output.insert(outcome.output.end(), buffer, buffer + n);
  }
  ::close(fds[0]);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (WIFEXITED(status)) {
    outcome.exited = true;
    outcome.exit_code = WEXITSTATUS(status);
  } else if (WIFSIGNALED(status)) {
    outcome.signal_number = WTERMSIG(status);
  }
  if (log != nullptr) {
    std::rewind(log);
    std::size_t n = 0;
    while (outcome.log.size() < kMaxLog && (n = std::fread(buffer, 1, std::min(sizeof buffer, kMaxLog - outcome.log.size()), log)) > 0) {
      outcome.log.append(buffer, n);
    }
    std::fclose(log);
  }
  return outcome;
}

}  // namespace tetrig::rigbuild
