// Reads the --dump file of tetrig-shm-cat (tools/tetrig_shm_cat.c, docs/shm.md section 7):
// "TSHMDMP1", then per frame: instance u64, frame id u64, vertex count u32, reserved u32 (0),
// vertex_count x 3 float32, all little-endian. Shared by the shared-memory and end-to-end tests.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace tetrig::test {

struct DumpRecord {
  std::uint64_t instance = 0, frame_id = 0;
  std::vector<float> positions;
};

// The records of a dump; `ok` is false for a bad magic, a truncated record or a non-zero reserved word.
inline std::vector<DumpRecord> parseDump(const std::string& bytes, bool& ok) {
  std::vector<DumpRecord> out;
  ok = bytes.size() >= 8 && bytes.compare(0, 8, "TSHMDMP1") == 0;
  std::size_t at = 8;
  while (ok && at < bytes.size()) {
    if (bytes.size() - at < 24) {
      ok = false;
      break;
    }
    DumpRecord rec;
    std::uint32_t vertices = 0, reserved = 1;
    std::memcpy(&rec.instance, bytes.data() + at, 8);
    std::memcpy(&rec.frame_id, bytes.data() + at + 8, 8);
    std::memcpy(&vertices, bytes.data() + at + 16, 4);
    std::memcpy(&reserved, bytes.data() + at + 20, 4);
    at += 24;
    if (reserved != 0 || bytes.size() - at < static_cast<std::size_t>(vertices) * 12) {
      ok = false;
      break;
    }
    rec.positions.resize(static_cast<std::size_t>(vertices) * 3);
    std::memcpy(rec.positions.data(), bytes.data() + at, rec.positions.size() * sizeof(float));
    at += rec.positions.size() * sizeof(float);
    out.push_back(std::move(rec));
  }
  return out;
}

}  // namespace tetrig::test
