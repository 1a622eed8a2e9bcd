// Human-readable summary of a rig (`tetrig inspect`): counts, bounding box, handles, markers,
// alignment, memory. Text from the rig (names, unit, labels, axes) is escaped for a terminal
// (tetrig/printable_text.hpp) and cut at 256 bytes. Offline, any thread, allocates.
#pragma once

#include "tetrig/rig_file.hpp"

#include <cstdint>
#include <string>

namespace tetrig::rigbuild {

// `file_bytes` is the size of the rig file (0 if unknown). `list_markers`: one line per marker.
std::string describeRig(const Rig& rig, std::int64_t file_bytes, bool list_markers);

}  // namespace tetrig::rigbuild
