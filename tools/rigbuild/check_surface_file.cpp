// Structural check of OFF, PLY, OBJ and STL files against the layouts their readers assume (OFF:
// Princeton Shape Benchmark / Geomview "OFF" text format; PLY: G. Turk's Stanford polygon file
// format; OBJ: Wavefront's "f" statements; STL: 3D Systems' binary and ASCII forms), done before
// assimp parses them. The rules mirror how assimp 5.2 reads each format (line by line, one item
// per line, counts taken from the header) so that a file passing here reads the same way there;
// where assimp would guess, drop data or read out of bounds, the file is refused. See
// check_surface_file.hpp for the list.
#include "tetrig/rigbuild/check_surface_file.hpp"
#include "ply_scalar_type.hpp"

#include "tetrig/printable_text.hpp"
#include "tetrig/rigbuild/surface_mesh.hpp"

#include <array>
#include <charconv>
#include <limits>
#include <optional>
#include <type_traits>
#include <vector>

namespace tetrig::rigbuild {
namespace {

constexpr std::int64_t kMaxCount = std::numeric_limits<std::int32_t>::max();  // vertices, faces, list lengths
constexpr std::size_t kOffLineBuffer = 4096;  // assimp's OFF reader copies each line into char[4096]
constexpr std::int32_t kOffMaxCorners = 9;     // ... and drops faces of more corners

[[noreturn]] void refuse(const std::string& name, const std::string& what) { throw RigBuildError(name + ": " + what); }

// File text shown in a message: escaped and cut short.
std::string shown(std::string_view text) {
  std::string out = printableText(text, 40);
  out.insert(out.begin(), '\'');
  out.push_back('\'');
  return out;
}

std::string str(std::int64_t v) { return std::to_string(v); }

bool isBlank(char c) { return c == ' ' || c == '\t'; }

// Splits `line` at blanks (spaces, tabs) into `out` (views into `line`).
void splitBlanks(std::string_view line, std::vector<std::string_view>& out) {
  out.clear();
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && isBlank(line[i])) ++i;
    const std::size_t start = i;
    while (i < line.size() && !isBlank(line[i])) ++i;
    if (i > start) out.push_back(line.substr(start, i - start));
  }
}

// A decimal integer token: digits, with a sign when `allow_sign`. Values beyond int64 saturate
// (every caller refuses them as too large).
std::optional<std::int64_t> parseInteger(std::string_view t, bool allow_sign) {
  bool negative = false;
  if (allow_sign && !t.empty() && (t[0] == '+' || t[0] == '-')) {
    negative = t[0] == '-';
    t.remove_prefix(1);
  }
  if (t.empty()) return std::nullopt;
  std::int64_t v = 0;
  for (const char c : t) {
    if (c < '0' || c > '9') return std::nullopt;
    v = v > (std::numeric_limits<std::int64_t>::max() - 9) / 10 ? std::numeric_limits<std::int64_t>::max() : v * 10 + (c - '0');
  }
  return negative ? -v : v;
}

// A whole token that is a real number (decimal or exponent form, nan, inf).
bool isReal(std::string_view t) {
  if (!t.empty() && t[0] == '+') t.remove_prefix(1);
  if (t.empty()) return false;
  double d = 0;
  const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), d);
  return (ec == std::errc() || ec == std::errc::result_out_of_range) && ptr == t.data() + t.size();
}

// The tally of polygons (faces of more than 3 corners), shared by every format.
class Polygons {
 public:
  Polygons(const std::string& name, const SurfaceFileLimits& limits, SurfaceFileSummary& summary)
      : name_(name), limits_(limits), summary_(summary) {}

  void add(std::int64_t corners, const std::string& where) {
    if (corners > limits_.max_face_corners) {
      refuse(name_, where + " has " + str(corners) + " corners, more than the " + str(limits_.max_face_corners) +
                        " a face may have (polygons are triangulated in quadratic time): triangulate the mesh "
                        "(e.g. Blender 'Triangulate Faces') and export it again");
    }
    if (corners > summary_.largest_face) summary_.largest_face = static_cast<std::int32_t>(corners);
    if (corners > 4) {
      summary_.polygon_work += corners * corners;
      if (summary_.polygon_work > limits_.max_polygon_work) {
        refuse(name_, "its faces of more than 4 corners add up to more triangulation work than allowed (sum of corners^2 over " +
                          str(limits_.max_polygon_work) + " at " + where +
                          "; polygons are triangulated in quadratic time): triangulate the mesh (e.g. Blender 'Triangulate "
                          "Faces') and export it again");
      }
    }
  }

 private:
  const std::string& name_;
  const SurfaceFileLimits& limits_;
  SurfaceFileSummary& summary_;
};

// ---- OFF ----

bool isOffLineEnd(char c) { return c == '\n' || c == '\r'; }

SurfaceFileSummary checkOff(std::string_view text, const std::string& name, const SurfaceFileLimits& limits) {
  SurfaceFileSummary summary;
  summary.format = SurfaceFileFormat::kOff;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c < 0x20 && c != '\t' && c != '\n' && c != '\r') {
      refuse(name, "byte " + str(static_cast<std::int64_t>(i)) + " is a control character (" + printableText(text.substr(i, 1)) +
                       "): an OFF file is text; export it again as text OFF");
    }
  }
  std::size_t pos = 0;
  if (text.substr(0, 3) == "\xEF\xBB\xBF") pos = 3;  // UTF-8 byte order mark
  std::int64_t line = 1;
  auto countLines = [&](std::size_t from, std::size_t to) {
    for (std::size_t i = from; i < to; ++i) line += text[i] == '\n' ? 1 : 0;
  };
  // Header tokens as assimp reads them: blanks, line ends and '#' comment lines are skipped.
  auto nextToken = [&]() -> std::string_view {
    for (;;) {
      const std::size_t from = pos;
      while (pos < text.size() && (isBlank(text[pos]) || isOffLineEnd(text[pos]))) ++pos;
      countLines(from, pos);
      if (pos < text.size() && text[pos] == '#') {
        while (pos < text.size() && !isOffLineEnd(text[pos])) ++pos;
        continue;
      }
      break;
    }
    const std::size_t start = pos;
    while (pos < text.size() && !isBlank(text[pos]) && !isOffLineEnd(text[pos]) && text[pos] != '#') ++pos;
    return text.substr(start, pos - start);
  };
  const std::string_view magic = nextToken();
  static constexpr std::array<std::string_view, 8> kMagics = {"OFF", "COFF", "NOFF", "CNOFF", "STOFF", "STCOFF", "STNOFF", "STCNOFF"};
  bool known = false;
  for (const std::string_view m : kMagics) known = known || magic == m;
  if (!known) {
    const bool other_off = magic.size() >= 3 && magic.substr(magic.size() - 3) == "OFF";
    refuse(name, other_off ? "OFF variant " + shown(magic) + " (homogeneous or n-dimensional) is not supported: export a plain OFF"
                           : "not an OFF file (it starts with " + shown(magic) +
                                 ", not 'OFF'): check the file, or give it the extension of its real format");
  }
  std::int64_t counts[3] = {0, 0, 0};
  const char* kCountNames[3] = {"vertex", "face", "edge"};
  for (int k = 0; k < 3; ++k) {
    const std::string_view t = nextToken();
    if (t == "BINARY") refuse(name, "binary OFF is not supported: export a text OFF");
    const std::optional<std::int64_t> v = parseInteger(t, false);
    if (!v) {
      refuse(name, "line " + str(line) + ": the header's " + kCountNames[k] + " count is " + (t.empty() ? std::string("missing") : shown(t)) +
                       ", not a number (expected 'OFF' then the vertex, face and edge counts)");
    }
    if (*v > kMaxCount) refuse(name, "line " + str(line) + ": the header's " + kCountNames[k] + " count " + str(*v) + " is too large");
    counts[k] = *v;
  }
  const std::int64_t nv = counts[0];
  const std::int64_t nf = counts[1];
  summary.vertices = nv;
  summary.faces = nf;
  if (nv == 0 || nf == 0) refuse(name, "the header declares " + str(nv) + " vertices and " + str(nf) + " faces: there is no surface");
  // The data: assimp skips what follows the edge count up to the next token, then reads one line
  // per vertex and per face (a run of line ends separates two lines).
  {
    const std::size_t from = pos;
    for (;;) {
      while (pos < text.size() && (isBlank(text[pos]) || isOffLineEnd(text[pos]))) ++pos;
      if (pos < text.size() && text[pos] == '#') {
        while (pos < text.size() && !isOffLineEnd(text[pos])) ++pos;
        continue;
      }
      break;
    }
    countLines(from, pos);
  }
  Polygons polygons(name, limits, summary);
  std::vector<std::string_view> tokens;
  for (std::int64_t item = 0; item < nv + nf; ++item) {
    const bool vertex = item < nv;
    if (pos >= text.size()) {
      refuse(name, "the header declares " + str(nv) + " vertices and " + str(nf) + " faces, but the data ends after " +
                       (vertex ? str(item) + " vertices" : "the vertices and " + str(item - nv) + " faces") + " (line " + str(line) +
                       "; OFF holds one vertex or face per line): the file is truncated or its header is wrong; export it again");
    }
    const std::size_t start = pos;
    while (pos < text.size() && !isOffLineEnd(text[pos])) ++pos;
    const std::string_view l = text.substr(start, pos - start);
    const std::string where = "line " + str(line) + " (" + (vertex ? "vertex " + str(item) : "face " + str(item - nv)) + ")";
    if (l.size() >= kOffLineBuffer) {
      refuse(name, where + " is " + str(static_cast<std::int64_t>(l.size())) + " bytes long; the OFF importer reads lines of at most " +
                       str(kOffLineBuffer - 1) + " bytes");
    }
    splitBlanks(l, tokens);
    if (!tokens.empty() && tokens[0][0] == '#') {
      refuse(name, where + " is a comment inside the " + (vertex ? "vertex" : "face") +
                       " list, which the OFF importer reads as data: remove the comment lines between the data lines");
    }
    if (vertex) {
      if (tokens.size() < 3 || !isReal(tokens[0]) || !isReal(tokens[1]) || !isReal(tokens[2])) {
        refuse(name, where + ": expected a vertex 'x y z', found " + shown(l) +
                         " (one vertex per line; the header's counts must match the data)");
      }
    } else {
      const std::optional<std::int64_t> k = tokens.empty() ? std::nullopt : parseInteger(tokens[0], false);
      if (!k || *k < 1) {
        refuse(name, where + ": expected a face 'k i_1 ... i_k' with k >= 1 corners, found " + shown(l));
      }
      if (*k > kOffMaxCorners) {
        refuse(name, where + " has " + str(*k) + " corners; the OFF importer reads faces of at most " + str(kOffMaxCorners) +
                         " corners (it drops larger ones): triangulate the mesh (e.g. Blender 'Triangulate Faces') and export it again");
      }
      if (static_cast<std::int64_t>(tokens.size()) < *k + 1) {
        refuse(name, where + " says " + str(*k) + " corners but lists " + str(static_cast<std::int64_t>(tokens.size()) - 1) +
                         " (one face per line)");
      }
      for (std::int64_t c = 1; c <= *k; ++c) {
        const std::optional<std::int64_t> v = parseInteger(tokens[static_cast<std::size_t>(c)], false);
        if (!v || *v >= nv) {
          refuse(name, where + ": corner " + shown(tokens[static_cast<std::size_t>(c)]) + " is not a vertex index in [0, " +
                           str(nv - 1) + "]: the file is corrupt");
        }
      }
      polygons.add(*k, where);
    }
    const std::size_t from = pos;
    while (pos < text.size() && isOffLineEnd(text[pos])) ++pos;
    countLines(from, pos);
  }
  return summary;
}

// ---- PLY ----

struct PlyProperty {
  std::string name;
  int size = 0;             // bytes of the scalar or of each list item
  bool is_float = false;
  bool is_signed = false;
  bool list = false;
  int count_size = 0;       // bytes of a list's length
  bool count_signed = false;
};

struct PlyElement {
  std::string name;
  std::int64_t count = 0;
  std::vector<PlyProperty> properties;
  std::int64_t header_line = 0;
};

bool isVertexIndexList(const PlyElement& e, const PlyProperty& p) {
  return p.list && e.name == "face" && (p.name == "vertex_indices" || p.name == "vertex_index");
}

// Item sources for the data walk: one ascii line per item, or the binary bytes.
class PlyAscii {
 public:
  PlyAscii(std::string_view data, std::int64_t first_line, const std::string& name) : data_(data), line_(first_line - 1), name_(name) {}

  void begin(const std::string& item) {
    item_ = item;
    if (pos_ >= data_.size()) refuse(name_, "the file ends before " + item + " (line " + str(line_ + 1) + "): it is truncated or its header is wrong");
    const std::size_t nl = data_.find('\n', pos_);
    const std::size_t end = nl == std::string_view::npos ? data_.size() : nl;
    std::string_view l = data_.substr(pos_, end - pos_);
    pos_ = nl == std::string_view::npos ? data_.size() : nl + 1;
    ++line_;
    if (!l.empty() && l.back() == '\r') l.remove_suffix(1);
    for (const char c : l) {
      if (static_cast<unsigned char>(c) < 0x20 && c != '\t') {
        refuse(name_, where() + " holds a control character (" + printableText(std::string_view(&c, 1)) + "): an ascii PLY file is text");
      }
    }
    splitBlanks(l, tokens_);
    if (tokens_.empty()) refuse(name_, where() + " is empty; an ascii PLY holds one item per line with no blank lines between");
    next_ = 0;
  }
  std::string where() const { return item_ + " (line " + str(line_) + ")"; }
  std::int64_t count(const PlyProperty& p) {
    const std::string_view t = token(p);
    const std::optional<std::int64_t> v = parseInteger(t, p.count_signed);
    if (!v || *v < 0) refuse(name_, where() + ": list length " + shown(t) + " of property " + shown(p.name) + " is not a count");
    return *v;
  }
  void needItems(const PlyProperty& p, std::int64_t n) {
    if (static_cast<std::int64_t>(tokens_.size() - next_) < n) {
      refuse(name_, where() + ": property " + shown(p.name) + " lists " + str(n) + " values but the line holds " +
                        str(static_cast<std::int64_t>(tokens_.size() - next_)) + " (one item per line)");
    }
  }
  std::int64_t integer(const PlyProperty& p) {
    const std::string_view t = token(p);
    const std::optional<std::int64_t> v = parseInteger(t, p.is_signed);
    if (!v) refuse(name_, where() + ": " + shown(t) + " is not an integer (property " + shown(p.name) + ")");
    return *v;
  }
  void value(const PlyProperty& p) {
    if (!p.is_float) {
      (void)integer(p);
      return;
    }
    const std::string_view t = token(p);
    if (!isReal(t)) refuse(name_, where() + ": " + shown(t) + " is not a number (property " + shown(p.name) + ")");
  }
  void values(const PlyProperty& p, std::int64_t n) {
    for (std::int64_t k = 0; k < n; ++k) value(p);
  }
 private:
  std::string_view token(const PlyProperty& p) {
    if (next_ >= tokens_.size()) refuse(name_, where() + ": property " + shown(p.name) + " is missing (one item per line, every property)");
    return tokens_[next_++];
  }
  std::string_view data_;
  std::size_t pos_ = 0;
  std::int64_t line_;
  const std::string& name_;
  std::string item_;
  std::vector<std::string_view> tokens_;
  std::size_t next_ = 0;
};

class PlyBinary {
 public:
  PlyBinary(std::string_view data, std::size_t offset, bool big, const std::string& name)
      : data_(data), pos_(offset), big_(big), name_(name) {}

  void begin(const std::string& item) { item_ = item; }
  std::string where() const { return item_ + " (byte " + str(static_cast<std::int64_t>(pos_)) + ")"; }
  std::int64_t count(const PlyProperty& p) {
    const std::int64_t v = read(p.count_size, p.count_signed, p);
    if (v < 0) refuse(name_, where() + ": list length " + str(v) + " of property " + shown(p.name) + " is negative");
    return v;
  }
  void needItems(const PlyProperty& p, std::int64_t n) {
    if (n > static_cast<std::int64_t>((data_.size() - pos_) / static_cast<std::size_t>(p.size))) {
      refuse(name_, where() + ": property " + shown(p.name) + " lists " + str(n) + " values of " + str(p.size) +
                        " bytes but only " + str(static_cast<std::int64_t>(data_.size() - pos_)) +
                        " bytes remain: the file is truncated or corrupt");
    }
  }
  std::int64_t integer(const PlyProperty& p) { return read(p.size, p.is_signed, p); }
  void value(const PlyProperty& p) { values(p, 1); }
  void values(const PlyProperty& p, std::int64_t n) {
    needItems(p, n);
    pos_ += static_cast<std::size_t>(n) * static_cast<std::size_t>(p.size);
  }
  // Elements without lists: every item has the same size, checked at once.
  bool skipFixed(const PlyElement& e) {
    if (e.count == 0) return true;  // (an element without properties holds no items: refused before)
    std::size_t bytes = 0;
    for (const PlyProperty& p : e.properties) {
      if (p.list) return false;
      bytes += static_cast<std::size_t>(p.size);
    }
    if (static_cast<std::uint64_t>(e.count) > (data_.size() - pos_) / bytes) {
      refuse(name_, "element " + shown(e.name) + " declares " + str(e.count) + " items of " + str(static_cast<std::int64_t>(bytes)) +
                        " bytes but only " + str(static_cast<std::int64_t>(data_.size() - pos_)) + " bytes remain (from byte " +
                        str(static_cast<std::int64_t>(pos_)) + "): the file is truncated or its header is wrong");
    }
    pos_ += static_cast<std::size_t>(e.count) * bytes;
    return true;
  }

 private:
  std::int64_t read(int size, bool is_signed, const PlyProperty& p) {
    if (data_.size() - pos_ < static_cast<std::size_t>(size)) {
      refuse(name_, "the file ends inside " + where() + ", property " + shown(p.name) + ": it is truncated or its header is wrong");
    }
    std::uint64_t u = 0;
    for (int i = 0; i < size; ++i) {
      const auto b = static_cast<unsigned char>(data_[pos_ + static_cast<std::size_t>(big_ ? i : size - 1 - i)]);
      u = (u << 8) | b;
    }
    pos_ += static_cast<std::size_t>(size);
    if (is_signed && size < 8 && ((u >> (8 * size - 1)) & 1u)) return static_cast<std::int64_t>(u | (~std::uint64_t{0} << (8 * size)));
    return static_cast<std::int64_t>(u);
  }
  std::string_view data_;
  std::size_t pos_;
  bool big_;
  const std::string& name_;
  std::string item_;
};

template <class Source>
void walkPly(Source& src, const std::vector<PlyElement>& elements, std::int64_t vertex_count, Polygons& polygons,
             const std::string& name) {
  for (const PlyElement& e : elements) {
    if constexpr (std::is_same_v<Source, PlyBinary>) {
      if (src.skipFixed(e)) continue;
    }
    const bool face = e.name == "face";
    for (std::int64_t i = 0; i < e.count; ++i) {
      src.begin("element " + shown(e.name) + " item " + str(i));
      std::int64_t corners = -1;
      std::int64_t texcoords = -1;
      for (const PlyProperty& p : e.properties) {
        if (!p.list) {
          src.value(p);
          continue;
        }
        const std::int64_t n = src.count(p);
        if (n > kMaxCount) refuse(name, src.where() + ": list length " + str(n) + " of property " + shown(p.name) + " is too large");
        if (isVertexIndexList(e, p)) {
          if (n < 1) refuse(name, src.where() + ": a face with no corners");
          polygons.add(n, src.where());
          corners = n;
          src.needItems(p, n);
          for (std::int64_t k = 0; k < n; ++k) {
            const std::int64_t v = src.integer(p);
            if (v >= vertex_count || v < 0) {
              refuse(name, src.where() + ": corner " + str(v) + " is not a vertex index in [0, " + str(vertex_count - 1) +
                               "]: the file is corrupt");
            }
          }
        } else {
          if (p.name == "texcoord") texcoords = n;
          src.needItems(p, n);
          src.values(p, n);
        }
      }
      if (face && texcoords > 2 * corners) {
        refuse(name, src.where() + ": " + str(texcoords) + " texture coordinates for " + str(corners) +
                         " corners (at most two per corner): the file is corrupt");
      }
    }
  }
}

SurfaceFileSummary checkPly(std::string_view text, const std::string& name, const SurfaceFileLimits& limits) {
  SurfaceFileSummary summary;
  std::size_t pos = 0;
  std::int64_t line_no = 0;
  bool saw_cr = false;
  std::vector<std::string_view> tokens;
  auto headerLine = [&]() -> std::string_view {
    const std::size_t nl = text.find('\n', pos);
    if (nl == std::string_view::npos) refuse(name, "the PLY header has no 'end_header' line: the file is truncated or not a PLY file");
    std::string_view l = text.substr(pos, nl - pos);
    pos = nl + 1;
    ++line_no;
    if (!l.empty() && l.back() == '\r') {
      l.remove_suffix(1);
      saw_cr = true;
    }
    for (const char c : l) {
      if (static_cast<unsigned char>(c) < 0x20 && c != '\t') {
        refuse(name, "header line " + str(line_no) + " holds a control character (" + printableText(std::string_view(&c, 1)) +
                         "): the file is corrupt");
      }
    }
    return l;
  };
  if (const std::string_view magic = headerLine(); magic != "ply" && magic != "PLY") {
    refuse(name, "not a PLY file (its first line is " + shown(magic) + ", not 'ply')");
  }
  splitBlanks(headerLine(), tokens);
  bool big = false;
  if (tokens.size() != 3 || tokens[0] != "format") {
    refuse(name, "line 2 must be 'format ascii 1.0' (or binary_little_endian / binary_big_endian), not " +
                     (tokens.empty() ? std::string("an empty line") : shown(tokens[0])));
  }
  if (tokens[1] == "ascii") {
    summary.format = SurfaceFileFormat::kPlyAscii;
  } else if (tokens[1] == "binary_little_endian" || tokens[1] == "binary_big_endian") {
    summary.format = SurfaceFileFormat::kPlyBinary;
    big = tokens[1] == "binary_big_endian";
  } else {
    refuse(name, "unknown PLY format " + shown(tokens[1]) + " (ascii, binary_little_endian or binary_big_endian)");
  }
  std::vector<PlyElement> elements;
  // A comment or obj_info line ends the property list of the element before it: assimp 5.2 drops
  // the property lines after one (and reads the data with fewer properties: wrong positions).
  bool properties_closed = false;
  for (;;) {
    const std::string_view l = headerLine();
    if (l.empty()) continue;
    const std::string where = "header line " + str(line_no);
    if (isBlank(l[0])) refuse(name, where + " starts with a blank, which the PLY importer does not read: remove it");
    splitBlanks(l, tokens);
    const std::string_view key = tokens[0];
    if (key == "end_header" && tokens.size() == 1) break;
    if (key == "comment" || key == "obj_info") {
      properties_closed = true;
      continue;
    }
    if (key == "element") {
      if (tokens.size() != 3) refuse(name, where + ": expected 'element NAME COUNT'");
      PlyElement e;
      e.name = std::string(tokens[1]);
      e.header_line = line_no;
      const std::optional<std::int64_t> count = parseInteger(tokens[2], false);
      if (!count) refuse(name, where + ": the count of element " + shown(e.name) + " is " + shown(tokens[2]) + ", not a number");
      if (*count > kMaxCount) refuse(name, where + ": element " + shown(e.name) + " declares " + str(*count) + " items, too many");
      e.count = *count;
      for (const PlyElement& o : elements) {
        if (o.name == e.name) refuse(name, where + ": element " + shown(e.name) + " is declared twice");
      }
      if (e.name == "tristrips" && e.count > 0) {
        refuse(name, where + ": triangle strips (element 'tristrips') are read wrongly by the PLY importer (one triangle "
                         "per strip): convert them to faces (e.g. MeshLab) and export again");
      }
      static constexpr std::array<std::string_view, 5> kKnown = {"vertex", "face", "tristrips", "edge", "material"};
      bool known = false;
      for (const std::string_view k : kKnown) known = known || e.name == k;
      if (!known && e.count > 0) {
        refuse(name, where + ": element " + shown(e.name) + " holds " + str(e.count) +
                         " items, but the PLY importer only reads the counts of vertex, face, edge and material "
                         "elements (it would misread the data after it): remove the element and export again");
      }
      elements.push_back(std::move(e));
      properties_closed = false;
      continue;
    }
    if (key == "property") {
      if (elements.empty()) refuse(name, where + ": a property line must follow an element line");
      if (properties_closed) {
        refuse(name, where + ": a property after a comment or obj_info line, which the PLY importer drops (it would read the "
                         "data without it): move the comment before the element line");
      }
      PlyProperty p;
      bool count_float = false;
      std::string_view type;
      if (tokens.size() == 5 && tokens[1] == "list") {
        p.list = true;
        if (!plyScalarType(tokens[2], p.count_size, count_float, p.count_signed) || count_float) {
          refuse(name, where + ": list length type " + shown(tokens[2]) + " is not an integer type");
        }
        type = tokens[3];
        p.name = std::string(tokens[4]);
      } else if (tokens.size() == 3) {
        type = tokens[1];
        p.name = std::string(tokens[2]);
      } else {
        refuse(name, where + ": expected 'property TYPE NAME' or 'property list COUNT_TYPE TYPE NAME'");
      }
      if (!plyScalarType(type, p.size, p.is_float, p.is_signed)) {
        refuse(name, where + ": unknown property type " + shown(type) + " (char, uchar, short, ushort, int, uint, float, double)");
      }
      PlyElement& e = elements.back();
      for (const PlyProperty& o : e.properties) {
        if (o.name == p.name) refuse(name, where + ": property " + shown(p.name) + " is declared twice in element " + shown(e.name));
      }
      e.properties.push_back(std::move(p));
      continue;
    }
    refuse(name, where + ": unknown header line " + shown(l) + " (PLY headers hold comment, obj_info, element, property, end_header)");
  }
  if (summary.format == SurfaceFileFormat::kPlyBinary && saw_cr) {
    refuse(name, "the header of a binary PLY must end its lines with a line feed alone (not CR LF), or the data is read one byte off");
  }
  // What the importer reads of each element.
  std::int64_t vertex_count = 0;
  for (const PlyElement& e : elements) {
    const std::string where = "element " + shown(e.name) + " (header line " + str(e.header_line) + ")";
    if (e.count > 0 && e.properties.empty()) refuse(name, where + " holds " + str(e.count) + " items without properties: the file is corrupt");
    int index_lists = 0;
    for (const PlyProperty& p : e.properties) {
      if (!p.list) continue;
      if (isVertexIndexList(e, p)) {
        ++index_lists;
        if (p.is_float) refuse(name, where + ": the vertex indices must have an integer type");
      } else if (!(e.name == "face" && p.name == "texcoord")) {
        refuse(name, where + ": list property " + shown(p.name) + " is not read safely by the PLY importer: remove it");
      }
    }
    if (e.name == "vertex") {
      vertex_count = e.count;
      for (const char* axis : {"x", "y", "z"}) {
        bool found = false;
        for (const PlyProperty& p : e.properties) found = found || p.name == axis;
        if (!found && e.count > 0) refuse(name, where + " has no property '" + std::string(axis) + "'");
      }
    }
    if (e.name == "face" && e.count > 0 && index_lists != 1) {
      refuse(name, where + " needs one list property 'vertex_indices' (or 'vertex_index'), it has " + str(index_lists));
    }
    if (e.name == "face") summary.faces = e.count;
  }
  summary.vertices = vertex_count;
  Polygons polygons(name, limits, summary);
  if (summary.format == SurfaceFileFormat::kPlyAscii) {
    PlyAscii src(text.substr(pos), line_no + 1, name);
    walkPly(src, elements, vertex_count, polygons, name);
  } else {
    PlyBinary src(text, pos, big, name);
    walkPly(src, elements, vertex_count, polygons, name);
  }
  return summary;
}

// ---- OBJ ----

SurfaceFileSummary checkObj(std::string_view text, const std::string& name, const SurfaceFileLimits& limits) {
  SurfaceFileSummary summary;
  summary.format = SurfaceFileFormat::kObj;
  Polygons polygons(name, limits, summary);
  std::size_t pos = 0;
  std::int64_t line_no = 0;
  while (pos < text.size()) {
    // One statement: a line, joined with the next while it ends in a backslash.
    const std::int64_t first_line = line_no + 1;
    const std::size_t start = pos;
    std::size_t end = pos;
    for (;;) {
      const std::size_t nl = text.find('\n', pos);
      end = nl == std::string_view::npos ? text.size() : nl;
      pos = nl == std::string_view::npos ? text.size() : nl + 1;
      ++line_no;
      std::size_t e = end;
      if (e > start && text[e - 1] == '\r') --e;
      if (e > start && text[e - 1] == '\\' && pos < text.size()) continue;
      break;
    }
    std::size_t i = start;
    while (i < end && (isBlank(text[i]) || text[i] == '\\' || text[i] == '\r')) ++i;
    if (i >= end) continue;
    const char c = text[i];
    if (c == 'v' && i + 1 < end && isBlank(text[i + 1])) {
      ++summary.vertices;
      continue;
    }
    if (c != 'f' && c != 'l' && c != 'p') continue;
    // Corners: the blank-separated tokens after the keyword (continuation backslashes and line
    // ends count as blanks).
    std::int64_t corners = 0;
    bool in_token = true;  // the keyword itself
    for (std::size_t k = i; k < end; ++k) {
      const char ch = text[k];
      const bool sep = isBlank(ch) || ch == '\\' || ch == '\r' || ch == '\n';
      if (!sep && !in_token) ++corners;
      in_token = !sep;
    }
    if (c == 'f') ++summary.faces;
    polygons.add(corners, "line " + str(first_line) + " (" + (c == 'f' ? "face" : c == 'l' ? "line" : "point") + " statement)");
  }
  return summary;
}

// ---- STL ----

SurfaceFileSummary checkStl(std::string_view bytes, const std::string& name) {
  SurfaceFileSummary summary;
  if (bytes.size() >= 84) {
    std::uint32_t n = 0;
    for (int i = 3; i >= 0; --i) n = (n << 8) | static_cast<unsigned char>(bytes[80 + static_cast<std::size_t>(i)]);
    if (84 + 50 * static_cast<std::uint64_t>(n) == bytes.size()) {
      summary.format = SurfaceFileFormat::kStlBinary;
      summary.faces = n;
      return summary;
    }
    std::size_t i = 0;
    while (i < bytes.size() && (isBlank(bytes[i]) || bytes[i] == '\n' || bytes[i] == '\r')) ++i;
    if (bytes.substr(i, 5) != "solid") {
      refuse(name, "a binary STL whose header says " + str(n) + " triangles must be " + str(84 + 50 * static_cast<std::int64_t>(n)) +
                       " bytes, the file has " + str(static_cast<std::int64_t>(bytes.size())) +
                       " (and it is not an ASCII STL, which starts with 'solid'): the file is truncated or corrupt");
    }
  } else {
    std::size_t i = 0;
    while (i < bytes.size() && (isBlank(bytes[i]) || bytes[i] == '\n' || bytes[i] == '\r')) ++i;
    if (bytes.substr(i, 5) != "solid") {
      refuse(name, "only " + str(static_cast<std::int64_t>(bytes.size())) +
                       " bytes: neither a binary STL (at least 84 bytes) nor an ASCII STL (starts with 'solid')");
    }
  }
  summary.format = SurfaceFileFormat::kStlAscii;
  return summary;
}

}  // namespace

SurfaceFileSummary checkSurfaceBytes(std::string_view bytes, std::string_view extension, const std::string& name,
                                     const SurfaceFileLimits& limits) {
  if (extension == ".off") return checkOff(bytes, name, limits);
  if (extension == ".ply") return checkPly(bytes, name, limits);
  if (extension == ".obj") return checkObj(bytes, name, limits);
  if (extension == ".stl") return checkStl(bytes, name);
  return {};
}

}  // namespace tetrig::rigbuild
