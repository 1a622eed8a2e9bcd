// Tests of the C3D reader: generated files in every processor/storage variant (the spec is the
// truth), the documented arbitration rules, truncation at every length, random corruption, and
// the real c3d.org / HDM05 / BTK files (facts from ../shared/data/NOTES.md and the format).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "c3d_test_writer.hpp"
#include "tetrig/drivers/c3d_reader.hpp"
#include "test_data.hpp"

namespace tetrig::drivers {
namespace {

using test::smallSpec;
using test::TestC3DSpec;
using test::writeTestC3D;

C3DClip parseBytes(const std::vector<std::uint8_t>& b, const char* name = "gen.c3d") {
  return C3DClip::parse(b, name);
}

void expectMatchesSpec(const C3DClip& clip, const TestC3DSpec& s) {
  ASSERT_EQ(clip.pointCount(), static_cast<int>(s.labels.size()));
  ASSERT_EQ(clip.frameCount(), s.frames);
  EXPECT_DOUBLE_EQ(clip.frameRate(), s.rate);
  EXPECT_EQ(clip.isFloat(), s.floating);
  EXPECT_FLOAT_EQ(clip.pointScale(), s.scale);
  EXPECT_EQ(clip.labels(), s.labels);
  for (std::size_t f = 0; f < s.frames; ++f) {
    for (std::size_t p = 0; p < s.labels.size(); ++p) {
      const std::size_t k = f * s.labels.size() + p;
      const int pi = static_cast<int>(p);
      ASSERT_EQ(clip.isValid(f, pi), static_cast<bool>(s.valid[k])) << "frame " << f << " point " << p;
      if (!s.valid[k]) {
        EXPECT_FLOAT_EQ(clip.residual(f, pi), -1.0f);
        continue;
      }
      for (int c = 0; c < 3; ++c) {
        EXPECT_FLOAT_EQ(clip.positions(f)[p * 3 + static_cast<std::size_t>(c)], s.xyz[k][static_cast<std::size_t>(c)])
            << "frame " << f << " point " << p << " axis " << c;
      }
      // The writer stores residual byte 3 (cameras 0x02): residual = 3 * |scale|.
      EXPECT_FLOAT_EQ(clip.residual(f, pi), 3.0f * s.scale);
    }
  }
}

struct Variant {
  C3DProcessor proc;
  bool floating;
};
const Variant kVariants[] = {{C3DProcessor::kIntel, true}, {C3DProcessor::kIntel, false}, {C3DProcessor::kDec, true},
                             {C3DProcessor::kDec, false},  {C3DProcessor::kMips, true},   {C3DProcessor::kMips, false}};

TEST(C3DVax, KnownValues) {
  // VAX F_floating 1.0 is the longword 0x00004080 (stored bytes 80 40 00 00); 0.5 is 0x00004000;
  // -2.0 is 0x0000C100. Exponent 0 with sign 0 is exactly zero.
  const std::uint8_t one[4] = {0x80, 0x40, 0x00, 0x00};
  const std::uint8_t half[4] = {0x00, 0x40, 0x00, 0x00};
  const std::uint8_t minus_two[4] = {0x00, 0xC1, 0x00, 0x00};
  const std::uint8_t zero[4] = {0x00, 0x00, 0x12, 0x34};
  const std::uint8_t reserved[4] = {0x00, 0x80, 0x00, 0x00};
  EXPECT_EQ(decodeVaxFloat(one), 1.0f);
  EXPECT_EQ(decodeVaxFloat(half), 0.5f);
  EXPECT_EQ(decodeVaxFloat(minus_two), -2.0f);
  EXPECT_EQ(decodeVaxFloat(zero), 0.0f);
  EXPECT_TRUE(std::isnan(decodeVaxFloat(reserved)));
  for (float v : {1.0f, -0.0833333358f, 60.0f, 1234.5678f, -1e-20f, 3e30f}) {
    std::uint8_t b[4];
    encodeVaxFloat(v, b);
    EXPECT_EQ(decodeVaxFloat(b), v);
  }
}

TEST(C3DReader, GeneratedVariantsDecodeToTheSpec) {
  for (const Variant& v : kVariants) {
    SCOPED_TRACE(std::to_string(static_cast<int>(v.proc)) + (v.floating ? " float" : " int"));
    TestC3DSpec s = smallSpec(v.proc, v.floating, 5, 7);
    s.analog_words = 6;
    const auto bytes = writeTestC3D(s);
    const C3DClip clip = parseBytes(bytes);
    EXPECT_EQ(clip.processor(), v.proc);
    EXPECT_TRUE(clip.hasParameters());
    EXPECT_TRUE(clip.warnings().empty()) << clip.warnings().front();
    EXPECT_EQ(clip.units(), "mm");
    EXPECT_DOUBLE_EQ(clip.unitsToMm(), 1.0);
    expectMatchesSpec(clip, s);
  }
}

// ---- invalid-sample encodings (the residual word) ----

// One point, one frame per case: each case is a residual word, a position, and what the reader
// must make of it.
struct WordCase {
  double word;                   // float files: the float written; int files: its low 16 bits
  std::array<float, 3> xyz;
  C3DSample expected;            // with the default options
  float residual_byte = 0.0f;    // valid cases: the expected residual / |scale|
};

std::vector<WordCase> wordCases(bool floating, C3DProcessor proc) {
  const std::array<float, 3> at{12.5f, -3.0f, 800.0f};
  const std::array<float, 3> origin{0.0f, 0.0f, 0.0f};
  std::vector<WordCase> c = {
      {-1.0, at, C3DSample::kInvalid},            // the standard's invalid word
      {-32768.0, at, C3DSample::kInvalid},        // 0x8000: any word with bit 15 set
      {0.0, at, C3DSample::kValid, 0.0f},         // residual 0 away from the origin: a real point
      {515.0, at, C3DSample::kValid, 3.0f},       // cameras 0x02, residual 3
      {32767.0, at, C3DSample::kValid, 255.0f},   // the largest valid word
      {0.0, origin, C3DSample::kZeroGap},         // zeros for a gap
      {512.0, origin, C3DSample::kZeroGap},       // cameras set but residual 0 at the origin
      {515.0, origin, C3DSample::kValid, 3.0f},   // a non-zero residual keeps the origin valid
  };
  if (floating) {
    // The same invalid words as their unsigned 16-bit values, and numbers no word can be.
    c.push_back({65535.0, at, C3DSample::kInvalid});   // -1 stored unsigned
    c.push_back({32768.0, at, C3DSample::kInvalid});   // 0x8000 unsigned
    c.push_back({33283.0, at, C3DSample::kInvalid});   // 0x8203 unsigned (bit 15 and a residual)
    c.push_back({70000.0, at, C3DSample::kInvalid});   // not a 16-bit word
    c.push_back({-0.5, at, C3DSample::kInvalid});
    c.push_back({3.75, at, C3DSample::kValid, 3.0f});  // a fraction: its integer part is the word
    if (proc != C3DProcessor::kDec) {                  // VAX floats have no NaN/Inf encoding here
      c.push_back({std::numeric_limits<double>::infinity(), at, C3DSample::kNonFinite});
      c.push_back({std::numeric_limits<double>::quiet_NaN(), at, C3DSample::kNonFinite});
      c.push_back({-std::numeric_limits<double>::infinity(), at, C3DSample::kInvalid});
    }
  } else {
    c.push_back({0xffff, at, C3DSample::kInvalid});    // -1
    c.push_back({0x8203, at, C3DSample::kInvalid});    // bit 15 with cameras and a residual
    c.push_back({0x00ff, origin, C3DSample::kValid, 255.0f});
  }
  return c;
}

TestC3DSpec wordSpec(const Variant& v, const std::vector<WordCase>& cases) {
  TestC3DSpec s = smallSpec(v.proc, v.floating, cases.size(), 1);
  for (std::size_t i = 0; i < cases.size(); ++i) {
    s.xyz[i] = cases[i].xyz;
    s.fourth_words.push_back(cases[i].word);
  }
  return s;
}

TEST(C3DReader, InvalidSampleEncodingsInEveryVariant) {
  for (const Variant& v : kVariants) {
    SCOPED_TRACE(std::to_string(static_cast<int>(v.proc)) + (v.floating ? " float" : " int"));
    const std::vector<WordCase> cases = wordCases(v.floating, v.proc);
    const C3DClip clip = parseBytes(writeTestC3D(wordSpec(v, cases)));
    std::size_t zero_gaps = 0;
    for (std::size_t i = 0; i < cases.size(); ++i) {
      const int p = static_cast<int>(i);
      SCOPED_TRACE("case " + std::to_string(i) + ": word " + std::to_string(cases[i].word));
      EXPECT_EQ(clip.samples(0)[i], cases[i].expected);
      EXPECT_EQ(clip.isValid(0, p), cases[i].expected == C3DSample::kValid);
      zero_gaps += cases[i].expected == C3DSample::kZeroGap ? 1 : 0;
      if (cases[i].expected == C3DSample::kValid) {
        for (std::size_t c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(clip.positions(0)[i * 3 + c], cases[i].xyz[c]);
        EXPECT_FLOAT_EQ(clip.residual(0, p), cases[i].residual_byte * 0.5f);  // |scale| = 0.5
      } else {
        for (std::size_t c = 0; c < 3; ++c) EXPECT_EQ(clip.positions(0)[i * 3 + c], 0.0f);
        EXPECT_EQ(clip.residual(0, p), -1.0f);
      }
    }
    // The zero gaps are counted in one warning that names the option keeping them.
    ASSERT_EQ(clip.warnings().size(), 1u);
    EXPECT_NE(clip.warnings()[0].find(std::to_string(zero_gaps) + " samples at x = y = z = 0"), std::string::npos)
        << clip.warnings()[0];
    EXPECT_NE(clip.warnings()[0].find("keep_zero_points"), std::string::npos);
  }
}

TEST(C3DReader, KeepZeroPointsReadsZeroSamplesAsValid) {
  for (const Variant& v : kVariants) {
    SCOPED_TRACE(std::to_string(static_cast<int>(v.proc)) + (v.floating ? " float" : " int"));
    const std::vector<WordCase> cases = wordCases(v.floating, v.proc);
    C3DReadOptions keep;
    keep.keep_zero_points = true;
    const C3DClip clip = C3DClip::parse(writeTestC3D(wordSpec(v, cases)), "keep.c3d", keep);
    for (std::size_t i = 0; i < cases.size(); ++i) {
      SCOPED_TRACE("case " + std::to_string(i));
      // Only the zero gaps change: they become valid points at the origin with residual 0.
      const C3DSample expected = cases[i].expected == C3DSample::kZeroGap ? C3DSample::kValid : cases[i].expected;
      EXPECT_EQ(clip.samples(0)[i], expected);
      if (cases[i].expected == C3DSample::kZeroGap) {
        EXPECT_EQ(clip.residual(0, static_cast<int>(i)), 0.0f);
        for (std::size_t c = 0; c < 3; ++c) EXPECT_EQ(clip.positions(0)[i * 3 + c], 0.0f);
      }
    }
    EXPECT_TRUE(clip.warnings().empty()) << clip.warnings().front();
  }
}

TEST(C3DReader, NonFiniteFloatsAreInvalidNotCrashes) {
  TestC3DSpec s = smallSpec(C3DProcessor::kIntel, true, 2, 2);
  s.xyz[2] = {std::nanf(""), 1.0f, 2.0f};
  s.valid[2] = true;
  const C3DClip clip = parseBytes(writeTestC3D(s));
  EXPECT_FALSE(clip.isValid(1, 0));
  EXPECT_EQ(clip.samples(1)[0], C3DSample::kNonFinite);
}

TEST(C3DReader, UnitsAreReportedAndConvertible) {
  for (const auto& [units, factor] : std::vector<std::pair<std::string, double>>{
           {"m", 1000.0}, {"cm", 10.0}, {"mm", 1.0}, {"in", 25.4}, {"M ", 1000.0}}) {
    TestC3DSpec s = smallSpec(C3DProcessor::kIntel, true);
    s.units = units;
    const C3DClip clip = parseBytes(writeTestC3D(s));
    EXPECT_DOUBLE_EQ(clip.unitsToMm(), factor) << units;
  }
  TestC3DSpec s = smallSpec(C3DProcessor::kIntel, true);
  s.units = "furlong";
  const C3DClip clip = parseBytes(writeTestC3D(s));
  EXPECT_DOUBLE_EQ(clip.unitsToMm(), 1.0);
  ASSERT_FALSE(clip.warnings().empty());
  EXPECT_NE(clip.warnings().front().find("furlong"), std::string::npos);
}

TEST(C3DReader, PointKindsAndLabelLookup) {
  TestC3DSpec s = smallSpec(C3DProcessor::kIntel, true, 6, 2);
  s.labels = {"subj:LFHD", "*0", "LHipAngles", "RFHD", "subj:*12", "LKneePower"};
  for (const char* extra : {"PELO", "PELA", "PELL", "PELP", "LCLA", "LTIB"}) s.labels.push_back(extra);
  s = [&] {  // regenerate the samples for 12 points
    TestC3DSpec t = smallSpec(C3DProcessor::kIntel, true, s.labels.size(), 2);
    t.labels = s.labels;
    return t;
  }();
  s.point_string_params = {{"ANGLES", {"LHipAngles"}}, {"POWERS", {"LKneePower", "RKneePower"}}};
  const C3DClip clip = parseBytes(writeTestC3D(s));
  EXPECT_EQ(clip.pointKind(0), C3DPointKind::kMarker);
  EXPECT_EQ(clip.pointKind(1), C3DPointKind::kUnlabeled);
  EXPECT_EQ(clip.pointKind(2), C3DPointKind::kModelled);
  EXPECT_EQ(clip.pointKind(3), C3DPointKind::kMarker);
  EXPECT_EQ(clip.pointKind(4), C3DPointKind::kUnlabeled);
  EXPECT_EQ(clip.pointKind(5), C3DPointKind::kModelled);
  for (int p = 6; p < 10; ++p) EXPECT_EQ(clip.pointKind(p), C3DPointKind::kModelled) << "PiG segment axis";
  EXPECT_EQ(clip.pointKind(10), C3DPointKind::kMarker);  // LCLA alone is not a quadruple
  EXPECT_EQ(clip.pointKind(11), C3DPointKind::kMarker);
  EXPECT_EQ(clip.findPoint("LFHD"), 0);
  EXPECT_EQ(clip.findPoint("subj:LFHD"), 0);
  EXPECT_EQ(clip.findPoint("RFHD"), 3);
  EXPECT_EQ(clip.findPoint("FHD"), -1);
  EXPECT_EQ(clip.findPoint("nope"), -1);
  ASSERT_NE(clip.findParameter("point", "angles"), nullptr);
  EXPECT_EQ(clip.findParameter("POINT", "ANGLES")->dimensions, (std::vector<int>{10, 1}));
}

TEST(C3DReader, LabelsContinueInLabels2) {
  // A parameter dimension is one byte, so files with more than 255 points continue their
  // labels in POINT:LABELS2.
  const TestC3DSpec s = smallSpec(C3DProcessor::kIntel, true, 300, 1);
  const C3DClip clip = parseBytes(writeTestC3D(s));
  ASSERT_NE(clip.findParameter("POINT", "LABELS2"), nullptr);
  EXPECT_EQ(clip.labels().size(), 300u);
  EXPECT_EQ(clip.labels()[254], "M254");
  EXPECT_EQ(clip.labels()[255], "M255");
  EXPECT_EQ(clip.labels()[299], "M299");
  EXPECT_EQ(clip.pointKind(299), C3DPointKind::kMarker);
}

// ---- data start arbitration (header word 9 vs POINT:DATA_START) ----

TEST(C3DReader, DataStartParameterZeroIsIgnored) {
  // Phoenix-style broken parameter (c3d.org sample13): POINT:DATA_START = 0, header correct.
  TestC3DSpec s = smallSpec(C3DProcessor::kIntel, false);
  s.param_data_start = 0;
  const C3DClip clip = parseBytes(writeTestC3D(s));
  expectMatchesSpec(clip, s);
  ASSERT_FALSE(clip.warnings().empty());
  EXPECT_NE(clip.warnings().front().find("header wins"), std::string::npos);
}

TEST(C3DReader, DataStartHeaderWinsWhenBothArePlausible) {
  // Data is written at the header's block (one empty block after the parameters); the
  // parameter names the earlier, empty block. Reading the parameter's block would give zeros.
  TestC3DSpec s = smallSpec(C3DProcessor::kMips, true);
  s.data_block_shift = 1;
  const auto probe = writeTestC3D(s);
  const int header_block = static_cast<int>(s.data_offset / 512 + 1);
  s.param_data_start = header_block - 1;
  const auto bytes = writeTestC3D(s);
  const C3DClip clip = parseBytes(bytes);
  EXPECT_EQ(clip.dataStartBlock(), static_cast<std::uint32_t>(header_block));
  expectMatchesSpec(clip, s);
}

TEST(C3DReader, DataStartParameterUsedWhenHeaderIsImpossible) {
  for (int bad : {0, 1, 2}) {  // 2 = the parameter block itself
    TestC3DSpec s = smallSpec(C3DProcessor::kDec, true);
    s.header_data_start_override = bad;
    const C3DClip clip = parseBytes(writeTestC3D(s));
    expectMatchesSpec(clip, s);
    ASSERT_FALSE(clip.warnings().empty());
    EXPECT_NE(clip.warnings().back().find("POINT:DATA_START"), std::string::npos);
  }
}

TEST(C3DReader, DataStartParameterUsedWhenHeaderFramesDoNotFit) {
  TestC3DSpec s = smallSpec(C3DProcessor::kIntel, true);
  s.pad_to_block = false;
  const auto probe = writeTestC3D(s);
  s.header_data_start_override = static_cast<int>(s.data_offset / 512 + 2);  // past the data
  const C3DClip clip = parseBytes(writeTestC3D(s));
  expectMatchesSpec(clip, s);
}

TEST(C3DReader, DataStartBothImpossibleFailsClearly) {
  TestC3DSpec s = smallSpec(C3DProcessor::kIntel, true);
  s.header_data_start_override = 1;
  s.param_data_start = 0;
  try {
    (void)parseBytes(writeTestC3D(s), "both_bad.c3d");
    FAIL() << "expected C3DError";
  } catch (const C3DError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("both_bad.c3d"), std::string::npos) << m;
    EXPECT_NE(m.find("data start"), std::string::npos) << m;
    EXPECT_NE(m.find("at byte"), std::string::npos) << m;
  }
}

// ---- header-only files, guessed processor, long clips ----

TEST(C3DReader, NoParameterSection) {
  for (const Variant& v : kVariants) {
    TestC3DSpec s = smallSpec(v.proc, v.floating);
    s.write_parameters = false;
    const C3DClip clip = parseBytes(writeTestC3D(s));
    EXPECT_FALSE(clip.hasParameters());
    EXPECT_EQ(clip.processor(), v.proc);
    TestC3DSpec expected = s;
    expected.labels.assign(s.labels.size(), "");
    expectMatchesSpec(clip, expected);
    for (int p = 0; p < clip.pointCount(); ++p) EXPECT_EQ(clip.pointKind(p), C3DPointKind::kMarker);
    EXPECT_DOUBLE_EQ(clip.unitsToMm(), 1.0);
  }
}

TEST(C3DReader, ProcessorIsGuessedOnlyWithoutAParameterSection) {
  // Header block pointer 1: no parameter section, so no processor byte to read. The guess is
  // exercised with the parameter block holding a byte that would be refused (0).
  for (const Variant& v : kVariants) {
    TestC3DSpec s = smallSpec(v.proc, v.floating);
    s.write_parameters = false;
    s.header_parameter_block = 1;
    s.processor_byte_override = 0x00;
    const C3DClip clip = parseBytes(writeTestC3D(s));
    EXPECT_EQ(clip.processor(), v.proc);
    EXPECT_FALSE(clip.hasParameters());
    TestC3DSpec expected = s;
    expected.labels.assign(s.labels.size(), "");
    expectMatchesSpec(clip, expected);
    bool guessed = false;
    for (const std::string& w : clip.warnings()) guessed = guessed || w.find("guessed") != std::string::npos;
    EXPECT_TRUE(guessed);
  }
}

TEST(C3DReader, UnknownProcessorByteIsRefused) {
  // With a parameter section header, its processor byte decides how every number is read: a byte
  // other than 84/85/86 is damage, not something to guess around (with or without entries).
  for (const bool with_parameters : {true, false}) {
    for (const std::uint8_t byte : {std::uint8_t{0}, std::uint8_t{83}, std::uint8_t{87}, std::uint8_t{0xff}}) {
      TestC3DSpec s = smallSpec(C3DProcessor::kIntel, true);
      s.write_parameters = with_parameters;
      s.processor_byte_override = byte;
      try {
        (void)parseBytes(writeTestC3D(s), "proc.c3d");
        ADD_FAILURE() << "processor byte " << int(byte) << " accepted";
      } catch (const C3DError& e) {
        const std::string m = e.what();
        EXPECT_EQ(m.rfind("proc.c3d: unknown processor type " + std::to_string(byte) + " ", 0), 0u) << m;
        EXPECT_NE(m.find("expected 84 Intel, 85 DEC or 86 MIPS/SGI"), std::string::npos) << m;
        EXPECT_NE(m.find("(at byte 515)"), std::string::npos) << m;  // block 2, byte 4 of its header
      }
    }
  }
}

// ---- parameter section extent and corruption ----

// A spec whose parameter section spans several blocks: long labels make LABELS about 2 KB.
TestC3DSpec longLabelSpec(C3DProcessor proc, bool floating) {
  TestC3DSpec s = smallSpec(proc, floating, 60, 3);
  for (std::size_t p = 0; p < s.labels.size(); ++p) {
    std::string label = "a_subject_with_a_long_name:MARKER_";
    label += std::to_string(p);
    s.labels[p] = label;
  }
  return s;
}

// Byte offset of the next-entry offset field of the parameter or group called `name`.
std::size_t offsetFieldOf(const std::vector<std::uint8_t>& file, const std::string& name) {
  for (std::size_t i = 512 + 4; i + name.size() + 2 < file.size(); ++i) {
    if (file[i] == name.size() && std::memcmp(&file[i + 2], name.data(), name.size()) == 0) {
      return i + 2 + name.size();
    }
  }
  ADD_FAILURE() << name << " not found";
  return 0;
}

void putI16(std::vector<std::uint8_t>& file, std::size_t at, std::int16_t v, C3DProcessor proc) {
  const auto u = static_cast<std::uint16_t>(v);
  file[at] = static_cast<std::uint8_t>(proc == C3DProcessor::kMips ? u >> 8 : u & 0xff);
  file[at + 1] = static_cast<std::uint8_t>(proc == C3DProcessor::kMips ? u & 0xff : u >> 8);
}

std::string errorOf(const std::vector<std::uint8_t>& bytes, const std::string& name = "bad.c3d") {
  try {
    (void)C3DClip::parse(bytes, name);
  } catch (const C3DError& e) {
    return e.what();
  }
  return "(parsed)";
}

TEST(C3DReader, ParameterSectionLongerThanDeclaredIsReadUpToTheData) {
  // Some writers declare fewer parameter blocks than their entries use, so LABELS runs past the
  // declared end. The entries are read up to the data start (header word 9) instead.
  for (const Variant& v : kVariants) {
    SCOPED_TRACE(std::to_string(static_cast<int>(v.proc)) + (v.floating ? " float" : " int"));
    TestC3DSpec s = longLabelSpec(v.proc, v.floating);
    const std::vector<std::uint8_t> honest = writeTestC3D(s);
    const std::size_t blocks = honest[512 + 2];
    ASSERT_GE(blocks, 4u) << "the section must span several blocks";
    for (int delta : {-1, -2, -static_cast<int>(blocks) + 1}) {
      s.param_blocks_delta = delta;
      const std::vector<std::uint8_t> bytes = writeTestC3D(s);
      ASSERT_EQ(bytes[512 + 2], blocks + static_cast<std::size_t>(delta));
      const C3DClip clip = parseBytes(bytes);
      expectMatchesSpec(clip, s);
      ASSERT_EQ(clip.warnings().size(), 1u);
      const std::size_t declared = blocks + static_cast<std::size_t>(delta);
      EXPECT_NE(clip.warnings()[0].find("declares " + std::to_string(declared) + (declared == 1 ? " block (" : " blocks (")),
                std::string::npos)
          << clip.warnings()[0];
      EXPECT_NE(clip.warnings()[0].find("read up to the data start (block"), std::string::npos) << clip.warnings()[0];
    }
  }
}

TEST(C3DReader, ParameterEntriesRunningIntoTheDataAreRefused) {
  // The header's data start bounds the entries: a LABELS that runs into the frames is corrupt.
  TestC3DSpec s = longLabelSpec(C3DProcessor::kIntel, true);
  (void)writeTestC3D(s);  // sets s.data_offset
  const int header_block = static_cast<int>(s.data_offset / 512 + 1);
  s.header_data_start_override = header_block - 2;  // cuts LABELS (the section fills its blocks)
  s.param_data_start = header_block - 2;
  const std::string m = errorOf(writeTestC3D(s));
  EXPECT_NE(m.find("corrupt parameter section: the data of parameter 'LABELS'"), std::string::npos) << m;
  EXPECT_NE(m.find("runs into the data, which starts at byte " + std::to_string((header_block - 3) * 512)),
            std::string::npos)
      << m;
}

TEST(C3DReader, ParameterEntriesOverlappingTheDataBlockUsedAreRefused) {
  // The header's block is impossible, so the entries are read to the end of the file and the
  // block comes from POINT:DATA_START, which lies inside the parameter section: refused, since
  // parameters and frames would share bytes.
  TestC3DSpec s = longLabelSpec(C3DProcessor::kDec, false);
  s.header_data_start_override = 1;
  s.param_data_start = 3;
  const std::string m = errorOf(writeTestC3D(s));
  EXPECT_NE(m.find("corrupt parameter section: parameter '"), std::string::npos) << m;
  EXPECT_NE(m.find("into the frames, which start at block 3 (at byte 1024)"), std::string::npos) << m;
}

TEST(C3DReader, CorruptParameterChainsAreRefused) {
  for (const C3DProcessor proc : {C3DProcessor::kIntel, C3DProcessor::kMips}) {
    SCOPED_TRACE(static_cast<int>(proc));
    const TestC3DSpec s = smallSpec(proc, true);
    const std::vector<std::uint8_t> good = writeTestC3D(s);
    const std::size_t rate = offsetFieldOf(good, "RATE");
    const std::string at_rate = "parameter 'RATE' at byte " + std::to_string(rate - 6);
    struct Case {
      std::int16_t offset;
      std::string expected;
    };
    const Case cases[] = {
        {-8, at_rate + " gives the next entry at offset -8, backwards"},
        {-1, at_rate + " gives the next entry at offset -1, backwards"},
        // RATE's data (type, dims, one float) ends 2 + 2 + 4 bytes after its offset field.
        {2, at_rate + " gives the next entry at byte " + std::to_string(rate + 2) + ", inside its own data (which ends at byte " +
                std::to_string(rate + 8) + ")"},
        {7, "inside its own data"},
        {0x7fff, at_rate + " gives the next entry at byte " + std::to_string(rate + 0x7fff) +
                     ", past the data start (block 3) at byte 1024"},
    };
    for (const Case& c : cases) {
      std::vector<std::uint8_t> bad = good;
      putI16(bad, rate, c.offset, proc);
      const std::string m = errorOf(bad);
      EXPECT_EQ(m.rfind("bad.c3d: corrupt parameter section: ", 0), 0u) << m;
      EXPECT_NE(m.find(c.expected), std::string::npos) << m;
      EXPECT_NE(m.find("(at byte " + std::to_string(rate) + ")"), std::string::npos) << m;
    }
    // Without a usable header data start the section may reach the end of the file, not further.
    // (An offset landing exactly at the end of the entry's data, cutting its description, is
    // accepted: mocap36.c3d's LABELS does that, and the real-data tests load it.)
    TestC3DSpec t = s;
    t.header_data_start_override = 0;
    std::vector<std::uint8_t> bad = writeTestC3D(t);
    putI16(bad, rate, 0x7fff, proc);
    const std::string m = errorOf(bad);
    EXPECT_NE(m.find("past the end of the file at byte " + std::to_string(bad.size())), std::string::npos) << m;
  }
}

TEST(C3DReader, ParameterDimensionsThatOverflowAreRefused) {
  // Nine dimensions of 128 give 2^63 elements; times 4 bytes that wraps to 0 in 64 bits, which
  // once passed the range check and read the parameter's "data" far past the buffer (the 1.2 KB
  // file libFuzzer found in fuzz_c3d). Every step of the product is checked against the section.
  for (const C3DProcessor proc : {C3DProcessor::kIntel, C3DProcessor::kDec, C3DProcessor::kMips}) {
    SCOPED_TRACE(static_cast<int>(proc));
    const TestC3DSpec s = smallSpec(proc, true);
    const std::vector<std::uint8_t> good = writeTestC3D(s);
    const std::size_t rate = offsetFieldOf(good, "RATE");  // then type, ndims, dims...
    ASSERT_LT(rate + 4 + 9, good.size());
    for (const std::int8_t type : {std::int8_t{4}, std::int8_t{2}, std::int8_t{-1}}) {
      std::vector<std::uint8_t> bad = good;
      bad[rate + 2] = static_cast<std::uint8_t>(type);
      bad[rate + 3] = 9;
      for (std::size_t k = 0; k < 9; ++k) bad[rate + 4 + k] = 128;
      const std::string m = errorOf(bad);
      EXPECT_EQ(m.rfind("bad.c3d: corrupt parameter 'RATE': its dimensions (128 x 128 x 128 x 128 x 128 x 128 x 128 x 128 x ... "
                        "(9 dimensions)) give more ", 0), 0u) << m;
      EXPECT_NE(m.find("-byte elements than the "), std::string::npos) << m;
    }
    // The largest product that fits: 255 x 255 ... of one-byte elements is refused at the step
    // that passes the bytes left, not after the product wrapped.
    std::vector<std::uint8_t> wide = good;
    wide[rate + 2] = 1;
    wide[rate + 3] = 255;
    const std::size_t dims_end = std::min(good.size(), rate + 4 + 255);
    for (std::size_t k = rate + 4; k < dims_end; ++k) wide[k] = 255;
    const std::string m = errorOf(wide);
    EXPECT_NE(m.find("corrupt parameter"), std::string::npos) << m;
    EXPECT_EQ(m.find("(parsed)"), std::string::npos) << m;
  }
  // A zero dimension makes the parameter empty, whatever the other dimensions say.
  const TestC3DSpec s = smallSpec(C3DProcessor::kIntel, true);
  std::vector<std::uint8_t> empty = writeTestC3D(s);
  const std::size_t rate = offsetFieldOf(empty, "RATE");
  // RATE becomes a 2-dimensional float parameter 128 x 0 (its data, 0 bytes); the next entry now
  // starts before the old float's bytes, which the next-entry offset still skips.
  empty[rate + 3] = 2;
  empty[rate + 4] = 128;
  empty[rate + 5] = 0;
  const C3DClip clip = parseBytes(empty);
  const C3DParameter* p = clip.findParameter("POINT", "RATE");
  ASSERT_NE(p, nullptr);
  EXPECT_EQ(p->dimensions, (std::vector<int>{128, 0}));
  EXPECT_TRUE(p->numbers.empty());
}

// ---- no raw bytes in messages ----

TEST(C3DReader, NamesInMessagesAreEscapedAndCut) {
  // A parameter name with a terminal escape sequence, 60 bytes long, and an invalid type.
  std::string hostile = "\x1b[2J\x07" "EVIL";
  hostile.push_back(static_cast<char>(0xff));
  while (hostile.size() < 56) hostile.push_back('N');
  hostile += "TAIL";
  TestC3DSpec s = smallSpec(C3DProcessor::kIntel, true);
  s.extra_params.push_back({hostile, 1, 3, {}, {1, 2, 3}});
  const std::string m = errorOf(writeTestC3D(s), "hostile.c3d");
  EXPECT_NE(m.find("corrupt parameter '\\x1b[2J\\x07EVIL\\xff"), std::string::npos) << m;
  EXPECT_NE(m.find("NNN...': type 3"), std::string::npos) << m;
  EXPECT_EQ(m.find("TAIL"), std::string::npos) << "the name was not cut: " << m;
  for (const char c : m) {
    const auto u = static_cast<unsigned char>(c);
    EXPECT_TRUE(u >= 0x20 && u < 0x7f) << "raw byte " << int(u) << " in: " << m;
  }
  // Text in warnings too: an unknown unit made of control bytes and junk.
  TestC3DSpec t = smallSpec(C3DProcessor::kIntel, true);
  t.units = std::string("\x1b]0;owned\x07") + std::string(50, 'u');
  const C3DClip clip = parseBytes(writeTestC3D(t));
  ASSERT_EQ(clip.warnings().size(), 1u);
  const std::string& w = clip.warnings()[0];
  EXPECT_NE(w.find("unknown POINT:UNITS '\\x1b]0;owned\\x07uuu"), std::string::npos) << w;
  EXPECT_NE(w.find("u...'"), std::string::npos) << w;
  for (const char c : w) EXPECT_TRUE(static_cast<unsigned char>(c) >= 0x20 && static_cast<unsigned char>(c) < 0x7f) << w;
}

TEST(C3DReader, MoreThan65535FramesFromTrialFields) {
  TestC3DSpec s = smallSpec(C3DProcessor::kIntel, false, 1, 70000);
  s.long_frame_fields = true;
  for (std::size_t f = 0; f < s.frames; ++f) {  // keep int16 in range, distinct per frame
    s.xyz[f] = {static_cast<float>(f % 20000) * 0.5f, static_cast<float>(f / 20000) * 0.5f, 3.0f};
  }
  const C3DClip clip = parseBytes(writeTestC3D(s));
  EXPECT_EQ(clip.header().last_frame, 65535);  // what the header can hold
  EXPECT_EQ(clip.frameCount(), 70000u);
  EXPECT_EQ(clip.firstFrameNumber(), 1u);
  expectMatchesSpec(clip, s);
}

// ---- damaged files ----

void expectClearError(const std::vector<std::uint8_t>& bytes, const std::string& name, const std::string& context) {
  try {
    (void)C3DClip::parse(bytes, name);
    ADD_FAILURE() << context << ": expected C3DError";
  } catch (const C3DError& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.rfind(name + ": ", 0), 0u) << context << ": " << m;
    EXPECT_NE(m.find("at byte"), std::string::npos) << context << ": " << m;
  }
}

TEST(C3DReader, EveryTruncationFailsClearlyOrKeepsAllData) {
  for (const Variant& v : kVariants) {
    TestC3DSpec s = smallSpec(v.proc, v.floating, 3, 4);
    s.analog_words = 2;
    const auto full = writeTestC3D(s);
    ASSERT_GT(full.size(), s.data_end);
    for (std::size_t len = 0; len < full.size(); ++len) {
      const std::vector<std::uint8_t> cut(full.begin(), full.begin() + static_cast<std::ptrdiff_t>(len));
      if (len < s.data_end) {
        expectClearError(cut, "cut.c3d", "length " + std::to_string(len));
        if (len >= 512 && len < s.data_offset) continue;
        if (len >= s.data_offset) {
          // Inside the frames: the message names the truncated data.
          try {
            (void)C3DClip::parse(cut, "cut.c3d");
          } catch (const C3DError& e) {
            EXPECT_NE(std::string(e.what()).find("truncated data"), std::string::npos) << e.what();
          }
        }
      } else {
        expectMatchesSpec(C3DClip::parse(cut, "cut.c3d"), s);  // only block padding removed
      }
    }
  }
}

TEST(C3DReader, RandomCorruptionsNeverCrash) {
  std::mt19937 rng(12345);
  int parsed = 0;
  int failed = 0;
  for (const Variant& v : kVariants) {
    TestC3DSpec s = smallSpec(v.proc, v.floating, 4, 5);
    s.analog_words = 2;
    const auto full = writeTestC3D(s);
    for (int trial = 0; trial < 600; ++trial) {
      std::vector<std::uint8_t> bad = full;
      const int flips = 1 + static_cast<int>(rng() % 8);
      for (int i = 0; i < flips; ++i) {
        // Bias half the damage into the header and parameter blocks, where structure lives.
        const std::size_t limit = (rng() % 2 == 0) ? std::min<std::size_t>(bad.size(), s.data_offset) : bad.size();
        bad[rng() % limit] = static_cast<std::uint8_t>(rng());
      }
      try {
        const C3DClip clip = C3DClip::parse(bad, "bad.c3d");
        // Whatever parsed must be internally consistent.
        for (std::size_t f = 0; f < clip.frameCount(); ++f) {
          for (int p = 0; p < clip.pointCount(); ++p) {
            if (clip.isValid(f, p)) {
              for (int c = 0; c < 3; ++c) EXPECT_TRUE(std::isfinite(clip.positions(f)[p * 3 + c]));
            }
          }
        }
        ++parsed;
      } catch (const C3DError& e) {
        EXPECT_EQ(std::string(e.what()).rfind("bad.c3d: ", 0), 0u) << e.what();
        ++failed;
      }
    }
  }
  EXPECT_EQ(parsed + failed, 3600);
  EXPECT_GT(failed, 0);  // some corruptions must be detected
}

TEST(C3DReader, NotAC3DFile) {
  std::vector<std::uint8_t> junk(2048, 0x41);
  expectClearError(junk, "junk.bin", "junk");
  expectClearError({}, "empty.c3d", "empty");
  EXPECT_THROW((void)C3DClip::load("/nonexistent/dir/x.c3d"), C3DError);
}

// ---- real data ----

TEST(C3DRealData, Sample01SixVariantsAgree) {
  const char* names[] = {"pi", "pr", "si", "sr", "vi", "vr"};
  const C3DProcessor procs[] = {C3DProcessor::kIntel, C3DProcessor::kIntel, C3DProcessor::kMips,
                                C3DProcessor::kMips,  C3DProcessor::kDec,   C3DProcessor::kDec};
  std::vector<C3DClip> clips;
  for (int i = 0; i < 6; ++i) {
    TETRIG_REQUIRE_DATA(path, std::string("mocap/c3d.org/sample01_Eb015") + names[i] + ".c3d");
    clips.push_back(C3DClip::load(path));
    EXPECT_EQ(clips.back().processor(), procs[i]) << names[i];
    EXPECT_EQ(clips.back().isFloat(), names[i][1] == 'r') << names[i];
  }
  const C3DClip& ref = clips[0];
  // c3d.org readme + NOTES: 26 points, 450 frames at 50 Hz, 1.93 % of samples invalid.
  EXPECT_EQ(ref.pointCount(), 26);
  EXPECT_EQ(ref.frameCount(), 450u);
  EXPECT_DOUBLE_EQ(ref.frameRate(), 50.0);
  EXPECT_EQ(ref.labels()[0], "RFT1");
  std::size_t invalid = 0;
  for (std::size_t f = 0; f < ref.frameCount(); ++f) {
    for (int p = 0; p < ref.pointCount(); ++p) invalid += ref.isValid(f, p) ? 0 : 1;
  }
  EXPECT_NEAR(static_cast<double>(invalid) / (26.0 * 450.0), 0.0193, 0.0005);
  for (std::size_t i = 1; i < clips.size(); ++i) {
    const C3DClip& c = clips[i];
    SCOPED_TRACE(names[i]);
    ASSERT_EQ(c.pointCount(), ref.pointCount());
    ASSERT_EQ(c.frameCount(), ref.frameCount());
    EXPECT_EQ(c.labels(), ref.labels());
    EXPECT_DOUBLE_EQ(c.frameRate(), ref.frameRate());
    double worst = 0.0;
    for (std::size_t f = 0; f < ref.frameCount(); ++f) {
      for (int p = 0; p < ref.pointCount(); ++p) {
        ASSERT_EQ(c.isValid(f, p), ref.isValid(f, p)) << "frame " << f << " point " << p;
        if (!ref.isValid(f, p)) continue;
        for (int k = 0; k < 3; ++k) {
          worst = std::max(worst, std::fabs(static_cast<double>(c.positions(f)[p * 3 + k]) - ref.positions(f)[p * 3 + k]));
        }
      }
    }
    EXPECT_LT(worst, 1e-3) << "largest coordinate difference in mm";
  }
}

TEST(C3DRealData, PhaseSpaceGapsAreInvalidNotZeros) {
  TETRIG_REQUIRE_DATA(path, "mocap/c3d.org/sample20_phasespace_sample.c3d");
  const C3DClip clip = C3DClip::load(path);
  // NOTES: header only, 40 unlabelled markers, 30 Hz, 701 frames, 4.57 % invalid, one marker
  // never valid, 26 markers with gaps.
  EXPECT_FALSE(clip.hasParameters());
  EXPECT_EQ(clip.pointCount(), 40);
  EXPECT_EQ(clip.frameCount(), 701u);
  EXPECT_DOUBLE_EQ(clip.frameRate(), 30.0);
  std::size_t invalid = 0;
  std::size_t valid_zero = 0;
  int never_valid = 0;
  int with_gaps = 0;
  for (int p = 0; p < clip.pointCount(); ++p) {
    EXPECT_EQ(clip.pointKind(p), C3DPointKind::kMarker);
    std::size_t point_invalid = 0;
    for (std::size_t f = 0; f < clip.frameCount(); ++f) {
      if (!clip.isValid(f, p)) {
        ++point_invalid;
        continue;
      }
      const float* x = clip.positions(f) + p * 3;
      if (x[0] == 0.0f && x[1] == 0.0f && x[2] == 0.0f) ++valid_zero;
    }
    invalid += point_invalid;
    never_valid += point_invalid == clip.frameCount() ? 1 : 0;
    with_gaps += point_invalid > 0 && point_invalid < clip.frameCount() ? 1 : 0;
  }
  EXPECT_NEAR(static_cast<double>(invalid) / (40.0 * 701.0), 0.0457, 0.0005);
  EXPECT_EQ(valid_zero, 0u) << "a gap came out as a valid (0,0,0) sample";
  EXPECT_EQ(never_valid, 1);
  EXPECT_EQ(with_gaps, 26);
  // NOTES: 226 short gap runs in the markers that are sometimes valid. (NOTES says 1-5 frames;
  // an independent script over the raw bytes finds 208 runs of 1-5 and 18 of 6-11 frames.)
  int runs = 0;
  std::size_t longest = 0;
  for (int p = 0; p < clip.pointCount(); ++p) {
    std::size_t run = 0;
    bool ever_valid = false;
    for (std::size_t f = 0; f < clip.frameCount(); ++f) ever_valid = ever_valid || clip.isValid(f, p);
    if (!ever_valid) continue;
    for (std::size_t f = 0; f < clip.frameCount(); ++f) {
      if (clip.isValid(f, p)) {
        run = 0;
        continue;
      }
      if (run++ == 0) ++runs;
      longest = std::max(longest, run);
    }
  }
  EXPECT_EQ(runs, 226);
  EXPECT_EQ(longest, 11u);
}

TEST(C3DRealData, Mocap36TrailingDropout) {
  TETRIG_REQUIRE_DATA(path, "mocap/btkdata/mocap36.c3d");
  const C3DClip clip = C3DClip::load(path);
  ASSERT_EQ(clip.pointCount(), 36);
  ASSERT_EQ(clip.frameCount(), 1380u);
  EXPECT_DOUBLE_EQ(clip.frameRate(), 100.0);
  for (std::size_t f = 1151; f <= 1379; ++f) {
    for (int p = 0; p < 36; ++p) ASSERT_FALSE(clip.isValid(f, p)) << "frame " << f << " point " << p;
  }
  int valid_before = 0;
  for (int p = 0; p < 36; ++p) valid_before += clip.isValid(1150, p) ? 1 : 0;
  EXPECT_GT(valid_before, 0) << "the dropout starts at frame 1151";
}

TEST(C3DRealData, Hdm05LabelsRateFrames) {
  TETRIG_REQUIRE_DATA(path, "mocap/hdm05/HDM_mm_01-02_03_120.c3d");
  const C3DClip clip = C3DClip::load(path);
  EXPECT_EQ(clip.processor(), C3DProcessor::kIntel);
  EXPECT_TRUE(clip.isFloat());
  EXPECT_DOUBLE_EQ(clip.frameRate(), 120.0);
  EXPECT_EQ(clip.frameCount(), 3990u);
  ASSERT_EQ(clip.pointCount(), 44);
  int markers = 0;
  int unlabeled = 0;
  for (int p = 0; p < clip.pointCount(); ++p) {
    markers += clip.pointKind(p) == C3DPointKind::kMarker ? 1 : 0;
    unlabeled += clip.pointKind(p) == C3DPointKind::kUnlabeled ? 1 : 0;
    if (clip.pointKind(p) == C3DPointKind::kMarker) {
      EXPECT_EQ(clip.labels()[static_cast<std::size_t>(p)].rfind("meinard:", 0), 0u);
    }
  }
  EXPECT_EQ(markers, 41);
  EXPECT_EQ(unlabeled, 3);
  EXPECT_EQ(clip.units(), "mm");
  // T-pose start: the left front head marker is about 1.71 m up (Z-up), NOTES section 3.
  const int lfhd = clip.findPoint("LFHD");
  ASSERT_GE(lfhd, 0);
  ASSERT_TRUE(clip.isValid(0, lfhd));
  EXPECT_NEAR(clip.positions(0)[lfhd * 3 + 2], 1710.0, 60.0);
  // No gaps: residual 0 everywhere (post-processed data).
  for (std::size_t f = 0; f < clip.frameCount(); f += 97) {
    for (int p = 0; p < 44; ++p) EXPECT_TRUE(clip.isValid(f, p));
  }
}

TEST(C3DRealData, DecIntegerPlugInGait) {
  TETRIG_REQUIRE_DATA(path, "mocap/c3d.org/sample09_PlugInC3D.c3d");
  const C3DClip clip = C3DClip::load(path);
  EXPECT_EQ(clip.processor(), C3DProcessor::kDec);
  EXPECT_FALSE(clip.isFloat());
  EXPECT_EQ(clip.pointCount(), 86);
  EXPECT_EQ(clip.frameCount(), 281u);
  EXPECT_DOUBLE_EQ(clip.frameRate(), 60.0);
  EXPECT_EQ(clip.labels()[0], "RKNE");
  // NOTES: 18 physical markers + 68 modelled points (10 angles + 8 forces + 8 moments + 6 powers
  // listed in the POINT lists, and 9 Plug-in Gait segment-axis quadruples PELO..RTOL).
  int modelled = 0;
  for (int p = 0; p < clip.pointCount(); ++p) modelled += clip.pointKind(p) == C3DPointKind::kModelled ? 1 : 0;
  EXPECT_EQ(modelled, 68);
  EXPECT_EQ(clip.pointKind(clip.findPoint("LCLA")), C3DPointKind::kMarker);  // a real clavicle marker
  EXPECT_EQ(clip.pointKind(clip.findPoint("PELO")), C3DPointKind::kModelled);
  // Physical markers have gaps (NOTES: 16-134 frames each) and plausible lab coordinates.
  const int rkne = clip.findPoint("RKNE");
  std::size_t gaps = 0;
  for (std::size_t f = 0; f < clip.frameCount(); ++f) {
    if (!clip.isValid(f, rkne)) {
      ++gaps;
      continue;
    }
    for (int k = 0; k < 3; ++k) EXPECT_LT(std::fabs(clip.positions(f)[rkne * 3 + k]), 10000.0f);
  }
  EXPECT_GE(gaps, 16u);
  EXPECT_LE(gaps, 134u);
  // Its modelled outputs (powers, ...) hold exact zeros with residual 0, the only such samples in
  // the data set (1254, all in points 64-85, counted by an independent script over the raw
  // bytes): gaps by default, valid origins with keep_zero_points. No physical marker has any.
  std::size_t zero_gaps = 0;
  for (std::size_t f = 0; f < clip.frameCount(); ++f) {
    for (int p = 0; p < clip.pointCount(); ++p) {
      if (clip.samples(f)[p] != C3DSample::kZeroGap) continue;
      ++zero_gaps;
      EXPECT_EQ(clip.pointKind(p), C3DPointKind::kModelled) << clip.labels()[static_cast<std::size_t>(p)];
    }
  }
  EXPECT_EQ(zero_gaps, 1254u);
  C3DReadOptions keep;
  keep.keep_zero_points = true;
  const C3DClip kept = C3DClip::load(path, keep);
  const int power = kept.findPoint("LAnklePower");
  ASSERT_GE(power, 0);
  std::size_t zero_valid = 0;
  std::size_t power_zero_gaps = 0;
  for (std::size_t f = 0; f < kept.frameCount(); ++f) {
    const float* x = kept.positions(f) + power * 3;
    if (kept.isValid(f, power) && x[0] == 0.0f && x[1] == 0.0f && x[2] == 0.0f) ++zero_valid;
    power_zero_gaps += clip.samples(f)[power] == C3DSample::kZeroGap ? 1 : 0;
    ASSERT_NE(kept.samples(f)[power], C3DSample::kZeroGap);
  }
  EXPECT_GT(zero_valid, 0u);
  EXPECT_EQ(zero_valid, power_zero_gaps);
}

TEST(C3DRealData, DeclaringTooFewParameterBlocksReadsTheSame) {
  // sample01's parameters fill 8.2 of their 9 declared blocks. Declaring fewer (down to 1) leaves
  // LABELS and later entries past the declared end, as some writers do; the reader must still
  // read them, up to the data start, and decode exactly what the honest file gives.
  for (const char* name : {"pr", "vi", "si"}) {
    TETRIG_REQUIRE_DATA(path, std::string("mocap/c3d.org/sample01_Eb015") + name + ".c3d");
    const C3DClip honest = C3DClip::load(path);
    std::ifstream in(path, std::ios::binary);
    std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    ASSERT_EQ(bytes[512 + 2], 9);
    for (std::uint8_t declared : {std::uint8_t{5}, std::uint8_t{1}}) {
      bytes[512 + 2] = declared;
      const C3DClip clip = C3DClip::parse(bytes, "fewer.c3d");
      ASSERT_EQ(clip.parameters().size(), honest.parameters().size()) << name;
      EXPECT_EQ(clip.labels(), honest.labels());
      ASSERT_EQ(clip.frameCount(), honest.frameCount());
      for (std::size_t f = 0; f < clip.frameCount(); f += 7) {
        for (int p = 0; p < clip.pointCount(); ++p) {
          ASSERT_EQ(clip.samples(f)[p], honest.samples(f)[p]);
          for (int c = 0; c < 3; ++c) ASSERT_EQ(clip.positions(f)[p * 3 + c], honest.positions(f)[p * 3 + c]);
        }
      }
      ASSERT_EQ(clip.warnings().size(), 1u);
      EXPECT_NE(clip.warnings()[0].find("declares " + std::to_string(declared) + (declared == 1 ? " block (" : " blocks (")),
                std::string::npos)
          << clip.warnings()[0];
    }
  }
}

TEST(C3DRealData, PlugInGaitModelledOutputsAreRecognised) {
  // NOTES: the static trial has 35 markers + 102 modelled points, the walk 35 + 158.
  const char* files[] = {"mocap/btkdata/PiG_Calibration-FlatFoot-Full.c3d", "mocap/btkdata/PiG_Motion-FlatFoot-Full.c3d"};
  const int expected_modelled[] = {102, 158};
  for (int i = 0; i < 2; ++i) {
    TETRIG_REQUIRE_DATA(path, files[i]);
    const C3DClip clip = C3DClip::load(path);
    int markers = 0;
    int modelled = 0;
    for (int p = 0; p < clip.pointCount(); ++p) {
      markers += clip.pointKind(p) == C3DPointKind::kMarker ? 1 : 0;
      modelled += clip.pointKind(p) == C3DPointKind::kModelled ? 1 : 0;
    }
    EXPECT_EQ(markers, 35) << files[i];
    EXPECT_EQ(modelled, expected_modelled[i]) << files[i];
  }
}

TEST(C3DRealData, EveryMocapFileLoads) {
  const char* files[] = {"mocap/cmu/85_02.c3d",
                         "mocap/c3d.org/sample32_vicon_zerowire.c3d",
                         "mocap/btkdata/PiG_Calibration-FlatFoot-Full.c3d",
                         "mocap/btkdata/PiG_Motion-FlatFoot-Full.c3d",
                         "mocap/ezc3d-testFiles/Qualisys.c3d"};
  const int points[] = {41, 55, 137, 193, 55};
  const std::size_t frames[] = {810, 306, 94, 315, 340};
  for (int i = 0; i < 5; ++i) {
    TETRIG_REQUIRE_DATA(path, files[i]);
    const C3DClip clip = C3DClip::load(path);
    EXPECT_EQ(clip.pointCount(), points[i]) << files[i];
    EXPECT_EQ(clip.frameCount(), frames[i]) << files[i];
  }
}

}  // namespace
}  // namespace tetrig::drivers
