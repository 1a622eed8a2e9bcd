#include "test_data.hpp"

#include <cstdlib>
#include <cstring>

namespace tetrig::test {

std::filesystem::path dataRoot() {
  if (const char* env = std::getenv("TETRIG_DATA_DIR"); env != nullptr && env[0] != '\0') {
    return std::filesystem::path(env);
  }
  return std::filesystem::path(TETRIG_SOURCE_DIR) / ".." / "shared" / "data";
}

std::filesystem::path dataPath(const std::string& relative) { return dataRoot() / relative; }

bool runningInCi() {
  const char* ci = std::getenv("CI");
  return ci != nullptr && (std::strcmp(ci, "true") == 0 || std::strcmp(ci, "1") == 0);
}

}  // namespace tetrig::test
