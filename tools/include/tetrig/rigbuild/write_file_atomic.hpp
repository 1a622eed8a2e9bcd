// Atomic file replacement: write a temporary file beside the target, fsync it, rename it over the
// target, fsync the directory. Readers see the old file or the whole new one, never a partial
// one; on any failure the temporary file is removed and the target is untouched.
// Offline, POSIX, any thread, throws RigBuildError naming the path and the system error.
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>

namespace tetrig::rigbuild {

void writeFileAtomically(const std::filesystem::path& path, std::span<const std::uint8_t> bytes);

}  // namespace tetrig::rigbuild
