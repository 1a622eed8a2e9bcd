// Atomic file replacement: write a temporary file beside the target, fsync it, rename it over the
// target, fsync the directory. Readers see the old file or the whole new one, never a partial
// one; on any failure the temporary file is removed and the target is untouched. A new file gets
// 0666 minus the umask, an existing one keeps its mode (tetrig::AtomicFile, tetrig/atomic_file.hpp,
// has the details).
// Offline, POSIX, any thread, throws RigBuildError naming the path and the system error.
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>

namespace tetrig::rigbuild {

void writeFileAtomically(const std::filesystem::path& path, std::span<const std::uint8_t> bytes);

}  // namespace tetrig::rigbuild
