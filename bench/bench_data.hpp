// Where benchmarks find the real data: $TETRIG_DATA_DIR if set, else
// TETRIG_SOURCE_DIR/../shared/data (the same lookup as tests/support/test_data.hpp, without
// GoogleTest). Benchmarks that need a file call state.SkipWithError(benchDataMissing(path)).
#pragma once

#include <cstdlib>
#include <filesystem>
#include <string>

namespace tetrig::bench {

inline std::filesystem::path benchDataRoot() {
  if (const char* env = std::getenv("TETRIG_DATA_DIR"); env != nullptr && env[0] != '\0') {
    return std::filesystem::path(env);
  }
  return std::filesystem::path(TETRIG_SOURCE_DIR) / ".." / "shared" / "data";
}

inline std::filesystem::path benchDataPath(const std::string& relative) { return benchDataRoot() / relative; }

// The message for a missing file: what is missing and how to provide it.
inline std::string benchDataMissing(const std::filesystem::path& path) {
  return "test data not found: " + path.string() +
         " (place ../shared/data beside the checkout or set TETRIG_DATA_DIR)";
}

}  // namespace tetrig::bench
