// C3D file reader: header block, parameter section and 3-D point data of the C3D format
// (c3d.org, "The C3D File Format User Guide"), Intel/DEC/MIPS processor types, float and scaled
// int16 storage. Written from the published byte layout; see c3d_reader.hpp for the decisions.
#include "tetrig/drivers/c3d_reader.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <optional>
#include <string>
#include <unordered_map>
#include <unordered_set>

namespace tetrig::drivers {

namespace {

constexpr std::size_t kBlockSize = 512;
constexpr std::uint8_t kKey = 0x50;

std::string upper(std::string_view s) {
  std::string out(s);
  for (char& c : out) {
    if (c >= 'a' && c <= 'z') c = static_cast<char>(c - 'a' + 'A');
  }
  return out;
}

bool equalsNoCase(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    char x = a[i];
    char y = b[i];
    if (x >= 'a' && x <= 'z') x = static_cast<char>(x - 'a' + 'A');
    if (y >= 'a' && y <= 'z') y = static_cast<char>(y - 'a' + 'A');
    if (x != y) return false;
  }
  return true;
}

std::string trim(std::string_view s) {
  std::size_t b = 0;
  std::size_t e = s.size();
  auto blank = [](char c) { return c == ' ' || c == '\0' || c == '\t' || c == '\r' || c == '\n'; };
  while (b < e && blank(s[b])) ++b;
  while (e > b && blank(s[e - 1])) --e;
  return std::string(s.substr(b, e - b));
}

// Longest piece of file text (name, label, unit) quoted in a message, in characters of the input.
constexpr std::size_t kMaxQuotedChars = 40;

// Printable form of a name read from the file, for messages: bytes outside printable ASCII are
// shown as \xNN, and text longer than kMaxQuotedChars is cut there and ends in "...". A message
// never carries raw file bytes (a name may hold terminal escape sequences or binary junk).
std::string printable(std::string_view s) {
  const bool cut = s.size() > kMaxQuotedChars;
  if (cut) s = s.substr(0, kMaxQuotedChars);
  std::string out;
  for (char c : s) {
    const auto u = static_cast<unsigned char>(c);
    if (u >= 0x20 && u < 0x7f) {
      out.push_back(c);
    } else {
      static const char* kHex = "0123456789abcdef";
      out += "\\x";
      out.push_back(kHex[u >> 4]);
      out.push_back(kHex[u & 0xf]);
    }
  }
  if (cut) out += "...";
  return out;
}

bool isUnlabeledName(std::string_view label) {
  if (label.empty()) return true;
  const std::size_t colon = label.rfind(':');
  if (colon != std::string_view::npos) label = label.substr(colon + 1);
  if (label.size() < 2 || label[0] != '*') return false;
  for (std::size_t i = 1; i < label.size(); ++i) {
    if (label[i] < '0' || label[i] > '9') return false;
  }
  return true;
}

std::optional<double> unitsToMillimetres(std::string_view units) {
  const std::string u = upper(units);
  if (u == "MM" || u == "MILLIMETERS" || u == "MILLIMETRES") return 1.0;
  if (u == "CM") return 10.0;
  if (u == "DM") return 100.0;
  if (u == "M" || u == "METERS" || u == "METRES") return 1000.0;
  if (u == "IN" || u == "INCH" || u == "INCHES") return 25.4;
  if (u == "FT" || u == "FEET") return 304.8;
  return std::nullopt;
}

}  // namespace

float decodeVaxFloat(const std::uint8_t bytes[4]) noexcept {
  // VAX F_floating: two little-endian 16-bit words, the first holding sign, 8-bit exponent
  // (excess 128) and the high 7 fraction bits, the second the low 16 fraction bits; value
  // 0.1f * 2^(e-128). Swapping the words gives IEEE's bit layout, whose value 1.f * 2^(e-127)
  // is 4x the VAX value.
  const std::uint32_t bits = static_cast<std::uint32_t>(bytes[2]) | (static_cast<std::uint32_t>(bytes[3]) << 8) |
                             (static_cast<std::uint32_t>(bytes[0]) << 16) |
                             (static_cast<std::uint32_t>(bytes[1]) << 24);
  const std::uint32_t exponent = (bits >> 23) & 0xffu;
  if (exponent == 0) {
    return (bits & 0x80000000u) != 0 ? std::numeric_limits<float>::quiet_NaN() : 0.0f;
  }
  return std::bit_cast<float>(bits) * 0.25f;
}

void encodeVaxFloat(float value, std::uint8_t bytes[4]) noexcept {
  std::uint32_t bits = 0;
  if (value != 0.0f && std::isfinite(value)) {
    const float ieee = value * 4.0f;  // exact unless it overflows; callers keep |value| < 1e37
    bits = std::bit_cast<std::uint32_t>(ieee);
    if (((bits >> 23) & 0xffu) == 0) bits = 0;  // too small for VAX: flush to zero
  }
  bytes[0] = static_cast<std::uint8_t>((bits >> 16) & 0xffu);
  bytes[1] = static_cast<std::uint8_t>((bits >> 24) & 0xffu);
  bytes[2] = static_cast<std::uint8_t>(bits & 0xffu);
  bytes[3] = static_cast<std::uint8_t>((bits >> 8) & 0xffu);
}

class C3DParser {
 public:
  C3DParser(std::span<const std::uint8_t> bytes, std::string_view name, const C3DReadOptions& options)
      : d_(bytes), name_(name), options_(options) {}

  C3DClip run() {
    clip_.source_name_ = name_;
    readHeaderAndProcessor();
    readParameters();
    resolve();
    readData();
    return std::move(clip_);
  }

 private:
  [[noreturn]] void fail(std::size_t offset, const std::string& what) const {
    throw C3DError(name_ + ": " + what + " (at byte " + std::to_string(offset) + ")");
  }

  void need(std::size_t offset, std::size_t count, const std::string& what) const {
    if (offset > d_.size() || count > d_.size() - offset) {
      fail(offset, "truncated file: expected " + std::to_string(count) + " bytes of " + what + ", file ends at byte " +
                       std::to_string(d_.size()));
    }
  }

  std::uint16_t u16(std::size_t off) const {
    const std::uint8_t a = d_[off];
    const std::uint8_t b = d_[off + 1];
    return big_endian_ ? static_cast<std::uint16_t>((a << 8) | b) : static_cast<std::uint16_t>((b << 8) | a);
  }
  std::int16_t i16(std::size_t off) const { return static_cast<std::int16_t>(u16(off)); }
  float f32(std::size_t off) const { return floatAs(clip_.processor_, &d_[off]); }

  static float floatAs(C3DProcessor proc, const std::uint8_t* p) {
    switch (proc) {
      case C3DProcessor::kDec:
        return decodeVaxFloat(p);
      case C3DProcessor::kMips: {
        const std::uint32_t bits = (static_cast<std::uint32_t>(p[0]) << 24) | (static_cast<std::uint32_t>(p[1]) << 16) |
                                   (static_cast<std::uint32_t>(p[2]) << 8) | static_cast<std::uint32_t>(p[3]);
        return std::bit_cast<float>(bits);
      }
      case C3DProcessor::kIntel:
      default: {
        const std::uint32_t bits = static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
                                   (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
        return std::bit_cast<float>(bits);
      }
    }
  }

  void warn(std::string text) { clip_.warnings_.push_back(std::move(text)); }

  // ---- header ----
  void readHeaderAndProcessor() {
    need(0, kBlockSize, "the header block");
    if (d_[1] != kKey) {
      fail(1, "not a C3D file: header byte 2 is " + std::to_string(d_[1]) + ", expected the key 80 (0x50)");
    }
    const std::uint8_t param_block = d_[0];
    clip_.header_.parameter_block = param_block;
    std::optional<C3DProcessor> proc;
    if (param_block >= 2) {
      param_start_ = (static_cast<std::size_t>(param_block) - 1) * kBlockSize;
      need(param_start_, 4, "the parameter section header (parameter block " + std::to_string(param_block) + ")");
      has_param_header_ = true;
      param_blocks_ = d_[param_start_ + 2];
      const std::uint8_t p = d_[param_start_ + 3];
      if (p != 84 && p != 85 && p != 86) {
        // Every number in the file depends on it: guessing could decode the data as garbage.
        fail(param_start_ + 3, "unknown processor type " + std::to_string(p) +
                                   " in the parameter section header (parameter block " + std::to_string(param_block) +
                                   "; expected 84 Intel, 85 DEC or 86 MIPS/SGI): the file is damaged or not a C3D file");
      }
      proc = static_cast<C3DProcessor>(p);
      if (d_[param_start_ + 1] != kKey) {
        warn("parameter section key is " + std::to_string(d_[param_start_ + 1]) + ", expected 80");
      }
    } else {
      warn("header names parameter block " + std::to_string(param_block) + ": no parameter section");
    }
    if (!proc) proc = guessProcessor();
    clip_.processor_ = *proc;
    big_endian_ = *proc == C3DProcessor::kMips;

    C3DHeader& h = clip_.header_;
    h.point_count = u16(2);
    h.analog_words = u16(4);
    h.first_frame = u16(6);
    h.last_frame = u16(8);
    h.max_gap = u16(10);
    h.scale = f32(12);
    h.data_start_block = u16(16);
    h.analog_samples_per_frame = u16(18);
    h.frame_rate = f32(20);
  }

  C3DProcessor guessProcessor() {
    for (C3DProcessor p : {C3DProcessor::kIntel, C3DProcessor::kDec, C3DProcessor::kMips}) {
      big_endian_ = p == C3DProcessor::kMips;
      const float scale = floatAs(p, &d_[12]);
      const float rate = floatAs(p, &d_[20]);
      const std::uint16_t first = u16(6);
      const std::uint16_t last = u16(8);
      // Normal (not denormal) numbers in sane ranges: a float read with the wrong byte order
      // or format is almost always denormal, zero or huge.
      const bool plausible = std::isnormal(scale) && std::fabs(scale) > 1e-9f && std::fabs(scale) < 1e6f &&
                             std::isnormal(rate) && rate > 1e-3f && rate <= 1e6f && first >= 1 && last >= first;
      if (plausible) {
        warn("processor type guessed as " + std::to_string(static_cast<int>(p)) + " from the header's scale and rate");
        return p;
      }
    }
    warn("processor type unknown; assumed Intel");
    return C3DProcessor::kIntel;
  }

  // ---- parameters ----
  void readParameters() {
    if (!has_param_header_) return;
    const C3DHeader& h = clip_.header_;
    // Entries may run up to the data start (the header's data block when it lies after the
    // parameter block, else the end of the file; always bounded by the file): the declared block
    // count is only a claim, and some writers set it too small (their LABELS runs past it). When
    // the header's block is not usable, resolve() checks the entries against the block used.
    const bool header_ds_after_params = h.data_start_block > h.parameter_block;
    const std::size_t header_ds_offset = (static_cast<std::size_t>(h.data_start_block) - 1) * kBlockSize;
    const std::size_t end = header_ds_after_params ? std::min(header_ds_offset, d_.size()) : d_.size();
    std::size_t declared_end = 0;
    if (param_blocks_ > 0) {
      declared_end = param_start_ + static_cast<std::size_t>(param_blocks_) * kBlockSize;
      std::size_t present = declared_end;
      if (header_ds_after_params && header_ds_offset < declared_end) {
        warn("parameter section declares " + std::to_string(param_blocks_) + " blocks but the data starts at block " +
             std::to_string(h.data_start_block) + "; parameters read up to the data");
        present = header_ds_offset;
      }
      need(param_start_, present - param_start_,
           "the parameter section (" + std::to_string(param_blocks_) + " blocks from block " +
               std::to_string(h.parameter_block) + ")");
    }
    const std::string end_what = end == d_.size() ? "the end of the file"
                                                  : "the data start (block " + std::to_string(h.data_start_block) + ")";

    struct GroupName {
      int id;
      std::string name;
    };
    std::vector<GroupName> groups;
    std::vector<int> param_group_ids;
    std::size_t p = param_start_ + 4;
    while (true) {
      if (p + 2 > end) {
        if (p + 2 > d_.size()) need(p, 2, "a parameter entry header");
        warn("parameter section ends without a terminating entry at byte " + std::to_string(p));
        break;
      }
      const int name_len_signed = static_cast<std::int8_t>(d_[p]);
      const int id = static_cast<std::int8_t>(d_[p + 1]);
      if (name_len_signed == 0 || id == 0) break;  // end of the parameter list
      const std::size_t name_len = static_cast<std::size_t>(std::abs(name_len_signed));
      const std::size_t q = p + 2 + name_len;  // offset field
      inSection(p, 2 + name_len + 2, end, "a parameter/group name and its next-entry offset");
      const std::string name(reinterpret_cast<const char*>(&d_[p + 2]), name_len);
      const std::int16_t next_offset = i16(q);  // signed: a negative offset would point backwards
      std::size_t content_end = q + 2;  // where the next entry may start (descriptions may be cut)
      if (id < 0) {
        inSection(q + 2, 1, end, "the description length of group '" + printable(name) + "'");
        groups.push_back({-id, upper(name)});
      } else {
        inSection(q + 2, 2, end, "the type and dimension count of parameter '" + printable(name) + "'");
        C3DParameter param;
        param.name = upper(name);
        param.offset = p;
        param.type = static_cast<std::int8_t>(d_[q + 2]);
        const std::size_t ndims = d_[q + 3];
        if (param.type != -1 && param.type != 1 && param.type != 2 && param.type != 4) {
          fail(q + 2, "corrupt parameter '" + printable(name) + "': type " + std::to_string(param.type) +
                          " (expected -1 char, 1 byte, 2 int16 or 4 float)");
        }
        inSection(q + 4, ndims, end, "the dimensions of parameter '" + printable(name) + "'");
        const std::size_t elem = static_cast<std::size_t>(std::abs(param.type));
        const std::size_t data = q + 4 + ndims;
        for (std::size_t k = 0; k < ndims; ++k) param.dimensions.push_back(d_[q + 4 + k]);
        // Up to 255 dimensions of up to 255 each: the product overflows any integer type, so
        // it is checked at every step against what the rest of the file could hold (a zero
        // dimension makes the parameter empty, whatever the others say); a product that fits
        // the file is then checked against the section by inSection below.
        const bool empty = std::find(param.dimensions.begin(), param.dimensions.end(), 0) != param.dimensions.end();
        const std::size_t room = data <= d_.size() ? (d_.size() - data) / elem : 0;
        std::uint64_t count = empty ? 0 : 1;
        for (std::size_t k = 0; k < ndims && count > 0; ++k) {
          const std::uint64_t dim = param.dimensions[k];
          if (count > room / dim) {
            fail(q + 4 + k, "corrupt parameter '" + printable(name) + "': its dimensions (" + dimensionsText(param.dimensions) +
                                ") give more " + std::to_string(elem) + "-byte elements than the " + std::to_string(d_.size() - data) +
                                " bytes left in the file");
          }
          count *= dim;
        }
        const std::uint64_t bytes = count * elem;
        inSection(data, bytes, end, "the data of parameter '" + printable(name) + "'");
        content_end = data + static_cast<std::size_t>(bytes);
        const std::size_t n = static_cast<std::size_t>(count);
        switch (param.type) {
          case -1:
            param.chars.assign(reinterpret_cast<const char*>(&d_[data]), n);
            break;
          case 1:
            for (std::size_t k = 0; k < n; ++k) param.numbers.push_back(d_[data + k]);
            break;
          case 2:
            for (std::size_t k = 0; k < n; ++k) {
              param.words.push_back(u16(data + 2 * k));
              param.numbers.push_back(i16(data + 2 * k));
            }
            break;
          default:
            for (std::size_t k = 0; k < n; ++k) param.numbers.push_back(f32(data + 4 * k));
            break;
        }
        clip_.parameters_.push_back(std::move(param));
        param_group_ids.push_back(id);
      }
      if (content_end > params_extent_) {
        params_extent_ = content_end;
        params_extent_entry_ = p;
      }
      if (next_offset == 0) break;
      // The chain only moves forward, past the entry's own data (its description may be cut
      // short: mocap36.c3d's LABELS points at the byte after its data), and stays in the section.
      auto entry = [&] { return describeEntry(p) + " at byte " + std::to_string(p); };
      if (next_offset < 0) {
        fail(q, "corrupt parameter section: " + entry() + " gives the next entry at offset " +
                    std::to_string(next_offset) + ", backwards");
      }
      const std::size_t next = q + static_cast<std::size_t>(next_offset);
      if (next < content_end) {
        fail(q, "corrupt parameter section: " + entry() + " gives the next entry at byte " + std::to_string(next) +
                    ", inside its own data (which ends at byte " + std::to_string(content_end) + ")");
      }
      if (next > end) {
        fail(q, "corrupt parameter section: " + entry() + " gives the next entry at byte " + std::to_string(next) +
                    ", past " + end_what + " at byte " + std::to_string(end));
      }
      p = next;
    }
    if (param_blocks_ > 0 && params_extent_ > declared_end) {
      warn("parameter section declares " + std::to_string(param_blocks_) + (param_blocks_ == 1 ? " block" : " blocks") +
           " (to byte " +
           std::to_string(declared_end) + ") but its entries run to byte " + std::to_string(params_extent_) +
           " (" + describeEntry(params_extent_entry_) + "); read up to " + end_what);
    }
    for (std::size_t i = 0; i < clip_.parameters_.size(); ++i) {
      std::string group = "?" + std::to_string(param_group_ids[i]);
      for (const GroupName& g : groups) {
        if (g.id == param_group_ids[i]) group = g.name;
      }
      clip_.parameters_[i].group = std::move(group);
    }
  }

  static std::string dimensionsText(const std::vector<int>& dims) {
    std::string out;
    for (std::size_t k = 0; k < dims.size() && k < 8; ++k) out += (k ? " x " : "") + std::to_string(dims[k]);
    if (dims.size() > 8) out += " x ... (" + std::to_string(dims.size()) + " dimensions)";
    return out;
  }

  // "parameter 'NAME'" or "group 'NAME'" for the entry at byte `p` (whose name was bounds-checked
  // when it was read), the name escaped and cut, for messages.
  std::string describeEntry(std::size_t p) const {
    const int name_len = std::abs(static_cast<int>(static_cast<std::int8_t>(d_[p])));
    const std::string_view name(reinterpret_cast<const char*>(&d_[p + 2]), static_cast<std::size_t>(name_len));
    return (static_cast<std::int8_t>(d_[p + 1]) < 0 ? "group '" : "parameter '") + printable(name) + "'";
  }

  void inSection(std::size_t offset, std::uint64_t count, std::size_t end, const std::string& what) const {
    if (offset > end || count > end - offset) {
      if (end >= d_.size() || offset > d_.size() || count > d_.size() - offset) {
        need(offset, static_cast<std::size_t>(std::min<std::uint64_t>(count, std::numeric_limits<std::size_t>::max() / 2)),
             what);
      }
      fail(offset, "corrupt parameter section: " + what + " (" + std::to_string(count) +
                       " bytes) runs into the data, which starts at byte " + std::to_string(end));
    }
  }

  // ---- arbitration ----
  const C3DParameter* param(std::string_view g, std::string_view n) const { return clip_.findParameter(g, n); }

  void resolve() {
    const C3DHeader& h = clip_.header_;
    // Scale and storage format.
    float scale = h.scale;
    if (!std::isfinite(scale) || scale == 0.0f) {
      const C3DParameter* ps = param("POINT", "SCALE");
      if (ps != nullptr && !ps->numbers.empty() && std::isfinite(ps->numbers[0]) && ps->numbers[0] != 0.0) {
        warn("header scale factor is unusable; POINT:SCALE used");
        scale = static_cast<float>(ps->numbers[0]);
      }
    }
    clip_.is_float_ = std::signbit(scale);
    clip_.scale_ = std::fabs(scale);
    if (!std::isfinite(clip_.scale_) || (!clip_.is_float_ && clip_.scale_ == 0.0f && h.point_count > 0)) {
      fail(12, "invalid scale factor " + std::to_string(scale) + " (int16 data needs a finite, non-zero scale)");
    }
    if (!std::isfinite(clip_.scale_)) clip_.scale_ = 1.0f;
    clip_.point_count_ = h.point_count;
    if (const C3DParameter* used = param("POINT", "USED"); used != nullptr && !used->words.empty() &&
                                                            used->words[0] != h.point_count) {
      warn("POINT:USED is " + std::to_string(used->words[0]) + " but the header says " + std::to_string(h.point_count) +
           " points; the header wins");
    }

    // Frame rate.
    clip_.frame_rate_ = h.frame_rate;
    if (!std::isfinite(clip_.frame_rate_) || clip_.frame_rate_ <= 0.0) {
      const C3DParameter* pr = param("POINT", "RATE");
      if (pr != nullptr && !pr->numbers.empty() && std::isfinite(pr->numbers[0]) && pr->numbers[0] > 0.0) {
        clip_.frame_rate_ = pr->numbers[0];
      } else {
        clip_.frame_rate_ = 0.0;
        warn("no usable frame rate in the header or POINT:RATE");
      }
    }

    // Frame count.
    std::uint64_t count = h.last_frame >= h.first_frame ? std::uint64_t{h.last_frame} - h.first_frame + 1 : 0;
    clip_.first_frame_number_ = h.first_frame;
    std::uint64_t long_count = 0;
    std::uint32_t long_first = 0;
    const C3DParameter* ts = param("TRIAL", "ACTUAL_START_FIELD");
    const C3DParameter* te = param("TRIAL", "ACTUAL_END_FIELD");
    if (ts != nullptr && te != nullptr && ts->words.size() >= 2 && te->words.size() >= 2) {
      const std::uint32_t s = ts->words[0] | (static_cast<std::uint32_t>(ts->words[1]) << 16);
      const std::uint32_t e = te->words[0] | (static_cast<std::uint32_t>(te->words[1]) << 16);
      if (e >= s) {
        long_count = std::uint64_t{e} - s + 1;
        long_first = s;
      }
    }
    auto consider = [&](const C3DParameter* pf) {
      if (pf == nullptr || pf->numbers.empty()) return;
      double v = pf->type == 2 && !pf->words.empty() ? double(pf->words[0]) : pf->numbers[0];
      if (std::isfinite(v) && v > double(long_count) && v < 4.3e9) {
        long_count = static_cast<std::uint64_t>(v);
        long_first = 1;
      }
    };
    if (long_count <= 65535) {
      consider(param("POINT", "LONG_FRAMES"));
      if (const C3DParameter* pf = param("POINT", "FRAMES"); pf != nullptr && pf->type == 4) consider(pf);
    }
    if (long_count > 65535 || (count == 0 && long_count > 0)) {
      if (long_count != count) {
        warn("frame count " + std::to_string(long_count) + " taken from the parameters (header says " +
             std::to_string(count) + ")");
      }
      count = long_count;
      clip_.first_frame_number_ = long_first;
    }

    // Data start block.
    const std::size_t word = clip_.is_float_ ? 4 : 2;
    frame_bytes_ = (4 * std::size_t{h.point_count} + h.analog_words) * word;
    auto impossible = [&](std::uint32_t block) {
      return block < 2 || (has_param_header_ && block <= h.parameter_block);
    };
    auto fits = [&](std::uint32_t block) {
      const std::uint64_t start = (std::uint64_t{block} - 1) * kBlockSize;
      return start <= d_.size() && count * frame_bytes_ <= d_.size() - start;
    };
    std::optional<std::uint32_t> param_ds;
    if (const C3DParameter* pd = param("POINT", "DATA_START"); pd != nullptr && !pd->words.empty()) {
      param_ds = pd->words[0];
    }
    std::uint32_t ds = h.data_start_block;
    const bool param_usable = param_ds && !impossible(*param_ds) && fits(*param_ds);
    if (!impossible(ds) && (fits(ds) || !param_usable)) {
      if (param_ds && *param_ds != ds) {
        warn("POINT:DATA_START is block " + std::to_string(*param_ds) + " but the header says block " +
             std::to_string(ds) + "; the header wins");
      }
    } else if (param_ds && !impossible(*param_ds)) {
      warn("header data start block " + std::to_string(ds) + " is " + (impossible(ds) ? "impossible" : "too late") +
           "; POINT:DATA_START block " + std::to_string(*param_ds) + " used");
      ds = *param_ds;
    } else {
      fail(16, "data start block " + std::to_string(ds) + " in the header" +
                   (param_ds ? " (and " + std::to_string(*param_ds) + " in POINT:DATA_START)" : std::string()) +
                   " points into the header or parameter section (parameter block " +
                   std::to_string(h.parameter_block) + ")");
    }
    // The header's block bounded the entries already; a block from POINT:DATA_START is checked
    // here: parameters and frames must not share bytes.
    const std::size_t data_offset = (std::size_t{ds} - 1) * kBlockSize;
    if (params_extent_ > data_offset) {
      fail(data_offset, "corrupt parameter section: " + describeEntry(params_extent_entry_) + " runs to byte " +
                            std::to_string(params_extent_) + ", into the frames, which start at block " +
                            std::to_string(ds));
    }
    clip_.data_start_block_ = ds;
    clip_.frame_count_ = static_cast<std::size_t>(count);

    // Units.
    if (const C3DParameter* pu = param("POINT", "UNITS"); pu != nullptr && pu->type == -1) {
      clip_.units_ = trim(pu->chars);
    }
    if (clip_.units_.empty()) {
      warn("no POINT:UNITS; millimetres assumed");
    } else if (const auto mm = unitsToMillimetres(clip_.units_)) {
      clip_.units_to_mm_ = *mm;
    } else {
      warn("unknown POINT:UNITS '" + printable(clip_.units_) + "'; millimetres assumed");
    }

    resolveLabels();
  }

  static std::vector<std::string> splitStrings(const C3DParameter& p) {
    std::vector<std::string> out;
    if (p.type != -1) return out;
    if (p.dimensions.empty()) {
      out.push_back(trim(p.chars));
      return out;
    }
    const std::size_t len = static_cast<std::size_t>(p.dimensions[0]);
    if (len == 0) return out;
    const std::size_t n = p.chars.size() / len;
    for (std::size_t i = 0; i < n; ++i) out.push_back(trim(std::string_view(p.chars).substr(i * len, len)));
    return out;
  }

  void resolveLabels() {
    const std::size_t n = static_cast<std::size_t>(clip_.point_count_);
    // POINT parameters by name: list lookups below stay O(1) even for hostile TYPE_GROUPS.
    std::unordered_map<std::string, const C3DParameter*> point_params;
    for (const C3DParameter& p : clip_.parameters_) {
      if (p.group == "POINT") point_params.emplace(p.name, &p);
    }
    auto pointParam = [&](const std::string& name) -> const C3DParameter* {
      const auto it = point_params.find(name);
      return it == point_params.end() ? nullptr : it->second;
    };
    std::vector<std::string> all;
    bool any_labels = false;
    if (const C3DParameter* pl = param("POINT", "LABELS")) {
      any_labels = true;
      all = splitStrings(*pl);
      for (int k = 2; all.size() < n; ++k) {
        const C3DParameter* more = pointParam("LABELS" + std::to_string(k));
        if (more == nullptr) break;
        const std::vector<std::string> extra = splitStrings(*more);
        all.insert(all.end(), extra.begin(), extra.end());
      }
    }
    all.resize(n);
    std::unordered_set<std::string> modelled;
    std::unordered_set<std::string> lists = {"ANGLES", "FORCES", "MOMENTS", "POWERS", "REACTIONS", "SCALARS"};
    if (const C3DParameter* tg = pointParam("TYPE_GROUPS")) {
      for (const std::string& s : splitStrings(*tg)) {
        if (!s.empty()) lists.insert(upper(s));
      }
    }
    for (const std::string& list : lists) {
      if (list == "LABELS" || list.rfind("LABELS", 0) == 0 || list == "DESCRIPTIONS") continue;
      if (const C3DParameter* pm = pointParam(list)) {
        for (std::string& s : splitStrings(*pm)) {
          if (!s.empty()) modelled.insert(std::move(s));
        }
      }
    }
    // Plug-in Gait segment axes: complete quadruples XXXO/XXXA/XXXL/XXXP (origin, anterior,
    // lateral, proximal) sharing a 3-character name, and the centre-of-mass outputs. A lone
    // "LCLA" (a real clavicle marker) is not a quadruple and stays a marker.
    std::unordered_set<std::string> bare_names;
    auto bare = [](const std::string& label) {
      const std::size_t colon = label.rfind(':');
      return colon == std::string::npos ? label : label.substr(colon + 1);
    };
    for (const std::string& label : all) bare_names.insert(bare(label));
    auto segmentAxis = [&](const std::string& label) {
      const std::string b = bare(label);
      if (b.size() != 4 || std::string_view("OALP").find(b[3]) == std::string_view::npos) return false;
      const std::string stem = b.substr(0, 3);
      for (const char* suffix : {"O", "A", "L", "P"}) {
        if (bare_names.count(stem + suffix) == 0) return false;
      }
      return true;
    };
    auto centreOfMass = [&](const std::string& label) {
      const std::string b = bare(label);
      return b.rfind("CentreOfMass", 0) == 0 || b.rfind("CenterOfMass", 0) == 0;
    };
    clip_.kinds_.assign(n, C3DPointKind::kMarker);
    for (std::size_t i = 0; i < n; ++i) {
      if (modelled.count(all[i]) != 0 || segmentAxis(all[i]) || centreOfMass(all[i])) {
        clip_.kinds_[i] = C3DPointKind::kModelled;
      } else if (any_labels && isUnlabeledName(all[i])) {
        clip_.kinds_[i] = C3DPointKind::kUnlabeled;
      }
    }
    clip_.labels_ = std::move(all);
  }

  // ---- data ----
  void readData() {
    const std::size_t points = static_cast<std::size_t>(clip_.point_count_);
    const std::size_t frames = clip_.frame_count_;
    const std::size_t start = (std::size_t{clip_.data_start_block_} - 1) * kBlockSize;
    if (frames > 0) {
      // Report the first frame that does not fit, with its own offset.
      const std::size_t available = d_.size() > start ? d_.size() - start : 0;
      const std::size_t whole = frame_bytes_ == 0 ? frames : available / frame_bytes_;
      if (whole < frames) {
        fail(start + whole * frame_bytes_, "truncated data: frame " + std::to_string(whole) + " of " +
                                               std::to_string(frames) + " needs " + std::to_string(frame_bytes_) +
                                               " bytes (frames start at block " +
                                               std::to_string(clip_.data_start_block_) + "), file ends at byte " +
                                               std::to_string(d_.size()));
      }
    }
    clip_.positions_.assign(frames * points * 3, 0.0f);
    clip_.residuals_.assign(frames * points, -1.0f);
    clip_.samples_.assign(frames * points, C3DSample::kInvalid);
    if (points == 0) return;  // frames without points (analog only, or empty): nothing to decode
    // One specialised loop per storage variant (the processor test is hoisted out of the loop).
    std::size_t zero_gaps = 0;
    switch (clip_.processor_) {
      case C3DProcessor::kDec:
        zero_gaps = clip_.is_float_ ? decodeSamples<C3DProcessor::kDec, true>(start)
                                    : decodeSamples<C3DProcessor::kDec, false>(start);
        break;
      case C3DProcessor::kMips:
        zero_gaps = clip_.is_float_ ? decodeSamples<C3DProcessor::kMips, true>(start)
                                    : decodeSamples<C3DProcessor::kMips, false>(start);
        break;
      case C3DProcessor::kIntel:
      default:
        zero_gaps = clip_.is_float_ ? decodeSamples<C3DProcessor::kIntel, true>(start)
                                    : decodeSamples<C3DProcessor::kIntel, false>(start);
        break;
    }
    if (zero_gaps > 0) {
      warn(std::to_string(zero_gaps) + " samples at x = y = z = 0 with residual 0 read as gaps" +
           " (C3DReadOptions::keep_zero_points keeps them)");
    }
  }

  template <C3DProcessor P>
  static float readFloat(const std::uint8_t* p) noexcept {
    if constexpr (P == C3DProcessor::kDec) {
      return decodeVaxFloat(p);
    } else if constexpr (P == C3DProcessor::kMips) {
      return std::bit_cast<float>((static_cast<std::uint32_t>(p[0]) << 24) | (static_cast<std::uint32_t>(p[1]) << 16) |
                                  (static_cast<std::uint32_t>(p[2]) << 8) | static_cast<std::uint32_t>(p[3]));
    } else {
      return std::bit_cast<float>(static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
                                  (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24));
    }
  }
  template <C3DProcessor P>
  static std::int16_t readInt16(const std::uint8_t* p) noexcept {
    if constexpr (P == C3DProcessor::kMips) {
      return static_cast<std::int16_t>(static_cast<std::uint16_t>((p[0] << 8) | p[1]));
    } else {
      return static_cast<std::int16_t>(static_cast<std::uint16_t>((p[1] << 8) | p[0]));
    }
  }

  // Decodes every (x, y, z, residual word) of every frame; bounds were checked by readData().
  // Returns the number of kZeroGap samples.
  template <C3DProcessor P, bool kFloat>
  std::size_t decodeSamples(std::size_t start) {
    const std::size_t points = static_cast<std::size_t>(clip_.point_count_);
    const std::size_t frames = clip_.frame_count_;
    const float scale = clip_.scale_;
    const bool zero_is_gap = !options_.keep_zero_points;
    float* positions = clip_.positions_.data();
    float* residuals = clip_.residuals_.data();
    C3DSample* samples = clip_.samples_.data();
    std::size_t zero_gaps = 0;
    for (std::size_t f = 0; f < frames; ++f) {
      const std::uint8_t* frame = d_.data() + start + f * frame_bytes_;
      for (std::size_t p = 0; p < points; ++p) {
        const std::size_t k = f * points + p;
        float xyz[3];
        unsigned word = 0;  // the residual word's 15 value bits: camera mask << 8 | residual
        if constexpr (kFloat) {
          const std::uint8_t* o = frame + p * 16;
          const float r = readFloat<P>(o + 12);
          // The word's integer value as a float: < 0 is the signed form of an invalid word (-1.0),
          // 32768..65535 its unsigned form (65535.0 = -1), >= 65536 no 16-bit word at all.
          if (std::isnan(r) || r == std::numeric_limits<float>::infinity()) {
            samples[k] = C3DSample::kNonFinite;
            continue;
          }
          if (!(r >= 0.0f && r < 32768.0f)) continue;  // stays kInvalid, position 0, residual -1
          for (std::size_t c = 0; c < 3; ++c) xyz[c] = readFloat<P>(o + 4 * c);
          word = static_cast<unsigned>(r);
        } else {
          const std::uint8_t* o = frame + p * 8;
          const std::int16_t r = readInt16<P>(o + 6);
          if (r < 0) continue;
          for (std::size_t c = 0; c < 3; ++c) xyz[c] = static_cast<float>(readInt16<P>(o + 2 * c)) * scale;
          word = static_cast<unsigned>(r);
        }
        if (!std::isfinite(xyz[0]) || !std::isfinite(xyz[1]) || !std::isfinite(xyz[2])) {
          samples[k] = C3DSample::kNonFinite;
          continue;
        }
        const unsigned residual_byte = word & 0xffu;
        if (zero_is_gap && residual_byte == 0 && xyz[0] == 0.0f && xyz[1] == 0.0f && xyz[2] == 0.0f) {
          samples[k] = C3DSample::kZeroGap;
          ++zero_gaps;
          continue;
        }
        positions[k * 3] = xyz[0];
        positions[k * 3 + 1] = xyz[1];
        positions[k * 3 + 2] = xyz[2];
        residuals[k] = static_cast<float>(residual_byte) * scale;
        samples[k] = C3DSample::kValid;
      }
    }
    return zero_gaps;
  }

  std::span<const std::uint8_t> d_;
  std::string name_;
  C3DReadOptions options_;
  C3DClip clip_;
  bool big_endian_ = false;
  bool has_param_header_ = false;
  std::size_t param_start_ = 0;
  std::size_t param_blocks_ = 0;
  std::size_t params_extent_ = 0;      // end of the furthest parameter/group content read
  std::size_t params_extent_entry_ = 0;  // byte offset of the entry that reaches params_extent_
  std::size_t frame_bytes_ = 0;
};

C3DClip C3DClip::parse(std::span<const std::uint8_t> bytes, std::string_view source_name,
                       const C3DReadOptions& options) {
  return C3DParser(bytes, source_name, options).run();
}

C3DClip C3DClip::load(const std::filesystem::path& path, const C3DReadOptions& options) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw C3DError(path.string() + ": is a folder, not a C3D file (give the .c3d clip)");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw C3DError(path.string() + ": cannot open the file for reading");
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size < 0) throw C3DError(path.string() + ": cannot determine the file size");
  in.seekg(0, std::ios::beg);
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(size));
  if (size > 0 && !in.read(reinterpret_cast<char*>(bytes.data()), size)) {
    throw C3DError(path.string() + ": read error after byte " + std::to_string(in.gcount()));
  }
  return parse(bytes, path.string(), options);
}

std::string c3dPointLabel(const C3DClip& clip, int point) {
  const auto p = static_cast<std::size_t>(point);
  const std::vector<std::string>& stored = clip.labels();
  return p < stored.size() && !stored[p].empty() ? stored[p] : "point" + std::to_string(point);
}

int C3DClip::findPoint(std::string_view label) const noexcept {
  if (label.empty()) return -1;
  for (std::size_t i = 0; i < labels_.size(); ++i) {
    if (labels_[i] == label) return static_cast<int>(i);
  }
  for (std::size_t i = 0; i < labels_.size(); ++i) {
    const std::string& l = labels_[i];
    if (l.size() > label.size() && l.compare(l.size() - label.size(), label.size(), label) == 0 &&
        l[l.size() - label.size() - 1] == ':') {
      return static_cast<int>(i);
    }
  }
  return -1;
}

const C3DParameter* C3DClip::findParameter(std::string_view group, std::string_view name) const noexcept {
  for (const C3DParameter& p : parameters_) {
    if (equalsNoCase(p.group, group) && equalsNoCase(p.name, name)) return &p;
  }
  return nullptr;
}

}  // namespace tetrig::drivers
