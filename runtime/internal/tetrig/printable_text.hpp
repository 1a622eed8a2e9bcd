// Text read from a file (a rig's name and unit, marker labels, region and pose-sensor names, C3D
// labels, JSON keys), made safe to print on a terminal. A file is input from anyone: printed raw,
// a name holding "\x1b[2J" clears the user's screen, and other escape sequences retitle the
// window, rewrite the clipboard or hide text; a newline forges an extra output line. Every
// program that prints file-supplied text passes it through printableText first (docs/rig-format.md,
// "Printing a rig").
//
// Escaped (each byte shown as "\xNN", two lower-case hex digits; "\n", "\r", "\t" for those three):
//   - C0 controls 0x00-0x1f and DEL 0x7f;
//   - C1 controls: raw bytes 0x80-0x9f (never valid UTF-8 on their own) and U+0080..U+009F
//     written in UTF-8 (C2 80 .. C2 9F), which some terminals act on as 8-bit controls;
//   - every byte that is not part of well-formed UTF-8 (RFC 3629: no overlong forms, no UTF-16
//     surrogates, nothing above U+10FFFF, no truncated sequence);
//   - the Unicode line and paragraph separators (U+2028, U+2029) and the bidirectional controls
//     (U+200E, U+200F, U+202A..U+202E, U+2066..U+2069), which forge line breaks or reorder what
//     is shown.
// Everything else is kept as it is, including well-formed non-ASCII UTF-8 ("Hüfte") and
// backslashes: the result is for reading, not for decoding back.
//
// Allocates (the result); no state; any thread. Not for the per-frame path.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace tetrig {

// `text` with the sequences listed above escaped. When `max_bytes` > 0 and the escaped text is
// longer, it is cut at a character (or escape) boundary at or before `max_bytes` bytes and
// "... (N bytes)" is appended, N being the length of `text` itself.
std::string printableText(std::string_view text, std::size_t max_bytes = 0);

// True when `text` is well-formed UTF-8 (RFC 3629; the empty string is). Control characters are
// well-formed: this says nothing about printing.
bool isWellFormedUtf8(std::string_view text) noexcept;

}  // namespace tetrig
