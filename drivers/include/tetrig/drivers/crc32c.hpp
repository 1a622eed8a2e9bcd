// CRC-32C (Castagnoli), the checksum of the tetrig marker-stream protocol (docs/protocol.md).
//
// Parameters (Rocksoft/Williams model, "CRC-32/ISCSI" in the CRC catalogue):
//   width 32, polynomial 0x1EDC6F41 (reflected 0x82F63B78), init 0xFFFFFFFF, input and output
//   reflected, xor-out 0xFFFFFFFF; check value crc32c("123456789") = 0xE3069283.
#pragma once

#include <cstdint>
#include <span>

namespace tetrig::drivers {

inline constexpr std::uint32_t kCrc32cCheck = 0xE3069283u;  // crc32c of the ASCII "123456789"

// CRC-32C of `data`. To checksum data given in pieces, pass the previous result as `previous`
// (crc32c(ab) == crc32c(b, crc32c(a))); start with 0. Any thread; no allocation; table-driven
// (slicing by 8, tables built at compile time).
[[nodiscard]] std::uint32_t crc32c(std::span<const std::uint8_t> data, std::uint32_t previous = 0) noexcept;

}  // namespace tetrig::drivers
