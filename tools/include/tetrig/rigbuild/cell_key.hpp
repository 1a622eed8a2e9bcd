// A key of three 64-bit integers (a cell of a uniform grid, or bit patterns of coordinates) and
// its hash, for the rig builder's hash maps over 3D positions (weldVertices, matchFileVertices).
#pragma once

#include <cstddef>
#include <cstdint>

namespace tetrig::rigbuild {

struct CellKey {
  std::int64_t x, y, z;
  bool operator==(const CellKey& o) const { return x == o.x && y == o.y && z == o.z; }
};

struct CellHash {
  std::size_t operator()(const CellKey& k) const {
    std::uint64_t h = static_cast<std::uint64_t>(k.x) * 0x9E3779B97F4A7C15ull;
    h ^= static_cast<std::uint64_t>(k.y) * 0xC2B2AE3D27D4EB4Full + (h << 6) + (h >> 2);
    h ^= static_cast<std::uint64_t>(k.z) * 0x165667B19E3779F9ull + (h << 6) + (h >> 2);
    return static_cast<std::size_t>(h);
  }
};

}  // namespace tetrig::rigbuild
