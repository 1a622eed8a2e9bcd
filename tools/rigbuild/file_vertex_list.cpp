// Vertex lists of three mesh formats, read from their published layouts: Wavefront OBJ ("v" lines,
// extra components such as w or colours ignored), Object File Format OFF (header "OFF" with the
// optional ST/C/N prefixes, counts on the header line or the next one, one vertex per line) and
// Stanford PLY (header, elements in order; ascii or binary little/big endian; list properties of
// elements before "vertex" skipped). Only positions are read; faces stay with assimp.
#include "tetrig/rigbuild/file_vertex_list.hpp"
#include "ply_scalar_type.hpp"
#include "tetrig/rigbuild/surface_mesh.hpp"

#include <array>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <sstream>
#include <streambuf>
#include <string>
#include <string_view>
#include <vector>

namespace tetrig::rigbuild {
namespace {

// Parses up to `n` doubles separated by blanks from `s`; returns how many were read.
int parseDoubles(std::string_view s, double* out, int n) {
  int got = 0;
  std::size_t i = 0;
  while (got < n) {
    while (i < s.size() && (s[i] == ' ' || s[i] == '\t' || s[i] == '\r')) ++i;
    if (i >= s.size()) break;
    const char* first = s.data() + i;
    if (*first == '+') ++first;  // from_chars refuses a leading '+'
    const auto [ptr, ec] = std::from_chars(first, s.data() + s.size(), out[got]);
    if (ec != std::errc()) break;
    ++got;
    i = static_cast<std::size_t>(ptr - s.data());
  }
  return got;
}

std::optional<Vertices> fromRows(const std::vector<std::array<double, 3>>& rows) {
  Vertices v(static_cast<Eigen::Index>(rows.size()), 3);
  for (std::size_t i = 0; i < rows.size(); ++i) {
    for (int k = 0; k < 3; ++k) v(static_cast<Eigen::Index>(i), k) = rows[i][static_cast<std::size_t>(k)];
  }
  return v;
}

std::optional<Vertices> readObj(std::istream& in) {
  std::vector<std::array<double, 3>> rows;
  std::string line;
  while (std::getline(in, line)) {
    std::size_t i = 0;
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
    if (i + 1 >= line.size() || line[i] != 'v' || (line[i + 1] != ' ' && line[i + 1] != '\t')) continue;
    std::array<double, 3> p{};
    if (parseDoubles(std::string_view(line).substr(i + 2), p.data(), 3) != 3) return std::nullopt;
    rows.push_back(p);
  }
  return fromRows(rows);
}

std::optional<Vertices> readOff(std::istream& in, std::uintmax_t file_bytes) {
  std::string line;
  auto nextLine = [&](std::string& out) {
    while (std::getline(in, out)) {
      const std::size_t hash = out.find('#');
      if (hash != std::string::npos) out.resize(hash);
      if (out.find_first_not_of(" \t\r") != std::string::npos) return true;
    }
    return false;
  };
  if (!nextLine(line)) return std::nullopt;
  std::istringstream header(line);
  std::string magic;
  header >> magic;
  // [ST][C][N]OFF only: 4OFF / nOFF (other dimensions) and binary OFF are left to the importer.
  if (magic.size() < 3 || magic.compare(magic.size() - 3, 3, "OFF") != 0) return std::nullopt;
  for (std::size_t i = 0; i + 3 < magic.size(); ++i) {
    if (std::string_view("STCN").find(magic[i]) == std::string_view::npos) return std::nullopt;
  }
  std::vector<long long> counts;
  std::string token;
  while (header >> token) {
    if (token == "BINARY") return std::nullopt;
    long long c = 0;
    const auto [ptr, ec] = std::from_chars(token.data(), token.data() + token.size(), c);
    if (ec != std::errc() || ptr != token.data() + token.size()) return std::nullopt;
    counts.push_back(c);
  }
  while (counts.size() < 3) {
    if (!nextLine(line)) return std::nullopt;
    std::istringstream s(line);
    long long c = 0;
    while (s >> c) counts.push_back(c);
    if (!s.eof()) return std::nullopt;
  }
  const long long nv = counts[0];
  // Each vertex line holds at least "0 0 0\n": a count beyond that is a corrupt header (and must
  // not become a huge allocation).
  if (nv < 0 || nv > (1ll << 31) - 1 || nv > static_cast<long long>(file_bytes / 6)) return std::nullopt;
  std::vector<std::array<double, 3>> rows;
  rows.reserve(static_cast<std::size_t>(nv));
  for (long long i = 0; i < nv; ++i) {
    if (!nextLine(line)) return std::nullopt;
    std::array<double, 3> p{};
    if (parseDoubles(line, p.data(), 3) != 3) return std::nullopt;
    rows.push_back(p);
  }
  return fromRows(rows);
}

// ---- PLY ----

enum class PlyFormat { kAscii, kLittle, kBig };

struct PlyProperty {
  std::string name;
  int size = 0;            // bytes of the scalar (or of the list's items)
  bool is_float = false;   // float/double (else integer)
  bool is_signed = false;
  bool list = false;
  int count_size = 0;      // bytes of a list's count
  bool count_signed = false;
};

struct PlyElement {
  std::string name;
  long long count = 0;
  std::vector<PlyProperty> properties;
};

// A list length read as a double (an ascii token may say "nan", "inf" or "2.5"): a whole number
// in [0, 1e6], so that it converts to an integer (converting NaN is undefined behaviour).
bool isListLength(double n) { return n >= 0.0 && n <= 1e6 && n == std::floor(n); }

// One binary scalar as a double; false at the end of the file.
bool readBinary(std::istream& in, int size, bool is_float, bool is_signed, bool big, double& out) {
  std::array<unsigned char, 8> b{};
  if (size < 1 || size > 8 || !in.read(reinterpret_cast<char*>(b.data()), size)) return false;
  std::uint64_t u = 0;  // the value's bits, most significant byte first
  for (int i = 0; i < size; ++i) u = (u << 8) | b[static_cast<std::size_t>(big ? i : size - 1 - i)];
  if (is_float) {
    out = size == 4 ? static_cast<double>(std::bit_cast<float>(static_cast<std::uint32_t>(u))) : std::bit_cast<double>(u);
  } else if (is_signed && size < 8 && ((u >> (8 * size - 1)) & 1u)) {
    out = static_cast<double>(static_cast<std::int64_t>(u | (~std::uint64_t{0} << (8 * size))));
  } else {
    out = is_signed ? static_cast<double>(static_cast<std::int64_t>(u)) : static_cast<double>(u);
  }
  return true;
}

std::optional<Vertices> readPly(std::istream& in, std::uintmax_t file_bytes) {
  std::string line;
  auto headerLine = [&]() {
    if (!std::getline(in, line)) return false;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    return true;
  };
  if (!headerLine() || line != "ply") return std::nullopt;
  PlyFormat format = PlyFormat::kAscii;
  std::vector<PlyElement> elements;
  bool have_format = false;
  for (;;) {
    if (!headerLine()) return std::nullopt;
    std::istringstream s(line);
    std::string word;
    s >> word;
    if (word == "end_header") break;
    if (word == "format") {
      std::string f;
      s >> f;
      if (f == "ascii") {
        format = PlyFormat::kAscii;
      } else if (f == "binary_little_endian") {
        format = PlyFormat::kLittle;
      } else if (f == "binary_big_endian") {
        format = PlyFormat::kBig;
      } else {
        return std::nullopt;
      }
      have_format = true;
    } else if (word == "element") {
      PlyElement e;
      if (!(s >> e.name >> e.count) || e.count < 0) return std::nullopt;
      elements.push_back(e);
    } else if (word == "property") {
      if (elements.empty()) return std::nullopt;
      PlyProperty p;
      std::string type;
      s >> type;
      if (type == "list") {
        std::string count_type;
        bool count_float = false;
        p.list = true;
        if (!(s >> count_type >> type) || !plyScalarType(count_type, p.count_size, count_float, p.count_signed) || count_float) return std::nullopt;
      }
      if (!plyScalarType(type, p.size, p.is_float, p.is_signed) || !(s >> p.name)) return std::nullopt;
      elements.back().properties.push_back(p);
    }  // comment, obj_info and unknown header lines are skipped
  }
  if (!have_format) return std::nullopt;

  std::string t;
  auto nextValue = [&](const PlyProperty& p, bool count, double& out) {
    if (format == PlyFormat::kAscii) return (in >> t) && parseDoubles(t, &out, 1) == 1;
    return count ? readBinary(in, p.count_size, false, p.count_signed, format == PlyFormat::kBig, out)
                 : readBinary(in, p.size, p.is_float, p.is_signed, format == PlyFormat::kBig, out);
  };
  for (const PlyElement& e : elements) {
    if (e.name != "vertex") {
      if (e.properties.empty()) continue;  // no data, whatever the count
      for (long long i = 0; i < e.count; ++i) {
        for (const PlyProperty& p : e.properties) {
          double n = 1;
          if (p.list && (!nextValue(p, true, n) || !isListLength(n))) return std::nullopt;
          for (long long k = 0; k < static_cast<long long>(n); ++k) {
            double ignored = 0;
            if (!nextValue(p, false, ignored)) return std::nullopt;
          }
        }
      }
      continue;
    }
    int xyz[3] = {-1, -1, -1};
    for (std::size_t k = 0; k < e.properties.size(); ++k) {
      const std::string& n = e.properties[k].name;
      const int axis = n == "x" ? 0 : n == "y" ? 1 : n == "z" ? 2 : -1;
      if (axis >= 0 && !e.properties[k].list) xyz[axis] = static_cast<int>(k);
    }
    // Bytes one vertex needs at least (binary: its scalar properties; ascii: three values and
    // separators): a count beyond the file's size is corrupt and must not become a huge allocation.
    std::uintmax_t min_bytes = format == PlyFormat::kAscii ? 6 : 0;
    if (format != PlyFormat::kAscii) {
      for (const PlyProperty& p : e.properties) min_bytes += static_cast<std::uintmax_t>(p.list ? p.count_size : p.size);
    }
    if (xyz[0] < 0 || xyz[1] < 0 || xyz[2] < 0 || e.count > (1ll << 31) - 1 ||
        static_cast<std::uintmax_t>(e.count) > file_bytes / min_bytes) {
      return std::nullopt;
    }
    std::vector<std::array<double, 3>> rows(static_cast<std::size_t>(e.count));
    for (long long i = 0; i < e.count; ++i) {
      for (std::size_t k = 0; k < e.properties.size(); ++k) {
        const PlyProperty& p = e.properties[k];
        double n = 1;
        if (p.list && (!nextValue(p, true, n) || !isListLength(n))) return std::nullopt;
        for (long long j = 0; j < static_cast<long long>(n); ++j) {
          double value = 0;
          if (!nextValue(p, false, value)) return std::nullopt;
          for (int a = 0; a < 3; ++a) {
            if (xyz[a] == static_cast<int>(k)) rows[static_cast<std::size_t>(i)][static_cast<std::size_t>(a)] = value;
          }
        }
      }
    }
    return fromRows(rows);
  }
  return std::nullopt;  // no vertex element
}

// A read-only stream over bytes in memory (no copy).
class ViewBuffer : public std::streambuf {
 public:
  explicit ViewBuffer(std::string_view bytes) {
    char* p = const_cast<char*>(bytes.data());  // only read: the get area is never written
    setg(p, p, p + bytes.size());
  }
};

std::optional<Vertices> readList(std::istream& in, std::string_view ext, std::uintmax_t bytes) {
  if (ext == ".obj") return readObj(in);
  if (ext == ".off") return readOff(in, bytes);
  return readPly(in, bytes);
}

}  // namespace

std::optional<Vertices> readFileVertexList(const std::filesystem::path& path) {
  const std::string ext = lowercaseExtension(path);
  if (ext != ".obj" && ext != ".off" && ext != ".ply") return std::nullopt;
  std::error_code ec;
  const std::uintmax_t bytes = std::filesystem::file_size(path, ec);
  std::ifstream in(path, std::ios::binary);
  if (ec || !in) return std::nullopt;
  return readList(in, ext, bytes);
}

std::optional<Vertices> readFileVertexList(std::string_view bytes, std::string_view extension) {
  if (extension != ".obj" && extension != ".off" && extension != ".ply") return std::nullopt;
  ViewBuffer buffer(bytes);
  std::istream in(&buffer);
  return readList(in, extension, bytes.size());
}

}  // namespace tetrig::rigbuild
