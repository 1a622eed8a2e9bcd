// libFuzzer target for the rig file loader (tetrig::parseRig). The first input byte selects
// whether the checksum is verified (odd) or skipped (even), so the fuzzer also reaches the
// section parsers behind the CRC. Any exception other than RigFileError, any crash or any
// sanitizer report is a bug. Build: cmake --preset fuzz && cmake --build --preset fuzz;
// run: build/fuzz/runtime/fuzz_rig_file -max_total_time=60 [corpus dir].
#include "tetrig/rig_file.hpp"

#include <cstddef>
#include <cstdint>
#include <span>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  tetrig::RigParseOptions options;
  options.verify_checksum = (data[0] & 1u) != 0;
  try {
    const tetrig::Rig rig = tetrig::parseRig(std::span<const std::uint8_t>(data + 1, size - 1), "fuzz.rig", options);
    // An accepted rig must be consistent and serialise again.
    if (!tetrig::validateRig(rig).empty()) __builtin_trap();
    (void)tetrig::serializeRig(rig);
  } catch (const tetrig::RigFileError&) {
  }
  return 0;
}
