// Test-only C3D writer: builds small C3D files in memory from a spec (the spec is the ground
// truth the reader tests compare against). Written from the format's byte layout, independently
// of the reader's code paths except for the shared VAX float encoder, which has its own tests.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "tetrig/drivers/c3d_reader.hpp"

namespace tetrig::test {

// A parameter written as given (after the writer's own POINT parameters), e.g. with a hostile
// name or an invalid type.
struct TestC3DRawParam {
  std::string name;
  int group_id = 1;                  // 1 POINT, 2 TRIAL
  int type = -1;                     // written as is (the reader accepts -1, 1, 2, 4)
  std::vector<int> dims;
  std::vector<std::uint8_t> data;    // raw bytes (byte order is the caller's business)
};

struct TestC3DSpec {
  drivers::C3DProcessor processor = drivers::C3DProcessor::kIntel;
  bool floating = true;
  float scale = 0.5f;  // magnitude; written negative when floating
  float rate = 100.0f;
  std::string units = "mm";
  std::vector<std::string> labels;            // one per point
  std::size_t frames = 0;
  // frames * points samples, frame-major. Values for integer files should be multiples of scale.
  std::vector<std::array<float, 3>> xyz;
  std::vector<bool> valid;
  std::uint16_t analog_words = 0;             // analog values per frame (written as 7 / 7.0)
  std::uint16_t first_frame = 1;
  bool write_parameters = true;               // false: parameter header with 0 blocks, no entries
  std::optional<std::uint8_t> processor_byte_override;  // written instead of the processor type
  int header_data_start_override = -1;        // >= 0: header word 9 value
  std::optional<int> param_data_start;        // POINT:DATA_START value (default: the real block)
  int data_block_shift = 0;                   // extra empty blocks between parameters and data
  bool long_frame_fields = false;             // TRIAL:ACTUAL_START/END_FIELD as 32-bit numbers
  std::vector<std::pair<std::string, std::vector<std::string>>> point_string_params;  // e.g. ANGLES
  bool pad_to_block = true;
  // Non-empty: frames * points residual words written as given (float files: this value as a
  // float, e.g. 65535.0; int files: the low 16 bits of this integer, e.g. -1 or 0x8203), and
  // every sample's coordinates from xyz (`valid` is then not used by the writer).
  std::vector<double> fourth_words;
  int param_blocks_delta = 0;                 // added to the declared parameter block count
  int header_parameter_block = -1;            // >= 0: header byte 1 (the parameter block pointer)
  std::vector<TestC3DRawParam> extra_params;  // appended after the POINT parameters
  // Filled by writeTestC3D: byte offset where the frames start and where they end.
  mutable std::size_t data_offset = 0;
  mutable std::size_t data_end = 0;
};

class TestC3DWriter {
 public:
  explicit TestC3DWriter(const TestC3DSpec& spec) : s_(spec) {}

  std::vector<std::uint8_t> write() {
    const std::size_t points = s_.labels.size();
    // ---- parameter section ----
    std::vector<std::uint8_t> params;
    params.push_back(1);
    params.push_back(0x50);
    params.push_back(0);  // block count, patched below
    params.push_back(s_.processor_byte_override ? *s_.processor_byte_override
                                                : static_cast<std::uint8_t>(s_.processor));
    std::size_t data_block = 3;
    if (s_.write_parameters) {
      // Two passes: the data start depends on the section size, which does not depend on it.
      for (int pass = 0; pass < 2; ++pass) {
        params.resize(4);
        group(params, "POINT", 1);
        group(params, "TRIAL", 2);
        paramInt(params, 1, "USED", {static_cast<std::uint16_t>(points)});
        paramInt(params, 1, "FRAMES", {static_cast<std::uint16_t>(std::min<std::size_t>(s_.frames, 65535))});
        const int ds = s_.param_data_start ? *s_.param_data_start : static_cast<int>(data_block);
        paramInt(params, 1, "DATA_START", {static_cast<std::uint16_t>(ds)});
        paramFloat(params, 1, "SCALE", s_.floating ? -s_.scale : s_.scale);
        paramFloat(params, 1, "RATE", s_.rate);
        paramChars(params, 1, "UNITS", {s_.units});
        // At most 255 strings per parameter (dimensions are bytes): LABELS, LABELS2, LABELS3...
        for (std::size_t first = 0, part = 1; first < s_.labels.size() || part == 1; first += 255, ++part) {
          const std::size_t last = std::min(s_.labels.size(), first + 255);
          std::string pname = "LABELS";
          if (part > 1) pname += std::to_string(part);
          paramChars(params, 1, pname,
                     std::vector<std::string>(s_.labels.begin() + static_cast<std::ptrdiff_t>(first),
                                              s_.labels.begin() + static_cast<std::ptrdiff_t>(last)));
        }
        for (const auto& [name, values] : s_.point_string_params) paramChars(params, 1, name, values);
        for (const TestC3DRawParam& raw : s_.extra_params) {
          paramHead(params, raw.group_id, raw.name, raw.type, raw.dims);
          params.insert(params.end(), raw.data.begin(), raw.data.end());
          params.push_back(0);
        }
        if (s_.long_frame_fields) {
          const std::uint32_t first = s_.first_frame;
          const auto last = static_cast<std::uint32_t>(first + s_.frames - 1);
          paramInt(params, 2, "ACTUAL_START_FIELD",
                   {static_cast<std::uint16_t>(first & 0xffff), static_cast<std::uint16_t>(first >> 16)});
          paramInt(params, 2, "ACTUAL_END_FIELD",
                   {static_cast<std::uint16_t>(last & 0xffff), static_cast<std::uint16_t>(last >> 16)});
        }
        // Terminate: the last entry's offset is 0.
        putU16At(params, last_offset_pos_, 0);
        const std::size_t blocks = (params.size() + 511) / 512;
        data_block = 2 + blocks + static_cast<std::size_t>(s_.data_block_shift);
        params[2] = static_cast<std::uint8_t>(static_cast<int>(blocks) + s_.param_blocks_delta);
      }
    } else {
      data_block = 3 + static_cast<std::size_t>(s_.data_block_shift);
    }
    params.resize(((params.size() + 511) / 512) * 512, 0);
    if (params.empty()) params.resize(512, 0);

    // ---- header ----
    std::vector<std::uint8_t> file(512, 0);
    file[0] = static_cast<std::uint8_t>(s_.header_parameter_block >= 0 ? s_.header_parameter_block : 2);
    file[1] = 0x50;
    putU16At(file, 2, static_cast<std::uint16_t>(points));
    putU16At(file, 4, s_.analog_words);
    putU16At(file, 6, s_.first_frame);
    const std::size_t last = s_.first_frame + s_.frames - 1;
    putU16At(file, 8, static_cast<std::uint16_t>(std::min<std::size_t>(last, 65535)));
    putU16At(file, 10, 10);
    putFloatAt(file, 12, s_.floating ? -s_.scale : s_.scale);
    putU16At(file, 16, static_cast<std::uint16_t>(s_.header_data_start_override >= 0 ? s_.header_data_start_override
                                                                                     : static_cast<int>(data_block)));
    putU16At(file, 18, s_.analog_words == 0 ? 0 : 1);
    putFloatAt(file, 20, s_.rate);
    file.insert(file.end(), params.begin(), params.end());
    file.resize((data_block - 1) * 512, 0);

    // ---- data ----
    s_.data_offset = file.size();
    for (std::size_t f = 0; f < s_.frames; ++f) {
      for (std::size_t p = 0; p < points; ++p) {
        const std::size_t k = f * points + p;
        const bool raw_word = !s_.fourth_words.empty();
        const bool ok = raw_word || s_.valid[k];
        for (int c = 0; c < 3; ++c) {
          const float v = ok ? s_.xyz[k][static_cast<std::size_t>(c)] : 0.0f;
          if (s_.floating) {
            appendFloat(file, v);
          } else {
            appendU16(file, static_cast<std::uint16_t>(static_cast<std::int16_t>(std::lround(v / s_.scale))));
          }
        }
        // Residual word: cameras 0x02 in the high byte, residual 3 in the low byte; -1 invalid.
        if (raw_word) {
          const double w = s_.fourth_words[k];
          if (s_.floating) {
            appendFloat(file, static_cast<float>(w));
          } else {
            appendU16(file, static_cast<std::uint16_t>(static_cast<std::int64_t>(w) & 0xffff));
          }
        } else if (s_.floating) {
          appendFloat(file, ok ? 515.0f : -1.0f);
        } else {
          appendU16(file, ok ? std::uint16_t{0x0203} : std::uint16_t{0xffff});
        }
      }
      for (int a = 0; a < s_.analog_words; ++a) {
        if (s_.floating) {
          appendFloat(file, 7.0f);
        } else {
          appendU16(file, 7);
        }
      }
    }
    s_.data_end = file.size();
    if (s_.pad_to_block) file.resize(((file.size() + 511) / 512) * 512, 0);
    return file;
  }

 private:
  bool bigEndian() const { return s_.processor == drivers::C3DProcessor::kMips; }

  void putU16At(std::vector<std::uint8_t>& b, std::size_t at, std::uint16_t v) const {
    if (bigEndian()) {
      b[at] = static_cast<std::uint8_t>(v >> 8);
      b[at + 1] = static_cast<std::uint8_t>(v & 0xff);
    } else {
      b[at] = static_cast<std::uint8_t>(v & 0xff);
      b[at + 1] = static_cast<std::uint8_t>(v >> 8);
    }
  }
  void floatBytes(float v, std::uint8_t out[4]) const {
    if (s_.processor == drivers::C3DProcessor::kDec) {
      drivers::encodeVaxFloat(v, out);
      return;
    }
    const auto bits = std::bit_cast<std::uint32_t>(v);
    for (int i = 0; i < 4; ++i) {
      const int shift = bigEndian() ? 24 - 8 * i : 8 * i;
      out[i] = static_cast<std::uint8_t>((bits >> shift) & 0xff);
    }
  }
  void putFloatAt(std::vector<std::uint8_t>& b, std::size_t at, float v) const {
    std::uint8_t x[4];
    floatBytes(v, x);
    std::memcpy(&b[at], x, 4);
  }
  void appendU16(std::vector<std::uint8_t>& b, std::uint16_t v) const {
    b.resize(b.size() + 2);
    putU16At(b, b.size() - 2, v);
  }
  void appendFloat(std::vector<std::uint8_t>& b, float v) const {
    b.resize(b.size() + 4);
    putFloatAt(b, b.size() - 4, v);
  }

  // Entry: name length, id, name, offset (patched when the next entry starts), content.
  void beginEntry(std::vector<std::uint8_t>& b, const std::string& name, int id) {
    if (have_last_) putU16At(b, last_offset_pos_, static_cast<std::uint16_t>(b.size() - last_offset_pos_));
    b.push_back(static_cast<std::uint8_t>(name.size()));
    b.push_back(static_cast<std::uint8_t>(static_cast<std::int8_t>(id)));
    b.insert(b.end(), name.begin(), name.end());
    last_offset_pos_ = b.size();
    have_last_ = true;
    appendU16(b, 0);
  }
  void group(std::vector<std::uint8_t>& b, const std::string& name, int id) {
    if (b.size() == 4) have_last_ = false;
    beginEntry(b, name, -id);
    b.push_back(0);  // no description
  }
  void paramHead(std::vector<std::uint8_t>& b, int gid, const std::string& name, int type,
                 const std::vector<int>& dims) {
    beginEntry(b, name, gid);
    b.push_back(static_cast<std::uint8_t>(static_cast<std::int8_t>(type)));
    b.push_back(static_cast<std::uint8_t>(dims.size()));
    for (int d : dims) b.push_back(static_cast<std::uint8_t>(d));
  }
  void paramInt(std::vector<std::uint8_t>& b, int gid, const std::string& name, const std::vector<std::uint16_t>& v) {
    paramHead(b, gid, name, 2, v.size() == 1 ? std::vector<int>{} : std::vector<int>{static_cast<int>(v.size())});
    for (std::uint16_t x : v) appendU16(b, x);
    b.push_back(0);
  }
  void paramFloat(std::vector<std::uint8_t>& b, int gid, const std::string& name, float v) {
    paramHead(b, gid, name, 4, {});
    appendFloat(b, v);
    b.push_back(0);
  }
  void paramChars(std::vector<std::uint8_t>& b, int gid, const std::string& name, const std::vector<std::string>& v) {
    std::size_t len = 1;
    for (const std::string& s : v) len = std::max(len, s.size());
    paramHead(b, gid, name, -1, {static_cast<int>(len), static_cast<int>(v.size())});
    for (const std::string& s : v) {
      std::string padded = s;
      padded.resize(len, ' ');
      b.insert(b.end(), padded.begin(), padded.end());
    }
    b.push_back(0);
  }

  const TestC3DSpec& s_;
  std::size_t last_offset_pos_ = 0;
  bool have_last_ = false;
};

inline std::vector<std::uint8_t> writeTestC3D(const TestC3DSpec& spec) { return TestC3DWriter(spec).write(); }

// A small spec: `points` markers named M0.., `frames` frames, values on the scale grid,
// deterministic pattern with a few invalid samples.
inline TestC3DSpec smallSpec(drivers::C3DProcessor proc, bool floating, std::size_t points = 3,
                             std::size_t frames = 4) {
  TestC3DSpec s;
  s.processor = proc;
  s.floating = floating;
  s.scale = 0.5f;
  s.rate = 100.0f;
  s.frames = frames;
  for (std::size_t p = 0; p < points; ++p) {
    std::string label = "M";  // (not "M" + to_string: GCC 12 -Wrestrict false positive)
    label += std::to_string(p);
    s.labels.push_back(label);
  }
  for (std::size_t f = 0; f < frames; ++f) {
    for (std::size_t p = 0; p < points; ++p) {
      const float base = static_cast<float>(f * 10 + p);
      s.xyz.push_back({base * 0.5f + 1.0f, -base * 1.5f, 100.0f + base * 2.0f});
      s.valid.push_back((f + p) % 5 != 3);
    }
  }
  return s;
}

}  // namespace tetrig::test
