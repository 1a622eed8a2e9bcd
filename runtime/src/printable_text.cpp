// Terminal-safe text (tetrig/printable_text.hpp). UTF-8 well-formedness follows RFC 3629,
// section 4 (the byte-sequence table): a lead byte fixes the length and the allowed range of the
// second byte (which excludes overlong forms, surrogates and code points above U+10FFFF); every
// further byte is a continuation byte 0x80-0xBF.
#include "tetrig/printable_text.hpp"

#include <cstdint>

namespace tetrig {
namespace {

// Length of the well-formed UTF-8 sequence starting at text[i] (1..4) and its code point, or 0
// when the bytes there do not form one.
std::size_t decodeUtf8(std::string_view text, std::size_t i, std::uint32_t& code_point) noexcept {
  const auto byte = [&text](std::size_t at) { return static_cast<std::uint8_t>(text[at]); };
  const std::uint8_t b0 = byte(i);
  if (b0 < 0x80) {
    code_point = b0;
    return 1;
  }
  std::size_t length = 0;
  std::uint8_t lo = 0x80, hi = 0xBF;  // allowed range of the second byte
  if (b0 >= 0xC2 && b0 <= 0xDF) {
    length = 2;
  } else if (b0 >= 0xE0 && b0 <= 0xEF) {
    length = 3;
    if (b0 == 0xE0) lo = 0xA0;  // no overlong 3-byte forms
    if (b0 == 0xED) hi = 0x9F;  // no surrogates U+D800..U+DFFF
  } else if (b0 >= 0xF0 && b0 <= 0xF4) {
    length = 4;
    if (b0 == 0xF0) lo = 0x90;  // no overlong 4-byte forms
    if (b0 == 0xF4) hi = 0x8F;  // nothing above U+10FFFF
  } else {
    return 0;  // 0x80-0xC1 (continuation bytes, overlong 2-byte leads) and 0xF5-0xFF
  }
  if (text.size() - i < length) return 0;
  const std::uint8_t b1 = byte(i + 1);
  if (b1 < lo || b1 > hi) return 0;
  std::uint32_t cp = b0 & (length == 2 ? 0x1Fu : length == 3 ? 0x0Fu : 0x07u);
  for (std::size_t k = 1; k < length; ++k) {
    const std::uint8_t b = byte(i + k);
    if (b < 0x80 || b > 0xBF) return 0;
    cp = (cp << 6) | (b & 0x3Fu);
  }
  code_point = cp;
  return length;
}

// Characters a terminal acts on or that change what the line looks like.
bool isControlCodePoint(std::uint32_t cp) noexcept {
  return cp < 0x20 || cp == 0x7F || (cp >= 0x80 && cp <= 0x9F) || cp == 0x200E || cp == 0x200F ||
         (cp >= 0x2028 && cp <= 0x202E) || (cp >= 0x2066 && cp <= 0x2069);
}

void appendEscapedByte(std::string& out, std::uint8_t b) {
  static constexpr char kHex[] = "0123456789abcdef";
  switch (b) {
    case '\n': out += "\\n"; return;
    case '\r': out += "\\r"; return;
    case '\t': out += "\\t"; return;
    default:
      out += "\\x";
      out += kHex[b >> 4];
      out += kHex[b & 0x0F];
  }
}

}  // namespace

std::string printableText(std::string_view text, std::size_t max_bytes) {
  std::string out;
  out.reserve(text.size());
  std::string piece;
  for (std::size_t i = 0; i < text.size();) {
    std::uint32_t cp = 0;
    std::size_t length = decodeUtf8(text, i, cp);
    piece.clear();
    if (length == 0) {
      appendEscapedByte(piece, static_cast<std::uint8_t>(text[i]));
      length = 1;
    } else if (isControlCodePoint(cp)) {
      for (std::size_t k = 0; k < length; ++k) appendEscapedByte(piece, static_cast<std::uint8_t>(text[i + k]));
    } else {
      piece.assign(text.substr(i, length));
    }
    if (max_bytes > 0 && out.size() + piece.size() > max_bytes) {
      out += "... (" + std::to_string(text.size()) + " bytes)";
      return out;
    }
    out += piece;
    i += length;
  }
  return out;
}

bool isWellFormedUtf8(std::string_view text) noexcept {
  for (std::size_t i = 0; i < text.size();) {
    std::uint32_t cp = 0;
    const std::size_t length = decodeUtf8(text, i, cp);
    if (length == 0) return false;
    i += length;
  }
  return true;
}

}  // namespace tetrig
