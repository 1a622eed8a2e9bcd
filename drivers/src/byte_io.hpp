// Little-endian readers and writers for the protocol decoders and encoders (private to drivers/).
// Byte-by-byte assembly: correct on any host byte order, no alignment requirement, no allocation.
// Callers check bounds before calling.
#pragma once

#include <bit>
#include <cstdint>

namespace tetrig::drivers::detail {

inline std::uint16_t loadU16(const std::uint8_t* p) noexcept {
  return static_cast<std::uint16_t>(p[0] | (p[1] << 8));
}
inline std::int16_t loadI16(const std::uint8_t* p) noexcept { return static_cast<std::int16_t>(loadU16(p)); }
inline std::uint32_t loadU32(const std::uint8_t* p) noexcept {
  return static_cast<std::uint32_t>(p[0]) | static_cast<std::uint32_t>(p[1]) << 8 |
         static_cast<std::uint32_t>(p[2]) << 16 | static_cast<std::uint32_t>(p[3]) << 24;
}
inline std::uint64_t loadU64(const std::uint8_t* p) noexcept {
  return static_cast<std::uint64_t>(loadU32(p)) | static_cast<std::uint64_t>(loadU32(p + 4)) << 32;
}
inline float loadF32(const std::uint8_t* p) noexcept { return std::bit_cast<float>(loadU32(p)); }

inline void storeU16(std::uint8_t* p, std::uint16_t v) noexcept {
  p[0] = static_cast<std::uint8_t>(v);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}
inline void storeI16(std::uint8_t* p, std::int16_t v) noexcept { storeU16(p, static_cast<std::uint16_t>(v)); }
inline void storeU32(std::uint8_t* p, std::uint32_t v) noexcept {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
inline void storeU64(std::uint8_t* p, std::uint64_t v) noexcept {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
inline void storeF32(std::uint8_t* p, float v) noexcept { storeU32(p, std::bit_cast<std::uint32_t>(v)); }

}  // namespace tetrig::drivers::detail
