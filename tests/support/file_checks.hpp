// What tests of the file writers (AtomicFile, writeFileAtomically, RawRecorder) look at after a
// write: a file's bytes, its permission bits (the link itself, not what it points to), and the
// writer's temporaries left in a directory. Tests only.
#pragma once

#include <sys/stat.h>

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

namespace tetrig::test {

inline std::string readText(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Permission bits of `p` (lstat: a symbolic link's own), with a test failure when it does not exist.
inline mode_t modeOf(const std::filesystem::path& p) {
  struct stat st {};
  EXPECT_EQ(::lstat(p.c_str(), &st), 0) << p;
  return st.st_mode & 07777;
}

// Names in `dir` that look like temporaries of the writer (".NAME.tmp-XXXXXX").
inline std::vector<std::string> temporaries(const std::filesystem::path& dir) {
  std::vector<std::string> out;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    const std::string n = e.path().filename().string();
    if (n.find(".tmp-") != std::string::npos) out.push_back(n);
  }
  return out;
}

}  // namespace tetrig::test
