// C3D file reader (the "Coordinate 3D" biomechanics/motion-capture format, c3d.org).
//
// Written from the format's published layout: 512-byte blocks; block 1 is the header (parameter
// block pointer, key 0x50, point count, analog words per frame, first/last frame, max gap, scale
// factor whose sign selects float (negative) or scaled int16 (positive) storage, data start block,
// analog samples per frame, frame rate); the parameter section starts with a 4-byte header whose
// last byte is the processor type (84 Intel = little-endian IEEE, 85 DEC = little-endian words
// with VAX F-floating floats, 86 MIPS/SGI = big-endian IEEE) and holds groups and parameters
// (signed name length, signed group id, name, int16 offset to the next entry, then type -1 char /
// 1 byte / 2 int16 / 4 float, dimensions, data, description); the data section holds, per frame,
// every point as (x, y, z, residual word) followed by the analog samples.
//
// Decisions where files disagree with the standard (see docs/drivers.md, "Playback"):
//  - validity: the fourth word of a point is the residual word, an int16 whose high byte is the
//    camera mask and low byte the residual (times |scale|); a negative word (bit 15 set) marks an
//    invalid sample. Float files store that word's integer value as a float, and writers encode
//    "invalid" either as the negative value (-1.0) or as the unsigned value of the same 16 bits
//    (65535.0 for -1): a float word < 0 or >= 32768 is invalid (>= 65536 is not a 16-bit word at
//    all), NaN or +Inf is non-finite. x = y = z = 0 with residual 0 (low byte 0) is a gap too
//    (several writers fill gaps so; status kZeroGap) unless C3DReadOptions::keep_zero_points.
//    Non-finite coordinates (float files) are invalid too and counted as non-finite.
//  - processor type: a parameter section whose processor byte is not 84, 85 or 86 is refused.
//    Only a file without a parameter section (header block pointer < 2) has its processor guessed.
//  - parameter section extent: entries are read up to the data start (the header's data block
//    when it lies after the parameter block, else the end of the file), not only the declared
//    block count, which some writers set too small. Refused: an entry whose next-entry offset
//    points backwards or into the entry's own data, a chain that leaves the section, and entries
//    that run into the frames actually used.
//  - data start: the header's word 9 wins over POINT:DATA_START (the header is what the writer
//    laid the data out by, and the parameter is known to be written wrong, e.g. 0). The parameter
//    is used only when the header's block is impossible (inside the header/parameter section) or
//    its frames do not fit in the file while the parameter's do. Disagreements add a warning.
//  - frame count: last - first + 1 from the header (unsigned 16-bit words). When the parameters
//    give more than 65535 frames (TRIAL:ACTUAL_START_FIELD/ACTUAL_END_FIELD as two 16-bit words,
//    POINT:LONG_FRAMES, or a float POINT:FRAMES), the parameter wins: the header cannot hold it.
//  - no parameter section (e.g. PhaseSpace's header-only files): the header alone describes the
//    data; no labels; units assumed mm (with a warning). Without a parameter section header there
//    is no processor byte: the processor is guessed from the plausibility of the header's scale
//    factor and frame rate.
//  - messages never print raw file bytes: names and labels are shown with non-printable bytes as
//    \xNN and cut to 40 characters + "...".
//
// Ownership and threads: C3DClip owns the whole decoded clip (it reads the file once, at load).
// Loading allocates and throws C3DError; after loading, every accessor is const, noexcept,
// allocation-free and safe to call from any number of threads at once.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace tetrig::drivers {

// Any failure to read a C3D file. what() names the file, the byte offset and what was expected,
// e.g. "walk.c3d: truncated data at byte 30720: frame 12 of 450 needs 1536 bytes, file ends at 31000".
class C3DError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

enum class C3DProcessor : std::uint8_t { kIntel = 84, kDec = 85, kMips = 86 };

// What a point is, from its label (see C3DClip::pointKind()).
enum class C3DPointKind : std::uint8_t {
  kMarker,     // a labelled physical marker (or any point of a file without labels)
  kUnlabeled,  // virtual/unlabeled trajectory: label "*<digits>" (optionally "prefix:*<n>") or none
  kModelled,   // listed in POINT:ANGLES/FORCES/MOMENTS/POWERS/REACTIONS/SCALARS or a TYPE_GROUPS
               // list; or a Plug-in Gait output recognised by name: segment axes (a complete
               // quadruple XXXO/XXXA/XXXL/XXXP) and CentreOfMass*
};

// Per-sample status stored by the reader.
enum class C3DSample : std::uint8_t {
  kInvalid = 0,    // residual word < 0, or (float files) its unsigned form >= 32768: occluded
  kValid = 1,
  kNonFinite = 2,  // float file with NaN/Inf coordinates or a NaN/+Inf residual word: invalid,
                   // and counted apart
  kZeroGap = 3,    // x = y = z = 0 with residual 0: a gap as several writers fill them (invalid;
                   // C3DReadOptions::keep_zero_points reads it as kValid instead)
};

// How to read a clip. The defaults suit motion-capture markers.
struct C3DReadOptions {
  // false (default): a sample at exactly x = y = z = 0 whose residual (the low byte of the residual
  // word) is 0 is a gap (kZeroGap), since writers that do not use the residual word fill gaps with
  // zeros. true: such samples are valid points at the origin (e.g. modelled outputs that are
  // legitimately 0). A zero position with a non-zero residual is always valid.
  bool keep_zero_points = false;
};

// One parameter as read (numbers converted to host order; DEC floats converted to IEEE).
struct C3DParameter {
  std::string group;               // upper-case as stored, e.g. "POINT"
  std::string name;                // e.g. "LABELS"
  int type = 0;                    // -1 char, 1 byte, 2 int16, 4 float
  std::vector<int> dimensions;     // empty = scalar; first dimension varies fastest
  std::string chars;               // type -1: the raw characters (product of dimensions)
  std::vector<double> numbers;     // types 1, 2, 4: the values (bytes and int16 as signed)
  std::vector<std::uint16_t> words;  // type 2 only: the same values as unsigned 16-bit words
  std::size_t offset = 0;          // byte offset of the entry in the file (for messages)
};

// The header block's fields, decoded with the file's processor type.
struct C3DHeader {
  std::uint8_t parameter_block = 0;     // 1-based block of the parameter section
  std::uint16_t point_count = 0;        // points per frame (word 2)
  std::uint16_t analog_words = 0;       // analog values per 3-D frame (word 3)
  std::uint16_t first_frame = 0;        // words 4, 5 (unsigned)
  std::uint16_t last_frame = 0;
  std::uint16_t max_gap = 0;
  float scale = 0.0f;                   // words 7-8; < 0: float data
  std::uint16_t data_start_block = 0;   // word 9 (1-based)
  std::uint16_t analog_samples_per_frame = 0;  // word 10
  float frame_rate = 0.0f;              // words 11-12, Hz
};

class C3DClip;

// The name every consumer of a clip gives point `point`: its stored label, or "point<N>" when the
// file names none (playback sources, the C API, the rig builder). Allocates.
std::string c3dPointLabel(const C3DClip& clip, int point);

class C3DClip {
 public:
  // Reads the whole file into memory and decodes it. Throws C3DError (clear message with the
  // path) on an unreadable, truncated or corrupted file. Allocates; load-time only.
  static C3DClip load(const std::filesystem::path& path, const C3DReadOptions& options = {});

  // Same from bytes already in memory (the fuzz target's entry point). `source_name` is used in
  // error messages only. The clip copies what it keeps; `bytes` may be freed afterwards.
  static C3DClip parse(std::span<const std::uint8_t> bytes, std::string_view source_name,
                       const C3DReadOptions& options = {});

  // ---- clip description (const, noexcept, no allocation, any thread) ----
  [[nodiscard]] const std::string& sourceName() const noexcept { return source_name_; }
  [[nodiscard]] C3DProcessor processor() const noexcept { return processor_; }
  [[nodiscard]] bool isFloat() const noexcept { return is_float_; }
  [[nodiscard]] bool hasParameters() const noexcept { return !parameters_.empty(); }
  [[nodiscard]] const C3DHeader& header() const noexcept { return header_; }
  [[nodiscard]] int pointCount() const noexcept { return point_count_; }
  [[nodiscard]] std::size_t frameCount() const noexcept { return frame_count_; }
  // File frame number of frame index 0 (header word 4, or TRIAL:ACTUAL_START_FIELD).
  [[nodiscard]] std::uint32_t firstFrameNumber() const noexcept { return first_frame_number_; }
  // Frames per second (header, else POINT:RATE); 0 when the file has none.
  [[nodiscard]] double frameRate() const noexcept { return frame_rate_; }
  // |scale factor| used for int16 coordinates and residuals.
  [[nodiscard]] float pointScale() const noexcept { return scale_; }
  // POINT:UNITS as stored (trimmed), "" when absent; unitsToMm() multiplies coordinates into mm.
  [[nodiscard]] const std::string& units() const noexcept { return units_; }
  [[nodiscard]] double unitsToMm() const noexcept { return units_to_mm_; }
  // 1-based block where the frames start (after the header/parameter arbitration).
  [[nodiscard]] std::uint32_t dataStartBlock() const noexcept { return data_start_block_; }

  // Labels, one per point (pointCount() entries), trailing blanks removed; "" when the file has
  // none for that point. From POINT:LABELS, LABELS2, LABELS3, ... in order.
  [[nodiscard]] const std::vector<std::string>& labels() const noexcept { return labels_; }
  [[nodiscard]] C3DPointKind pointKind(int point) const noexcept { return kinds_[static_cast<std::size_t>(point)]; }
  // Index of the point whose label is `label`, or whose label ends in ":" + label (subject
  // prefixes such as "meinard:LFHD"); -1 when there is none. Exact matches win.
  [[nodiscard]] int findPoint(std::string_view label) const noexcept;

  // Parameters in file order; find() returns nullptr when absent. Group and name compare
  // case-insensitively.
  [[nodiscard]] const std::vector<C3DParameter>& parameters() const noexcept { return parameters_; }
  [[nodiscard]] const C3DParameter* findParameter(std::string_view group, std::string_view name) const noexcept;

  // Human-readable notes about repaired inconsistencies (data start disagreement, assumed units,
  // guessed processor, a parameter section longer than declared, how many zero samples were read
  // as gaps...). Empty for a clean file. File text in them is escaped and cut short.
  [[nodiscard]] const std::vector<std::string>& warnings() const noexcept { return warnings_; }

  // ---- frame access (const, noexcept, no allocation, any thread) ----
  // Preconditions: frame < frameCount(), 0 <= point < pointCount().
  // positions(f): pointCount() x 3 floats (x, y, z per point), in the file's units (see
  // unitsToMm()); invalid samples hold 0. samples(f): pointCount() statuses.
  [[nodiscard]] const float* positions(std::size_t frame) const noexcept {
    return positions_.data() + frame * static_cast<std::size_t>(point_count_) * 3u;
  }
  [[nodiscard]] const C3DSample* samples(std::size_t frame) const noexcept {
    return samples_.data() + frame * static_cast<std::size_t>(point_count_);
  }
  [[nodiscard]] bool isValid(std::size_t frame, int point) const noexcept {
    return samples(frame)[point] == C3DSample::kValid;
  }
  // Residual in file units (low byte of the residual word times |scale|); -1 when invalid.
  [[nodiscard]] float residual(std::size_t frame, int point) const noexcept {
    return residuals_[frame * static_cast<std::size_t>(point_count_) + static_cast<std::size_t>(point)];
  }

 private:
  C3DClip() = default;
  friend class C3DParser;

  std::string source_name_;
  C3DProcessor processor_ = C3DProcessor::kIntel;
  bool is_float_ = false;
  C3DHeader header_{};
  int point_count_ = 0;
  std::size_t frame_count_ = 0;
  std::uint32_t first_frame_number_ = 1;
  double frame_rate_ = 0.0;
  float scale_ = 1.0f;
  std::string units_;
  double units_to_mm_ = 1.0;
  std::uint32_t data_start_block_ = 0;
  std::vector<std::string> labels_;
  std::vector<C3DPointKind> kinds_;
  std::vector<C3DParameter> parameters_;
  std::vector<std::string> warnings_;
  std::vector<float> positions_;   // frame-major: frame, point, xyz
  std::vector<float> residuals_;   // frame, point
  std::vector<C3DSample> samples_; // frame, point
};

// Converts one DEC (VAX F-floating) value stored as 4 file bytes into an IEEE float. Exponent 0
// gives 0 (or NaN for the VAX "reserved operand", sign 1). Pure; no allocation.
float decodeVaxFloat(const std::uint8_t bytes[4]) noexcept;

// Inverse of decodeVaxFloat for finite values whose magnitude VAX can hold (used by test writers).
void encodeVaxFloat(float value, std::uint8_t bytes[4]) noexcept;

}  // namespace tetrig::drivers
