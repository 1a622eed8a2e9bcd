// Atomic file replacement (atomic_file.hpp): O_CREAT | O_EXCL temporary + fsync + rename(2) +
// directory fsync, POSIX.1-2008.
#include "tetrig/atomic_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <random>

namespace tetrig {
namespace {

constexpr int kCreateAttempts = 64;
constexpr std::size_t kMaxNameInTemporary = 200;  // keeps ".NAME.tmp-XXXXXX" under NAME_MAX (255)

std::string randomSuffix(std::mt19937_64& rng) {
  static constexpr char kChars[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789";
  std::string s(6, '0');
  for (char& c : s) c = kChars[rng() % (sizeof(kChars) - 1)];
  return s;
}

}  // namespace

AtomicFile::AtomicFile(const std::filesystem::path& target) : target_(target) {
  const std::filesystem::path dir = target.has_parent_path() ? target.parent_path() : std::filesystem::path(".");
  std::string base = target.filename().string();
  if (base.size() > kMaxNameInTemporary) base.resize(kMaxNameInTemporary);
  // An existing regular target keeps its mode (and owner/group where allowed); a new one gets
  // 0666 minus the umask, which open(2) applies.
  struct stat old {};
  const bool keep = ::lstat(target.c_str(), &old) == 0 && S_ISREG(old.st_mode);
  const mode_t mode = keep ? (old.st_mode & 07777 & ~static_cast<mode_t>(S_ISUID | S_ISGID)) : 0666;
  std::random_device seed;
  std::mt19937_64 rng((static_cast<std::uint64_t>(seed()) << 32) ^ seed());
  int err = 0;
  for (int attempt = 0; attempt < kCreateAttempts && fd_ < 0; ++attempt) {
    temporary_ = dir / ("." + base + ".tmp-" + randomSuffix(rng));
    fd_ = ::open(temporary_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, keep ? 0600 : mode);
    err = errno;
    if (fd_ < 0 && err != EEXIST) break;
  }
  if (fd_ < 0) {
    temporary_.clear();
    throw AtomicFileError(target_.string() + ": cannot create a temporary file in " + dir.string() + ": " + std::strerror(err));
  }
  if (keep) {
    (void)::fchown(fd_, old.st_uid, old.st_gid);  // as far as allowed (root: always; others: their groups)
    if (::fchmod(fd_, mode) != 0) fail("cannot set the mode of the temporary file", errno);
  }
}

AtomicFile::~AtomicFile() {
  if (!committed_) abort();
}

void AtomicFile::fail(const std::string& step, int err) {
  abort();
  throw AtomicFileError(target_.string() + ": " + step + ": " + std::strerror(err));
}

void AtomicFile::write(const void* data, std::size_t bytes) {
  if (fd_ < 0) throw AtomicFileError(target_.string() + ": write after commit or failure");
  if (stream_ != nullptr && std::fflush(stream_) != 0) fail("write failed", errno);
  const char* p = static_cast<const char*>(data);
  while (bytes > 0) {
    const ssize_t n = ::write(fd_, p, bytes);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) fail("write failed", errno);
    if (n == 0) fail("write failed", EIO);
    p += n;
    bytes -= static_cast<std::size_t>(n);
  }
}

std::FILE* AtomicFile::stream() {
  if (fd_ < 0) throw AtomicFileError(target_.string() + ": write after commit or failure");
  if (stream_ == nullptr) {
    stream_ = ::fdopen(fd_, "wb");
    if (stream_ == nullptr) fail("cannot open a stream on the temporary file", errno);
  }
  return stream_;
}

void AtomicFile::commit() {
  if (fd_ < 0) throw AtomicFileError(target_.string() + ": commit after commit or failure");
  if (stream_ != nullptr && std::fflush(stream_) != 0) fail("write failed", errno);
  if (::fsync(fd_) != 0) fail("fsync failed", errno);
  const int closed = stream_ != nullptr ? std::fclose(stream_) : ::close(fd_);
  const int close_err = errno;
  stream_ = nullptr;
  fd_ = -1;
  if (closed != 0) fail("close failed", close_err);
  if (::rename(temporary_.c_str(), target_.c_str()) != 0) fail("cannot rename the temporary file into place", errno);
  committed_ = true;
  const std::filesystem::path dir = target_.has_parent_path() ? target_.parent_path() : std::filesystem::path(".");
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    (void)::fsync(dfd);  // the rename is done; a failure to persist the directory entry is not reported
    ::close(dfd);
  }
}

void AtomicFile::abort() noexcept {
  if (stream_ != nullptr) {
    std::fclose(stream_);
  } else if (fd_ >= 0) {
    ::close(fd_);
  }
  stream_ = nullptr;
  fd_ = -1;
  if (!committed_ && !temporary_.empty()) {
    ::unlink(temporary_.c_str());
    temporary_.clear();
  }
}

}  // namespace tetrig
