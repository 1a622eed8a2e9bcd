// Atomic write of a whole buffer through tetrig::AtomicFile (temporary + fsync + rename +
// directory fsync; the project's one file writer, runtime/include/tetrig/atomic_file.hpp).
#include "tetrig/rigbuild/write_file_atomic.hpp"

#include "tetrig/atomic_file.hpp"
#include "tetrig/rigbuild/surface_mesh.hpp"

namespace tetrig::rigbuild {

void writeFileAtomically(const std::filesystem::path& path, std::span<const std::uint8_t> bytes) {
  try {
    AtomicFile file(path);
    file.write(bytes.data(), bytes.size());
    file.commit();
  } catch (const AtomicFileError& e) {
    throw RigBuildError(e.what());
  }
}

}  // namespace tetrig::rigbuild
