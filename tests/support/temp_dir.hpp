// A fresh private directory for one test: created by mkdtemp(3) under the system's temporary
// directory ($TMPDIR, else /tmp) with an unpredictable name and mode 0700, so no other user can
// plant a file or a symbolic link where the test writes, and two tests (or two runs at once)
// never share files. Removed with everything in it when the object is destroyed, unless the
// environment variable TETRIG_KEEP_TEMP is set (then its path is printed on stderr, to look at
// what a failing test wrote).
//
// Tests only; throws std::runtime_error when the directory cannot be created.
#pragma once

#include <stdlib.h>

#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace tetrig::test {

class TempDir {
 public:
  // `prefix`: the start of the directory's name (letters, digits, '-', '_'), for whoever looks in /tmp.
  explicit TempDir(std::string_view prefix = "tetrig-test") {
    std::string tmpl = (std::filesystem::temp_directory_path() / (std::string(prefix) + "-XXXXXX")).string();
    if (::mkdtemp(tmpl.data()) == nullptr) {
      throw std::runtime_error("mkdtemp(" + tmpl + ") failed: " + std::strerror(errno));
    }
    path_ = tmpl;
  }
  ~TempDir() {
    if (std::getenv("TETRIG_KEEP_TEMP") != nullptr) {
      std::fprintf(stderr, "TETRIG_KEEP_TEMP: kept %s\n", path_.c_str());
      return;
    }
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  const std::filesystem::path& path() const { return path_; }
  // path() / name
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }
  // Writes `text` (byte for byte) to path() / name and returns that path.
  std::filesystem::path write(const std::string& name, std::string_view text) const {
    std::ofstream out(path_ / name, std::ios::binary | std::ios::trunc);
    out.write(text.data(), static_cast<std::streamsize>(text.size()));
    return path_ / name;
  }
  std::filesystem::path writeBytes(const std::string& name, const std::vector<std::uint8_t>& bytes) const {
    return write(name, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
  }

 private:
  std::filesystem::path path_;
};

}  // namespace tetrig::test
