// Terminal-safe text (runtime/internal/tetrig/printable_text.hpp): what is escaped (C0, DEL, C1 raw
// and UTF-8-encoded, malformed UTF-8 of every kind RFC 3629 forbids, line separators and bidi
// controls), what is kept (ASCII, well-formed non-ASCII UTF-8, backslashes), the cut at a
// character boundary, and that no output of any input holds a byte a terminal acts on.
#include "tetrig/printable_text.hpp"

#include <gtest/gtest.h>

#include <random>
#include <string>

namespace tetrig {
namespace {

using namespace std::string_literals;

// True when `s` holds a C0 control, DEL or a byte 0x80-0x9f outside a well-formed sequence, or a
// well-formed U+0080..U+009F: the bytes a terminal may act on.
bool holdsControlBytes(const std::string& s) {
  for (std::size_t i = 0; i < s.size(); ++i) {
    const auto b = static_cast<unsigned char>(s[i]);
    if (b < 0x20 || b == 0x7F) return true;
    if (b == 0xC2 && i + 1 < s.size() && static_cast<unsigned char>(s[i + 1]) <= 0x9F) return true;
  }
  return !isWellFormedUtf8(s);
}

TEST(PrintableText, EscapesC0ControlsAndDel) {
  EXPECT_EQ(printableText("evil\x1b[2J\nname"), "evil\\x1b[2J\\nname");
  EXPECT_EQ(printableText("a\tb\rc"), "a\\tb\\rc");
  EXPECT_EQ(printableText("\x07\x7f"s), "\\x07\\x7f");
  EXPECT_EQ(printableText("nul\0byte"s), "nul\\x00byte");
  EXPECT_EQ(printableText("\x1b]0;title\x07"), "\\x1b]0;title\\x07");  // OSC: retitles the window
}

TEST(PrintableText, EscapesC1ControlsRawAndEncoded) {
  EXPECT_EQ(printableText("a\x9b" "31mb"), "a\\x9b31mb");       // raw CSI byte: not UTF-8 on its own
  EXPECT_EQ(printableText("a\xc2\x9b" "31mb"), "a\\xc2\\x9b31mb");  // U+009B, well-formed but a control
  EXPECT_EQ(printableText("\xc2\x80\xc2\x9f"), "\\xc2\\x80\\xc2\\x9f");
  EXPECT_EQ(printableText("\xc2\xa0"), "\xc2\xa0");  // U+00A0, the first code point after C1: kept
}

TEST(PrintableText, EscapesMalformedUtf8) {
  EXPECT_EQ(printableText("H\xfc" "fte"), "H\\xfcfte");               // Latin-1, not UTF-8
  EXPECT_EQ(printableText("\xc0\xaf"), "\\xc0\\xaf");                 // overlong '/'
  EXPECT_EQ(printableText("\xe0\x80\xaf"), "\\xe0\\x80\\xaf");        // overlong 3-byte
  EXPECT_EQ(printableText("\xed\xa0\x80"), "\\xed\\xa0\\x80");        // surrogate U+D800
  EXPECT_EQ(printableText("\xf4\x90\x80\x80"), "\\xf4\\x90\\x80\\x80");  // above U+10FFFF
  EXPECT_EQ(printableText("\xf8\x88\x80\x80\x80"), "\\xf8\\x88\\x80\\x80\\x80");
  EXPECT_EQ(printableText("ab\xe2\x82"), "ab\\xe2\\x82");             // truncated at the end
  EXPECT_EQ(printableText("\xe2\x82" "x"), "\\xe2\\x82x");             // truncated in the middle
  EXPECT_FALSE(isWellFormedUtf8("H\xfc" "fte"));
  EXPECT_FALSE(isWellFormedUtf8("\xed\xa0\x80"));
  EXPECT_FALSE(isWellFormedUtf8("\xf4\x90\x80\x80"));
  EXPECT_FALSE(isWellFormedUtf8("\xe2\x82"));
}

TEST(PrintableText, EscapesLineSeparatorsAndBidiControls) {
  EXPECT_EQ(printableText("a\xe2\x80\xa8" "b"), "a\\xe2\\x80\\xa8b");  // U+2028
  EXPECT_EQ(printableText("a\xe2\x80\xae" "b"), "a\\xe2\\x80\\xaeb");  // U+202E right-to-left override
  EXPECT_EQ(printableText("\xe2\x81\xa6"), "\\xe2\\x81\\xa6");          // U+2066
  EXPECT_EQ(printableText("\xe2\x80\x8f"), "\\xe2\\x80\\x8f");          // U+200F
  EXPECT_EQ(printableText("\xe2\x80\x94"), "\xe2\x80\x94");             // U+2014 em dash: kept
}

TEST(PrintableText, KeepsPrintableTextAsItIs) {
  EXPECT_EQ(printableText(""), "");
  EXPECT_EQ(printableText("LFHD subject:RWRA 0-9 ~!@#$%^&*()"), "LFHD subject:RWRA 0-9 ~!@#$%^&*()");
  EXPECT_EQ(printableText("H\xc3\xbc" "fte \xe6\x89\x8b \xf0\x9f\x96\x90"), "H\xc3\xbc" "fte \xe6\x89\x8b \xf0\x9f\x96\x90");
  EXPECT_EQ(printableText("back\\slash \\x1b"), "back\\slash \\x1b");  // for reading, not decoding
  EXPECT_TRUE(isWellFormedUtf8(""));
  EXPECT_TRUE(isWellFormedUtf8("H\xc3\xbc" "fte \xf4\x8f\xbf\xbf"));  // U+10FFFF is the last code point
  EXPECT_TRUE(isWellFormedUtf8("ctl\x1b\n"));                          // well-formed, though not printable
}

TEST(PrintableText, CutsLongTextAtACharacterBoundary) {
  EXPECT_EQ(printableText(std::string(300, 'a'), 256), std::string(256, 'a') + "... (300 bytes)");
  EXPECT_EQ(printableText(std::string(256, 'a'), 256), std::string(256, 'a'));
  // A 2-byte character that would straddle the limit is left out whole.
  EXPECT_EQ(printableText("abc\xc3\xbc" "d", 4), "abc... (6 bytes)");
  // So is an escape: never a partial "\x1".
  EXPECT_EQ(printableText("abc\x1b" "d", 5), "abc... (5 bytes)");
  EXPECT_EQ(printableText("abc\x1b" "d", 7), "abc\\x1b... (5 bytes)");
}

TEST(PrintableText, NoInputGivesControlBytes) {
  // Random byte strings, biased to the interesting ranges: the output never holds a byte a
  // terminal acts on, is well-formed UTF-8, and equals the input when the input was clean.
  std::mt19937 rng(2024);
  const unsigned char interesting[] = {0x00, 0x07, 0x0a, 0x1b, 0x5c, 0x7f, 0x80, 0x9b, 0x9f, 0xa0, 0xbf, 0xc0, 0xc2,
                                       0xc3, 0xdf, 0xe0, 0xe2, 0xed, 0xef, 0xf0, 0xf4, 0xf5, 0xff, 'a', '['};
  for (int trial = 0; trial < 20000; ++trial) {
    std::string in(1 + rng() % 12, '\0');
    for (char& c : in) c = static_cast<char>(rng() % 2 ? interesting[rng() % sizeof interesting] : rng() % 256);
    const std::string out = printableText(in);
    ASSERT_FALSE(holdsControlBytes(out)) << "input bytes: " << printableText(in);
    if (!holdsControlBytes(in) && in.find("\xe2\x80") == std::string::npos && in.find("\xe2\x81") == std::string::npos) {
      EXPECT_EQ(out, in);
    }
    const std::string cut = printableText(in, 1 + rng() % 8);
    ASSERT_FALSE(holdsControlBytes(cut));
  }
}

}  // namespace
}  // namespace tetrig
