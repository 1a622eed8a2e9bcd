// Where the real test data lives (../shared/data beside the checkout, or $TETRIG_DATA_DIR).
// Tests that need a file call TETRIG_REQUIRE_DATA(path): when the file is absent the test is
// reported SKIPPED with the full path it looked for and the variable to set; in CI
// (environment variable CI=true) an absent file is a failure instead, since CI has the data.
#pragma once

#include <filesystem>
#include <string>

namespace tetrig::test {

// Root of the shared data folder: $TETRIG_DATA_DIR if set, else <source>/../shared/data.
std::filesystem::path dataRoot();

// dataRoot() / relative.
std::filesystem::path dataPath(const std::string& relative);

// True when running under CI (CI=true in the environment).
bool runningInCi();

}  // namespace tetrig::test

// Resolves `relative` under the data root into `var`; skips (or fails under CI) when absent.
#define TETRIG_REQUIRE_DATA(var, relative)                                                        \
  const std::filesystem::path var = ::tetrig::test::dataPath(relative);                          \
  if (!std::filesystem::exists(var)) {                                                            \
    if (::tetrig::test::runningInCi()) {                                                          \
      FAIL() << "test data missing in CI: " << var.string() << " (set TETRIG_DATA_DIR)";          \
    }                                                                                             \
    GTEST_SKIP() << "test data not found: " << var.string()                                       \
                 << " (place ../shared/data beside the checkout or set TETRIG_DATA_DIR)";         \
  }
