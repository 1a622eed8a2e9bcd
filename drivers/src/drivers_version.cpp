// The drivers library's version: the project's (tetrig/version.h, generated from the top CMakeLists.txt).
#include "tetrig/version.h"

namespace tetrig::drivers {
const char* version() { return TETRIG_VERSION_STRING; }
}  // namespace tetrig::drivers
