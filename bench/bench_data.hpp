// Where benchmarks find the real data: $TETRIG_DATA_DIR if set, else
// TETRIG_SOURCE_DIR/../shared/data (the same lookup as tests/support/test_data.hpp, without
// GoogleTest). Benchmarks that need a file call state.SkipWithError(benchDataMissing(path)).
#pragma once

#include <cstdlib>
#include <exception>
#include <filesystem>
#include <memory>
#include <stdexcept>
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

// `relative`'s path under the data root; throws std::runtime_error(benchDataMissing) when absent.
inline std::filesystem::path requireBenchData(const std::string& relative) {
  auto path = benchDataPath(relative);
  if (!std::filesystem::exists(path)) throw std::runtime_error(benchDataMissing(path));
  return path;
}

// A scene shared by several benchmarks, built on first use (one per call site: the static state
// belongs to the instantiation, and each lambda has its own type). `build()` returns it as a
// std::unique_ptr<T> or throws; after a throw every call returns null with the message in `error`,
// and the benchmark calls state.SkipWithError with it.
template <class T, class Build>
const T* buildOnce(Build&& build, std::string& error) {
  static std::unique_ptr<T> scene;
  static std::string build_error;
  static bool tried = false;
  if (!tried) {
    tried = true;
    try {
      scene = build();
    } catch (const std::exception& e) {
      build_error = e.what();
    }
  }
  error = build_error;
  return scene.get();
}

}  // namespace tetrig::bench
