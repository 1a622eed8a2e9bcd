// libFuzzer target for the rig file loader (tetrig::parseRig). The first input byte selects
// whether the checksum is verified (odd) or skipped (even), so the fuzzer also reaches the
// layout checks and section parsers behind the CRC. Any exception other than RigFileError, any
// crash or any sanitizer report is a bug; so is an accepted rig that fails validation, does not
// serialise, or does not read back to the same bytes (the writer's layout is the only one the
// loader accepts for the sections it knows). Seeds (runtime/fuzz/corpus/rig_file): serializeRig
// of a one-tet rig and of a two-tet rig with one of every section (marker, region, pose sensor,
// point handle, rigid group, stiffness), and of that rig with itself as its coarse level (CRSE: a
// rig file inside the rig file), each with the checksum on and off.
// Build: cmake --preset fuzz && cmake --build --preset fuzz --target fuzz_rig_file;
// run: build/fuzz/runtime/fuzz_rig_file -max_total_time=60 runtime/fuzz/corpus/rig_file.
#include "tetrig/printable_text.hpp"
#include "tetrig/rig_file.hpp"

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  tetrig::RigParseOptions options;
  options.verify_checksum = (data[0] & 1u) != 0;
  try {
    const tetrig::Rig rig = tetrig::parseRig(std::span<const std::uint8_t>(data + 1, size - 1), "fuzz.rig", options);
    // An accepted rig must be consistent, serialise again, and read back to the same bytes.
    if (!tetrig::validateRig(rig).empty()) __builtin_trap();
    const std::vector<std::uint8_t> bytes = tetrig::serializeRig(rig);
    const tetrig::Rig back = tetrig::parseRig(bytes, "again.rig");
    if (tetrig::serializeRig(back) != bytes) __builtin_trap();
    // Its text prints without a byte a terminal acts on.
    const std::string shown = tetrig::printableText(rig.name) + tetrig::printableText(rig.unit);
    for (const char c : shown) {
      if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) == 0x7F) __builtin_trap();
    }
  } catch (const tetrig::RigFileError&) {
  }
  return 0;
}
